//! The chain's invariants on generated models: along every chain error rises and triangles
//! and bytes fall; a model too small to simplify keeps its full level alone; mirrored and
//! sheared placements keep their winding at every level.

#![allow(clippy::unwrap_used)]

use glam::{Affine3A, Mat3, Vec3};
use horizon_levels::{build_chain, level_zero, texel_density, Chain, LevelOptions};
use horizon_mesh::{
    export_glb, import_bytes, ExportOptions, Format, ImportOptions, Instance, InstancedMesh,
    Submesh,
};
use horizon_worldgen::{distinct_building, generate_model};

fn chain_of(mesh: &InstancedMesh) -> (u64, Chain) {
    let bytes = export_glb(mesh, &ExportOptions::plain()).unwrap().len() as u64;
    (bytes, build_chain(mesh, bytes, &LevelOptions::default()))
}

fn check_monotone(mesh: &InstancedMesh, bytes: u64, chain: &Chain) {
    let mut before = level_zero(mesh, bytes);
    for (k, level) in chain.levels.iter().enumerate() {
        let info = &level.info;
        assert!(info.error >= before.error, "level {}: error fell", k + 1);
        assert!(
            info.triangles <= before.triangles,
            "level {}: triangles rose",
            k + 1
        );
        assert!(
            info.bytes < before.bytes,
            "level {}: bytes did not fall",
            k + 1
        );
        assert_eq!(info.bytes, level.glb.len() as u64);
        // The GLB reads back as a valid model with the triangles it claims.
        let back = import_bytes(&level.glb, Format::Glb, None, &ImportOptions::trusted())
            .unwrap()
            .mesh;
        back.validate().unwrap();
        assert_eq!(back.expanded_triangle_count(), info.triangles);
        before = info.clone();
    }
}

#[test]
fn along_every_chain_error_rises_and_triangles_and_bytes_fall() {
    let mut models: Vec<InstancedMesh> =
        ["maple-tree", "village-mesh", "patio-chair", "stonehenge"]
            .iter()
            .map(|name| generate_model(name, 3).unwrap())
            .collect();
    models.push(distinct_building(1, 7).unwrap());
    for mesh in &models {
        let (bytes, chain) = chain_of(mesh);
        eprintln!(
            "{} triangles, {} submeshes, {} instances, {bytes} bytes: {:?}",
            mesh.expanded_triangle_count(),
            mesh.submeshes.len(),
            mesh.instances.len(),
            chain
                .levels
                .iter()
                .map(|l| (l.info.triangles, l.info.bytes, l.info.error))
                .collect::<Vec<_>>()
        );
        assert!(chain.failure.is_none(), "{:?}", chain.failure);
        check_monotone(mesh, bytes, &chain);
        // The coarsest level is under half the model (a tree of 9,324 leaf placements keeps
        // them all: instances are a floor IAS does not go below).
        let last = chain.levels.last().map_or(bytes, |l| l.info.bytes);
        assert!(last * 2 < bytes, "{last} of {bytes} bytes");
    }
}

#[test]
fn textures_halve_and_the_texel_density_with_them() {
    let mesh = distinct_building(1, 11).unwrap();
    let full = texel_density(&mesh).expect("the building is textured");
    let (_, chain) = chain_of(&mesh);
    // The first level that halves the textures: half the texels along each side, about half
    // the density (the geometry may have moved a little).
    let mut before = full;
    let halved = chain
        .levels
        .iter()
        .map(|l| l.info.texel_density.unwrap())
        .find(|&d| {
            let found = d < 0.9 * before;
            if !found {
                before = d;
            }
            found
        })
        .expect("a level halves the textures");
    assert!(
        (halved / before - 0.5).abs() < 0.1,
        "{halved} against {before}"
    );
}

fn tetrahedron() -> Submesh {
    Submesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
        indices: vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3],
        ..Submesh::default()
    }
}

#[test]
fn a_model_too_small_to_simplify_gets_one_level() {
    let mesh = InstancedMesh {
        submeshes: vec![tetrahedron()],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..InstancedMesh::default()
    };
    let (_, chain) = chain_of(&mesh);
    assert!(chain.levels.is_empty());
    assert!(chain.failure.is_none());
}

#[test]
fn mirrored_and_sheared_placements_keep_their_winding_at_every_level() {
    let mut mesh = distinct_building(1, 5).unwrap();
    // Every part also placed mirrored, and sheared, beside the original.
    let mirror = Affine3A::from_translation(Vec3::new(60.0, 0.0, 0.0))
        * Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    let shear = Affine3A::from_translation(Vec3::new(0.0, 0.0, 60.0))
        * Affine3A::from_mat3(Mat3::from_cols(Vec3::X, Vec3::new(0.4, 1.0, 0.0), Vec3::Z));
    let originals = mesh.instances.clone();
    for m in [mirror, shear] {
        for inst in &originals {
            mesh.instances.push(Instance {
                submesh: inst.submesh,
                transform: m * inst.transform,
            });
        }
    }
    mesh.validate().unwrap();
    let (bytes, chain) = chain_of(&mesh);
    check_monotone(&mesh, bytes, &chain);
    assert!(!chain.levels.is_empty());
    // A closed building's summed oriented area is about zero per part, so compare what
    // faces outwards: the signed volume of each instance's triangles keeps its sign.
    let volume = |m: &InstancedMesh| -> Vec<f32> {
        let e = m.expand();
        let mut out = vec![0.0f32; m.instances.len()];
        for (t, tri) in e.indices.chunks_exact(3).enumerate() {
            let [a, b, c] = [0, 1, 2].map(|i| e.positions[tri[i] as usize]);
            out[e.triangle_instance[t] as usize] += a.dot(b.cross(c)) / 6.0;
        }
        out
    };
    let full = volume(&mesh);
    for level in &chain.levels {
        let back = import_bytes(&level.glb, Format::Glb, None, &ImportOptions::trusted())
            .unwrap()
            .mesh;
        let v = volume(&back);
        let (sum_full, sum_level): (f32, f32) = (full.iter().sum(), v.iter().sum());
        assert!(
            sum_full.signum() == sum_level.signum() && sum_level.abs() > 0.3 * sum_full.abs(),
            "the level turned inside out: {sum_level} against {sum_full}"
        );
    }
}

#[test]
fn alpha_masked_textures_keep_their_coverage_down_the_chain() {
    use horizon_mesh::{AlphaMode, Material, Texture, TextureRef, Wrap};
    // Leaves: smooth blobs of every size, opaque where a sum of waves is high, on a quad.
    let side = 512;
    let image = image::RgbaImage::from_fn(side, side, |x, y| {
        let shade = ((x * 7919 + y * 104_729) % 61) as u8;
        let (x, y) = (x as f32, y as f32);
        let f = (x * 0.21).sin() + (y * 0.17).sin() + ((x + y) * 0.13).sin() + (x * 0.05).cos();
        image::Rgba([90 + shade, 140, 60 + shade, if f > 0.8 { 255 } else { 0 }])
    });
    let mut png = Vec::new();
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let coverage = |img: &image::RgbaImage| {
        img.pixels().filter(|p| p.0[3] >= 128).count() as f64
            / f64::from(img.width() * img.height())
    };
    let quad = Submesh {
        positions: vec![
            Vec3::ZERO,
            Vec3::X * 4.0,
            Vec3::new(4.0, 4.0, 0.0),
            Vec3::Y * 4.0,
        ],
        uvs: Some(vec![
            glam::Vec2::new(0.0, 1.0),
            glam::Vec2::new(1.0, 1.0),
            glam::Vec2::new(1.0, 0.0),
            glam::Vec2::new(0.0, 0.0),
        ]),
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(0),
        ..Submesh::default()
    };
    let mesh = InstancedMesh {
        submeshes: vec![quad],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: vec![Material {
            base_color_texture: Some(TextureRef {
                texture: 0,
                transform: None,
            }),
            alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
            ..Material::default()
        }],
        textures: vec![Texture {
            bytes: png,
            mime_type: "image/png".into(),
            size: (side, side),
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::Repeat,
        }],
    };
    mesh.validate().unwrap();
    let (_, chain) = chain_of(&mesh);
    let full = coverage(&image);
    let mut halvings = 0;
    for level in &chain.levels {
        let back = import_bytes(&level.glb, Format::Glb, None, &ImportOptions::trusted())
            .unwrap()
            .mesh;
        let texels = back.textures[0].decode().unwrap();
        if texels.width() < side {
            halvings += 1;
        }
        let c = coverage(&texels);
        assert!(
            (c - full).abs() < 0.03,
            "{}x{}: coverage {c} against {full}",
            texels.width(),
            texels.height()
        );
    }
    assert!(halvings >= 2, "only {halvings} levels halve the texture");
}

#[test]
fn a_chain_that_fails_says_why_and_keeps_what_it_made() {
    // A texture whose header reads but whose pixels do not: the chain cannot halve it.
    let mut mesh = distinct_building(1, 2).unwrap();
    let bytes = export_glb(&mesh, &ExportOptions::plain()).unwrap().len() as u64;
    for t in &mut mesh.textures {
        let keep = t.bytes.len().min(64);
        t.bytes.truncate(keep);
    }
    let chain = build_chain(&mesh, bytes, &LevelOptions::default());
    let why = chain.failure.expect("the chain says it failed");
    assert!(why.contains("texture"), "{why}");
    assert!(!why.contains('\n'));
    // Whatever it made before the failure is a valid, smaller level.
    for level in &chain.levels {
        let back = import_bytes(&level.glb, Format::Glb, None, &ImportOptions::trusted())
            .unwrap()
            .mesh;
        back.validate().unwrap();
        assert!(level.info.bytes < bytes);
    }
}
