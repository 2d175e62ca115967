//! IAS on tiny meshes whose right answer is obvious, and property tests of its promises.

use glam::{Affine3A, Quat, Vec2, Vec3};
use horizon_mesh::{Instance, InstancedMesh, Submesh};
use horizon_simplify::{simplify, simplify_qem, simplify_with, SimplifyOptions, Target, Workspace};
use proptest::prelude::*;

fn single(sub: Submesh, transforms: &[Affine3A]) -> InstancedMesh {
    InstancedMesh {
        submeshes: vec![sub],
        instances: transforms
            .iter()
            .map(|&transform| Instance {
                submesh: 0,
                transform,
            })
            .collect(),
        materials: Vec::new(),
        textures: Vec::new(),
    }
}

/// An n x n grid of quads on [0, 1]^2 at z = height(x, y), with UVs (x, y) and +Z normals.
fn grid(n: u32, height: impl Fn(f32, f32) -> f32) -> Submesh {
    let mut sub = Submesh::default();
    let mut uvs = Vec::new();
    let mut normals = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
            sub.positions.push(Vec3::new(x, y, height(x, y)));
            uvs.push(Vec2::new(x, y));
            normals.push(Vec3::Z);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
            sub.indices.extend([a, b, d, a, d, c]);
        }
    }
    sub.uvs = Some(uvs);
    sub.normals = Some(normals);
    sub
}

/// A flat grid whose left half (x < 0.5) has u = x and right half u = x + 1: a UV seam along
/// x = 0.5, with the seam vertices stored twice.
fn seamed_grid(n: u32) -> Submesh {
    assert!(n.is_multiple_of(2));
    let mut sub = Submesh::default();
    let mut uvs = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut vertex = |i: u32, j: u32, right: bool, sub: &mut Submesh| -> u32 {
        *index.entry((i, j, right && i == n / 2)).or_insert_with(|| {
            let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
            sub.positions.push(Vec3::new(x, y, 0.0));
            uvs.push(Vec2::new(if right { x + 1.0 } else { x }, y));
            (sub.positions.len() - 1) as u32
        })
    };
    for j in 0..n {
        for i in 0..n {
            let right = i >= n / 2;
            let a = vertex(i, j, right, &mut sub);
            let b = vertex(i + 1, j, right, &mut sub);
            let c = vertex(i, j + 1, right, &mut sub);
            let d = vertex(i + 1, j + 1, right, &mut sub);
            sub.indices.extend([a, b, d, a, d, c]);
        }
    }
    sub.uvs = Some(uvs);
    sub
}

fn tetrahedron() -> Submesh {
    Submesh {
        positions: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ],
        indices: vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3],
        ..Submesh::default()
    }
}

/// A UV sphere (closed, with a UV seam and pole fans), radius 1.
fn sphere(rings: u32, segments: u32, bump: impl Fn(Vec3) -> f32) -> Submesh {
    let mut sub = Submesh::default();
    let mut uvs = Vec::new();
    let mut normals = Vec::new();
    let top = 0;
    sub.positions.push(Vec3::Y * (1.0 + bump(Vec3::Y)));
    uvs.push(Vec2::new(0.5, 0.0));
    normals.push(Vec3::Y);
    for r in 1..rings {
        let phi = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let theta = std::f32::consts::TAU * (s % segments) as f32 / segments as f32;
            let d = Vec3::new(phi.sin() * theta.cos(), phi.cos(), phi.sin() * theta.sin());
            sub.positions.push(d * (1.0 + bump(d)));
            uvs.push(Vec2::new(
                s as f32 / segments as f32,
                r as f32 / rings as f32,
            ));
            normals.push(d);
        }
    }
    let bottom = sub.positions.len() as u32;
    sub.positions.push(-Vec3::Y * (1.0 + bump(-Vec3::Y)));
    uvs.push(Vec2::new(0.5, 1.0));
    normals.push(-Vec3::Y);
    let row = |r: u32| 1 + (r - 1) * (segments + 1);
    for s in 0..segments {
        sub.indices.extend([top, row(1) + s + 1, row(1) + s]);
        sub.indices
            .extend([bottom, row(rings - 1) + s, row(rings - 1) + s + 1]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            let (a, b) = (row(r) + s, row(r) + s + 1);
            let (c, d) = (row(r + 1) + s, row(r + 1) + s + 1);
            sub.indices.extend([a, b, d, a, d, c]);
        }
    }
    sub.uvs = Some(uvs);
    sub.normals = Some(normals);
    sub
}

fn face_normal(sub: &Submesh, t: &[u32]) -> Vec3 {
    let [a, b, c] = [0, 1, 2].map(|k| sub.positions[t[k] as usize]);
    (b - a).cross(c - a)
}

#[test]
fn a_tetrahedron_cannot_collapse() {
    let mesh = single(tetrahedron(), &[Affine3A::IDENTITY]);
    let out = simplify(&mesh, Target::Ratio(0.0), &SimplifyOptions::default()).expect("simplify");
    assert_eq!(out.report.triangles_out, 4);
    assert_eq!(out.report.collapses, 0);
    out.mesh.validate().expect("valid");
}

#[test]
fn a_flat_grid_collapses_to_two_triangles_with_zero_error() {
    let mesh = single(grid(8, |_, _| 0.0), &[Affine3A::IDENTITY]);
    let out = simplify(&mesh, Target::Triangles(2), &SimplifyOptions::default()).expect("simplify");
    assert_eq!(out.report.triangles_out, 2);
    assert!(out.report.error < 1e-6, "error {}", out.report.error);
    let b = out.mesh.bounds();
    assert!(
        (b.min - Vec3::ZERO).length() < 1e-6 && (b.max - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-6
    );
    // UVs were (x, y) everywhere; interpolation on collapse keeps them right.
    let sub = &out.mesh.submeshes[0];
    for (p, uv) in sub.positions.iter().zip(sub.uvs.as_ref().expect("uvs")) {
        assert!((Vec2::new(p.x, p.y) - *uv).length() < 1e-5, "{p} {uv}");
    }
}

#[test]
fn a_mirrored_instance_gives_the_same_error_as_its_twin() {
    let bumpy = sphere(12, 16, |d| {
        0.1 * (3.0 * d.x).sin() * (2.0 * d.z + d.y).cos()
    });
    let t = Affine3A::from_scale_rotation_translation(
        Vec3::new(2.0, 1.0, 0.5),
        Quat::from_rotation_z(0.3),
        Vec3::new(3.0, 0.0, 1.0),
    );
    let mirror = t * Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    let plain = simplify(
        &single(bumpy.clone(), &[t]),
        Target::Ratio(0.3),
        &SimplifyOptions::default(),
    )
    .expect("simplify");
    let mirrored = simplify(
        &single(bumpy, &[mirror]),
        Target::Ratio(0.3),
        &SimplifyOptions::default(),
    )
    .expect("simplify");
    assert_eq!(plain.report.triangles_out, mirrored.report.triangles_out);
    assert!(plain.report.error > 0.0);
    let rel = (plain.report.error - mirrored.report.error).abs() / plain.report.error;
    assert!(
        rel < 1e-6,
        "{} vs {}",
        plain.report.error,
        mirrored.report.error
    );
}

#[test]
fn a_seam_stays_a_seam() {
    let mesh = single(seamed_grid(8), &[Affine3A::IDENTITY]);
    let out = simplify(&mesh, Target::Ratio(0.1), &SimplifyOptions::default()).expect("simplify");
    assert!(
        out.report.triangles_out < 20,
        "{}",
        out.report.triangles_out
    );
    let sub = &out.mesh.submeshes[0];
    let uvs = sub.uvs.as_ref().expect("uvs");
    for t in sub.indices.chunks_exact(3) {
        // A triangle lies wholly on one side of the seam, and its UVs still follow position.
        let right = uvs[t[0] as usize].x >= 1.0;
        for &i in t {
            let (p, uv) = (sub.positions[i as usize], uvs[i as usize]);
            assert_eq!(uv.x >= 1.0, right, "triangle straddles the seam");
            let expected = Vec2::new(if right { p.x + 1.0 } else { p.x }, p.y);
            assert!((uv - expected).length() < 1e-5, "uv {uv} at {p}");
            if right {
                assert!(p.x >= 0.5 - 1e-6);
            } else {
                assert!(p.x <= 0.5 + 1e-6);
            }
        }
    }
    // The seam is still there: positions on x = 0.5 carry two UVs.
    let on_seam: Vec<usize> = (0..sub.positions.len())
        .filter(|&i| (sub.positions[i].x - 0.5).abs() < 1e-6)
        .collect();
    assert!(on_seam.iter().any(|&i| uvs[i].x >= 1.0) && on_seam.iter().any(|&i| uvs[i].x < 1.0));
}

#[test]
fn one_instance_ias_equals_the_quadric_baseline() {
    let s = sphere(10, 14, |d| 0.05 * (5.0 * d.x).sin());
    let t = Affine3A::from_scale_rotation_translation(
        Vec3::splat(2.0),
        Quat::from_rotation_x(1.0),
        Vec3::ONE,
    );
    let mesh = single(s, &[t]);
    let ias = simplify(&mesh, Target::Ratio(0.25), &SimplifyOptions::default()).expect("ias");
    let qem = simplify_qem(&mesh, Target::Ratio(0.25), &SimplifyOptions::default()).expect("qem");
    assert_eq!(ias.report.triangles_out, qem.report.triangles_out);
    let rel = (ias.report.error - qem.report.error).abs() / qem.report.error.max(1e-12);
    assert!(rel < 1e-3, "{} vs {}", ias.report.error, qem.report.error);
}

#[test]
fn instances_multiply_the_count_removed_per_collapse() {
    let transforms: Vec<Affine3A> = (0..7)
        .map(|k| Affine3A::from_translation(Vec3::new(3.0 * k as f32, 0.0, 0.0)))
        .collect();
    let mesh = single(grid(6, |x, y| 0.1 * (x * 7.0).sin() * y), &transforms);
    let out = simplify(&mesh, Target::Ratio(0.5), &SimplifyOptions::default()).expect("simplify");
    assert_eq!(out.report.triangles_in, 72 * 7);
    assert_eq!(out.report.triangles_out % 7, 0);
    assert_eq!(out.report.triangles_out, out.mesh.expanded_triangle_count());
    assert!(out.report.triangles_out <= 36 * 7);
}

#[test]
fn a_bad_ratio_is_refused() {
    let mesh = single(tetrahedron(), &[Affine3A::IDENTITY]);
    for r in [-0.1, 1.5, f64::NAN] {
        assert!(simplify(&mesh, Target::Ratio(r), &SimplifyOptions::default()).is_err());
    }
}

fn arb_transform() -> impl Strategy<Value = Affine3A> {
    (
        prop::array::uniform3(0.2f32..3.0),
        prop::array::uniform3(-3.0f32..3.0),
        prop::array::uniform3(-10.0f32..10.0),
        any::<bool>(),
    )
        .prop_map(|(s, r, t, mirror)| {
            let mut scale = Vec3::from(s);
            if mirror {
                scale.x = -scale.x;
            }
            Affine3A::from_scale_rotation_translation(
                scale,
                Quat::from_euler(glam::EulerRot::XYZ, r[0], r[1], r[2]),
                Vec3::from(t),
            )
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn simplification_keeps_its_promises(
        n in 2u32..9,
        amp in 0.0f32..0.3,
        freq in 0.5f32..6.0,
        transforms in prop::collection::vec(arb_transform(), 1..6),
        ratio in 0.0f64..1.0,
        degenerate in any::<bool>(),
    ) {
        let mut sub = grid(n, |x, y| amp * (freq * x).sin() * (freq * y + 1.0).cos());
        if degenerate {
            // A zero-area sliver and a triangle with a repeated index.
            sub.indices.extend([0, 1, 1, 0, n + 1, 0]);
        }
        let mesh = InstancedMesh {
            submeshes: vec![sub.clone(), sphere(4 + n, 6 + n, |d| amp * d.x)],
            instances: transforms.iter().enumerate().map(|(k, &transform)| Instance { submesh: k % 2, transform }).collect(),
            materials: Vec::new(),
            textures: Vec::new(),
        };
        let mut workspace = Workspace::new();
        let out = simplify_with(&mesh, Target::Ratio(ratio), &SimplifyOptions::default(), &mut workspace).expect("simplify");
        out.mesh.validate().expect("valid output");
        // The engine's own state: topology, and no triangle turned over from its input normal.
        prop_assert_eq!(workspace.validate(), Ok(()));
        prop_assert!(out.report.triangles_out <= out.report.triangles_in);
        prop_assert_eq!(out.report.triangles_out, out.mesh.expanded_triangle_count());
        // No flips. The engine's promise: in every instance, no triangle ends up facing more
        // than 90 degrees away from the normal it had in the input. On a height field whose
        // input normals lie within theta of up (world space, per instance), every output
        // normal therefore lies within 90 degrees + theta of up: a triangle turned over
        // (facing down) breaks it, and so does a chain of small turns that adds up.
        let cofactor = |a: &Affine3A| {
            let m = a.matrix3;
            glam::Mat3::from_cols(
                Vec3::from(m.y_axis).cross(Vec3::from(m.z_axis)),
                Vec3::from(m.z_axis).cross(Vec3::from(m.x_axis)),
                Vec3::from(m.x_axis).cross(Vec3::from(m.y_axis)),
            )
        };
        // The grid is input submesh 0; `kept` says where it went (`None`: it lost every
        // triangle, and a sphere simplified to a few vertices may lie inside the grid's box).
        prop_assert_eq!(out.kept.len(), mesh.submeshes.len());
        if let Some(gi) = out.kept[0] {
            let g = &out.mesh.submeshes[gi];
            for inst in out.mesh.instances.iter().filter(|i| i.submesh == gi) {
                let cof = cofactor(&inst.transform);
                let up = cof * Vec3::Z;
                let theta = sub
                    .indices
                    .chunks_exact(3)
                    .map(|t| cof * face_normal(&sub, t))
                    .filter(|n| n.length() > 1e-7)
                    .map(|n| n.angle_between(up))
                    .fold(0.0f32, f32::max);
                for t in g.indices.chunks_exact(3) {
                    let n = cof * face_normal(g, t);
                    if n.length() > 1e-7 {
                        let angle = n.angle_between(up);
                        prop_assert!(
                            angle <= std::f32::consts::FRAC_PI_2 + theta + 1e-3,
                            "triangle turned {} degrees from up; input normals were within {}",
                            angle.to_degrees(),
                            theta.to_degrees()
                        );
                    }
                }
            }
        }
    }
}
