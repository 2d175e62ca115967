//! Runs IAS on a generated bumpy torus, for profiling the collapse engine:
//! `cargo run --release -p horizon-simplify --example profile_engine -- 400 600`.

use glam::{Affine3A, Vec2, Vec3};
use horizon_mesh::{Instance, InstancedMesh, Submesh};
use horizon_simplify::{simplify, SimplifyOptions, Target};

fn main() {
    let mut args = std::env::args().skip(1);
    let rings: u32 = args.next().and_then(|a| a.parse().ok()).unwrap_or(400);
    let segments: u32 = args.next().and_then(|a| a.parse().ok()).unwrap_or(600);
    let mut sub = Submesh::default();
    let mut uvs = Vec::new();
    for r in 0..=rings {
        let phi = std::f32::consts::TAU * r as f32 / rings as f32;
        for s in 0..=segments {
            let theta = std::f32::consts::TAU * s as f32 / segments as f32;
            let tube = 0.3 * (1.0 + 0.1 * (7.0 * phi).sin() * (5.0 * theta).cos());
            let d = Vec3::new(
                (1.0 + tube * theta.cos()) * phi.cos(),
                tube * theta.sin(),
                (1.0 + tube * theta.cos()) * phi.sin(),
            );
            sub.positions.push(d);
            uvs.push(Vec2::new(
                s as f32 / segments as f32,
                r as f32 / rings as f32,
            ));
        }
    }
    for r in 0..rings {
        for s in 0..segments {
            let a = r * (segments + 1) + s;
            let (b, c, d) = (a + 1, a + segments + 1, a + segments + 2);
            sub.indices.extend([a, b, d, a, d, c]);
        }
    }
    sub.uvs = Some(uvs);
    let mesh = InstancedMesh {
        submeshes: vec![sub],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: Vec::new(),
        textures: Vec::new(),
    };
    let out = simplify(&mesh, Target::Ratio(0.2), &SimplifyOptions::default()).expect("simplify");
    println!(
        "{} -> {} triangles in {:.3} s ({:.0} triangles/s), error {:.3e}",
        out.report.triangles_in,
        out.report.triangles_out,
        out.report.seconds,
        out.report.triangles_in as f64 / out.report.seconds,
        out.report.error
    );
}
