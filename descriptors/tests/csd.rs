//! Tests of the Color Structure Descriptor on charted textures: the HMMD quantiser on known
//! colours, hand-built models whose descriptors follow from the definition, the rules of
//! charting (unused texels, repeats, masks), invariance under rigid instances, the shared
//! models, and a property test over random small models.

use std::io::Cursor;
use std::path::Path;

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use horizon_descriptors::csd::{
    color_structure, quantize_amplitude, unify_bin, CsdOptions, Hmmd, CSD_BINS,
};
use horizon_descriptors::DescriptorError;
use horizon_mesh::{
    import_file, AlphaMode, ImportOptions, Instance, InstancedMesh, Material, Submesh, Texture,
    TextureRef, Wrap,
};
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

const RED: [u8; 3] = [255, 0, 0];
const GREEN: [u8; 3] = [0, 255, 0];
const BLUE: [u8; 3] = [0, 0, 255];
const WHITE: [u8; 3] = [255, 255, 255];

/// The descriptor bin a single sRGB colour lands in.
fn bin_of(rgb: [u8; 3]) -> usize {
    unify_bin(Hmmd::from_rgb8(rgb).bin_256())
}

/// A PNG-encoded texture of `w x h` texels coloured by `texel(x, y)`.
fn texture(w: u32, h: u32, wrap: Wrap, texel: impl Fn(u32, u32) -> [u8; 4]) -> Texture {
    let image = image::RgbaImage::from_fn(w, h, |x, y| image::Rgba(texel(x, y)));
    let mut bytes = Vec::new();
    image
        .write_to(&mut Cursor::new(&mut bytes), image::ImageFormat::Png)
        .expect("PNG encoding of a small image");
    Texture {
        bytes,
        mime_type: "image/png".into(),
        size: (w, h),
        wrap_u: wrap,
        wrap_v: wrap,
    }
}

fn opaque(rgb: [u8; 3]) -> [u8; 4] {
    [rgb[0], rgb[1], rgb[2], 255]
}

/// A material of one flat colour given in sRGB bytes (stored linear, as glTF does).
fn flat(rgb: [u8; 3]) -> Material {
    let linear = |c: u8| {
        let s = f32::from(c) / 255.0;
        if s <= 0.04045 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        }
    };
    Material {
        base_color_factor: Vec4::new(linear(rgb[0]), linear(rgb[1]), linear(rgb[2]), 1.0),
        ..Material::default()
    }
}

/// A white material showing texture `texture`.
fn textured(texture: usize) -> Material {
    Material {
        base_color_texture: Some(TextureRef {
            texture,
            transform: None,
        }),
        ..Material::default()
    }
}

/// The unit square in the XY plane with UVs spanning `uv_min..uv_max`.
fn quad(material: usize, uv_min: Vec2, uv_max: Vec2) -> Submesh {
    Submesh {
        positions: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ],
        uvs: Some(vec![
            Vec2::new(uv_min.x, uv_min.y),
            Vec2::new(uv_max.x, uv_min.y),
            Vec2::new(uv_max.x, uv_max.y),
            Vec2::new(uv_min.x, uv_max.y),
        ]),
        indices: vec![0, 1, 2, 0, 2, 3],
        material: Some(material),
        ..Submesh::default()
    }
}

/// One instance of each submesh at the identity.
fn model(
    submeshes: Vec<Submesh>,
    materials: Vec<Material>,
    textures: Vec<Texture>,
) -> InstancedMesh {
    let instances = (0..submeshes.len())
        .map(|submesh| Instance {
            submesh,
            transform: Affine3A::IDENTITY,
        })
        .collect();
    InstancedMesh {
        submeshes,
        instances,
        materials,
        textures,
    }
}

fn csd(mesh: &InstancedMesh) -> [f32; CSD_BINS] {
    color_structure(mesh, &CsdOptions::default()).expect("descriptor of a valid model")
}

fn l1(a: &[f32; CSD_BINS], b: &[f32; CSD_BINS]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum()
}

/// All bins zero except those listed.
fn only(bins: &[(usize, f32)]) -> [f32; CSD_BINS] {
    let mut out = [0.0; CSD_BINS];
    for &(b, v) in bins {
        out[b] = v;
    }
    out
}

fn shared_model(name: &str) -> InstancedMesh {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/models")
        .join(name);
    import_file(&path, &ImportOptions::trusted())
        .unwrap_or_else(|e| panic!("{name}: {e}"))
        .mesh
}

const SHARED_MODELS: [&str; 8] = [
    "BoxTextured/BoxTextured.glb",
    "CesiumMilkTruck/CesiumMilkTruck.glb",
    "DamagedHelmet/DamagedHelmet.glb",
    "GlassVaseFlowers/GlassVaseFlowers.glb",
    "SimpleInstancing/SimpleInstancing.glb",
    "NegativeScaleTest/NegativeScaleTest.glb",
    "GpuInstancesMetadata/GpuInstancesMetadata.gltf",
    "bunny_trimesh/bunny.ply",
];

// ---------------------------------------------------------------------------------------------
// HMMD and the quantisers
// ---------------------------------------------------------------------------------------------

#[test]
fn hmmd_of_known_colours() {
    // Hue is HSV's; sum is (max + min) / 2 rounded up at .5; diff is max - min.
    assert_eq!(
        Hmmd::from_rgb8([0, 0, 0]),
        Hmmd {
            hue: 0,
            sum: 0,
            diff: 0
        }
    );
    assert_eq!(
        Hmmd::from_rgb8(WHITE),
        Hmmd {
            hue: 0,
            sum: 255,
            diff: 0
        }
    );
    assert_eq!(
        Hmmd::from_rgb8(RED),
        Hmmd {
            hue: 0,
            sum: 128,
            diff: 255
        }
    );
    assert_eq!(
        Hmmd::from_rgb8(GREEN),
        Hmmd {
            hue: 120,
            sum: 128,
            diff: 255
        }
    );
    assert_eq!(
        Hmmd::from_rgb8(BLUE),
        Hmmd {
            hue: 240,
            sum: 128,
            diff: 255
        }
    );
    assert_eq!(
        Hmmd::from_rgb8([128, 128, 128]),
        Hmmd {
            hue: 0,
            sum: 128,
            diff: 0
        }
    );
    // Magenta (255, 0, 255): blue is max, hue 4 + (255 - 0) / 255 sextants = 300 degrees.
    assert_eq!(Hmmd::from_rgb8([255, 0, 255]).hue, 300);
    // A hue of 359.6 rounds to 360, which the quantiser folds back to the red quadrant.
    let almost_red = Hmmd::from_rgb8([255, 0, 2]);
    assert_eq!(almost_red.hue, 360);
    assert_eq!(almost_red.bin_32(), 0);
}

#[test]
fn thirty_two_bin_quantiser_on_known_colours() {
    // Saturated colours (diff >= 110) take bins 0..=3 by hue quadrant: red and yellow (hue 0,
    // 60) are quadrant 0, green (120) 1, cyan (180) and blue (240) 2, magenta (300) 3.
    for (rgb, bin) in [
        (RED, 0),
        ([255, 255, 0], 0),
        (GREEN, 1),
        ([0, 255, 255], 2),
        (BLUE, 2),
        ([255, 0, 255], 3),
    ] {
        assert_eq!(Hmmd::from_rgb8(rgb).bin_32(), bin, "{rgb:?}");
        assert_eq!(bin_of(rgb), bin, "{rgb:?} through the 256 cells");
    }
    // Greys (diff < 6) take bins 24..=31 by sum: 8 equal slices of 0..=255.
    for (level, bin) in [
        (0, 24),
        (31, 24),
        (33, 25),
        (64, 26),
        (128, 28),
        (200, 30),
        (255, 31),
    ] {
        assert_eq!(Hmmd::from_rgb8([level; 3]).bin_32(), bin, "grey {level}");
        assert_eq!(
            bin_of([level; 3]),
            bin,
            "grey {level} through the 256 cells"
        );
    }
    // Nearly grey (diff 5) is still grey; diff 6 starts the moderate subspace.
    assert_eq!(Hmmd::from_rgb8([100, 100, 105]).bin_32(), 27);
    // (150, 120, 120): diff 30, hue 0, sum 135 -> moderate subspace (bins 8..=23), hue
    // quadrant 0, sum slice floor((135 - 3) * 4 / 249) = 2 -> bin 10.
    assert_eq!(Hmmd::from_rgb8([150, 120, 120]).bin_32(), 10);
    // (200, 120, 120): diff 80 -> strong subspace (bins 4..=7), hue quadrant 0.
    assert_eq!(Hmmd::from_rgb8([200, 120, 120]).bin_32(), 4);
    // Black and white in the 256 cells: the grey subspace comes last (224..=255).
    assert_eq!(Hmmd::from_rgb8([0, 0, 0]).bin_256(), 224);
    assert_eq!(Hmmd::from_rgb8(WHITE).bin_256(), 255);
}

#[test]
fn amplitude_quantisation_is_mpeg7s() {
    // Segments [0, 1e-12) [.., 0.037) [.., 0.08) [.., 0.195) [.., 0.32) [.., 1] get
    // 1, 25, 20, 35, 35 and 140 codes.
    assert_eq!(quantize_amplitude(0.0), 0);
    assert_eq!(quantize_amplitude(0.01), 1 + (0.01 * 25.0 / 0.037) as u8);
    assert_eq!(
        quantize_amplitude(0.5),
        116 + ((0.5 - 0.32) * 140.0 / 0.68) as u8
    );
    assert_eq!(quantize_amplitude(1.0), 255);
}

// ---------------------------------------------------------------------------------------------
// Untextured models
// ---------------------------------------------------------------------------------------------

#[test]
fn single_colour_model_fills_one_bin() {
    // Every element position on a one-colour surface holds that colour: value 1 -> 255.
    let mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![flat(RED)],
        vec![],
    );
    assert_eq!(csd(&mesh), only(&[(0, 255.0)]));
    // The default material is white.
    let mut white = mesh.clone();
    white.submeshes[0].material = None;
    assert_eq!(csd(&white), only(&[(31, 255.0)]));
}

#[test]
fn two_colours_of_equal_area_split_the_mass() {
    // Red and blue unit squares: each bin holds 0.5, which MPEG-7 codes as
    // 116 + floor((0.5 - 0.32) * 140 / 0.68) = 153.
    let mesh = model(
        vec![
            quad(0, Vec2::ZERO, Vec2::ONE),
            quad(1, Vec2::ZERO, Vec2::ONE),
        ],
        vec![flat(RED), flat(BLUE)],
        vec![],
    );
    assert_eq!(csd(&mesh), only(&[(0, 153.0), (2, 153.0)]));
}

#[test]
fn vertex_colours_tint_the_base_colour() {
    // A white material whose vertices are all pure linear green shows green.
    let mut sub = quad(0, Vec2::ZERO, Vec2::ONE);
    sub.colors = Some(vec![Vec4::new(0.0, 1.0, 0.0, 1.0); 4]);
    let mesh = model(vec![sub], vec![Material::default()], vec![]);
    assert_eq!(csd(&mesh), only(&[(1, 255.0)]));
}

// ---------------------------------------------------------------------------------------------
// Charting
// ---------------------------------------------------------------------------------------------

/// 32 x 32 texels: red on the left half, blue on the right.
fn red_blue_halves(wrap: Wrap) -> Texture {
    texture(32, 32, wrap, |x, _| opaque(if x < 16 { RED } else { BLUE }))
}

#[test]
fn a_textured_square_measures_its_texture() {
    // The 32 x 32 chart (k = 1, since 1024 texels is far below 2^16). An anchor at column x
    // sees columns x-4..=x+3: red for x <= 19 (20 of 32 columns), blue for x >= 13 (19 of
    // 32). 0.625 -> 116 + floor(0.305 * 140 / 0.68) = 178; 0.59375 -> 172.
    let mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![textured(0)],
        vec![red_blue_halves(Wrap::Repeat)],
    );
    assert_eq!(csd(&mesh), only(&[(0, 178.0), (2, 172.0)]));
}

#[test]
fn repeats_count() {
    // The same square and texture, once and tiled 4 x 1: the tiled chart has four times as
    // many red-blue borders, so more element positions see both colours.
    let once = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![textured(0)],
        vec![red_blue_halves(Wrap::Repeat)],
    );
    let mut tiled = once.clone();
    tiled.submeshes[0] = quad(0, Vec2::ZERO, Vec2::new(4.0, 1.0));
    let (a, b) = (csd(&once), csd(&tiled));
    assert!(l1(&a, &b) > 20.0, "{a:?} vs {b:?}");
    // Red columns 0..16, 32..48, 64..80 and 96..112 of 128: red is seen from anchors 0..=19,
    // 29..=51, 61..=83 and 93..=115, 89 of 128 = 0.6953 -> 116 + floor(0.3753 * 205.88)
    // = 193.
    assert_eq!(b[0], 193.0);
    // Mirrored repeat shows the same colours with half the borders (blue meets blue).
    let mut mirrored = tiled.clone();
    mirrored.textures[0] = red_blue_halves(Wrap::MirroredRepeat);
    let c = csd(&mirrored);
    assert!(c[0] < b[0] && c[2] < b[2], "{c:?} vs {b:?}");
}

#[test]
fn unused_texels_do_not_count() {
    // The square maps only the left half of a 64 x 32 texture, which holds red and green
    // stripes; the right half is blue in one texture and white in the other. Same descriptor,
    // and neither blue nor white shows.
    let stripes = |right: [u8; 3]| {
        texture(64, 32, Wrap::Repeat, move |x, y| {
            opaque(if x >= 32 {
                right
            } else if (y / 4) % 2 == 0 {
                RED
            } else {
                GREEN
            })
        })
    };
    let mesh = |right| {
        model(
            vec![quad(0, Vec2::ZERO, Vec2::new(0.5, 1.0))],
            vec![textured(0)],
            vec![stripes(right)],
        )
    };
    let (a, b) = (csd(&mesh(BLUE)), csd(&mesh(WHITE)));
    assert_eq!(a, b);
    assert_eq!(a[bin_of(BLUE)], 0.0);
    assert_eq!(a[bin_of(WHITE)], 0.0);
    assert!(a[bin_of(RED)] > 0.0 && a[bin_of(GREEN)] > 0.0);
}

#[test]
fn clamped_uvs_stretch_the_edge() {
    // UVs 0..4 on a clamped red|blue texture: only the first 16 of 128 chart columns are red,
    // the rest repeat the blue edge texel.
    let mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::new(4.0, 1.0))],
        vec![textured(0)],
        vec![red_blue_halves(Wrap::ClampToEdge)],
    );
    let d = csd(&mesh);
    // Red is seen from anchors 0..=19 (20 of 128), blue from 13..=127 (115 of 128).
    assert_eq!(d[0], f32::from(quantize_amplitude(20.0 / 128.0)));
    assert_eq!(d[2], f32::from(quantize_amplitude(115.0 / 128.0)));
}

#[test]
fn texture_transform_and_base_colour_apply() {
    // KHR_texture_transform with scale 0.5 maps the square to the red half only.
    let mut half = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![textured(0)],
        vec![red_blue_halves(Wrap::Repeat)],
    );
    half.materials[0].base_color_texture = Some(TextureRef {
        texture: 0,
        transform: Some(horizon_mesh::UvTransform {
            offset: Vec2::ZERO,
            rotation: 0.0,
            scale: Vec2::new(0.5, 1.0),
        }),
    });
    assert_eq!(csd(&half), only(&[(0, 255.0)]));
    // A black base colour factor turns every texel black (grey bin 24).
    let mut black = half.clone();
    black.materials[0].base_color_factor = Vec4::new(0.0, 0.0, 0.0, 1.0);
    assert_eq!(csd(&black), only(&[(24, 255.0)]));
}

#[test]
fn masked_texels_are_cut_out() {
    // The right half is blue with alpha 0: under a Mask material it is not drawn.
    let tex = texture(32, 32, Wrap::Repeat, |x, _| {
        if x < 16 {
            opaque(RED)
        } else {
            [0, 0, 255, 0]
        }
    });
    let mut mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![textured(0)],
        vec![tex],
    );
    mesh.materials[0].alpha_mode = AlphaMode::Mask { cutoff: 0.5 };
    assert_eq!(csd(&mesh), only(&[(0, 255.0)]));
    // Beside an untextured green square of the same area, the masked square weighs only its
    // visible half: green holds 2/3 of the visible surface.
    let mut beside = mesh.clone();
    beside.submeshes.push(quad(1, Vec2::ZERO, Vec2::ONE));
    beside.materials.push(flat(GREEN));
    beside.instances.push(Instance {
        submesh: 1,
        transform: Affine3A::IDENTITY,
    });
    let q = |v: f64| f32::from(quantize_amplitude(v));
    assert_eq!(csd(&beside), only(&[(0, q(1.0 / 3.0)), (1, q(2.0 / 3.0))]));
    // Opaque, the blue shows.
    mesh.materials[0].alpha_mode = AlphaMode::Opaque;
    assert!(csd(&mesh)[2] > 0.0);
}

#[test]
fn collapsed_uvs_show_the_texel_they_point_at() {
    // Every UV is the centre of texel (24, 5), in the blue half: a palette-style mapping
    // whose footprint covers no texel centre still shows blue.
    let point = Vec2::new(24.5 / 32.0, 5.5 / 32.0);
    let mesh = model(
        vec![quad(0, point, point)],
        vec![textured(0)],
        vec![red_blue_halves(Wrap::Repeat)],
    );
    assert_eq!(csd(&mesh), only(&[(2, 255.0)]));
}

#[test]
fn textured_and_untextured_surfaces_weigh_by_area() {
    // A red textured unit square and a blue untextured square of area 3: blue holds 3/4,
    // red 1/4.
    let mut big = quad(1, Vec2::ZERO, Vec2::ONE);
    for p in &mut big.positions {
        *p *= 3f32.sqrt();
    }
    let mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::new(0.5, 1.0)), big],
        vec![textured(0), flat(BLUE)],
        vec![red_blue_halves(Wrap::Repeat)],
    );
    let d = csd(&mesh);
    assert_eq!(d[0], f32::from(quantize_amplitude(0.25)));
    assert_eq!(d[2], f32::from(quantize_amplitude(0.75)));
}

#[test]
fn large_textures_are_subsampled() {
    // A 1024 x 1024 texture of 64-texel red and blue stripes, used whole: the footprint is
    // 2^20 texels, so k = 2^round(10 - 8) = 4 and the chart is 256 x 256 cells, in which a
    // stripe is 16 cells wide (the jittered samples stay inside their stripe: 64 is a
    // multiple of 4). Red stripe j covers columns 32j..32j+16 and is seen from anchors
    // 32j-3..=32j+19: 20 + 7 x 23 = 181 of 256 columns; blue from 32j+13..=32j+35, clipped
    // at the last column: 7 x 23 + 19 = 180. At k = 1 both would be near 1.
    let tex = texture(1024, 1024, Wrap::Repeat, |x, _| {
        opaque(if (x / 64) % 2 == 0 { RED } else { BLUE })
    });
    let mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![textured(0)],
        vec![tex],
    );
    let q = |v: f64| f32::from(quantize_amplitude(v));
    assert_eq!(
        csd(&mesh),
        only(&[(0, q(181.0 / 256.0)), (2, q(180.0 / 256.0))])
    );
}

// ---------------------------------------------------------------------------------------------
// Instances
// ---------------------------------------------------------------------------------------------

/// A textured square and two untextured squares (red, green), each instanced twice.
fn instanced_scene() -> InstancedMesh {
    let mut mesh = model(
        vec![
            quad(0, Vec2::ZERO, Vec2::new(2.0, 1.0)),
            quad(1, Vec2::ZERO, Vec2::ONE),
            quad(2, Vec2::ZERO, Vec2::ONE),
        ],
        vec![textured(0), flat(RED), flat(GREEN)],
        vec![red_blue_halves(Wrap::Repeat)],
    );
    mesh.instances = (0..6)
        .map(|i| Instance {
            submesh: i % 3,
            transform: Affine3A::from_translation(Vec3::new(i as f32 * 2.0, 0.0, 0.0)),
        })
        .collect();
    mesh
}

#[test]
fn rigid_instance_transforms_do_not_change_the_descriptor() {
    let base = instanced_scene();
    let reference = csd(&base);
    let motions = [
        Affine3A::from_rotation_translation(
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
            Vec3::new(10.0, -3.0, 5.0),
        ),
        Affine3A::from_quat(Quat::from_rotation_z(1.3)),
        // A mirror is rigid too.
        Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
    ];
    for motion in motions {
        let mut moved = base.clone();
        for (i, inst) in moved.instances.iter_mut().enumerate() {
            // Move each instance differently, and some twice.
            inst.transform = if i % 2 == 0 {
                motion * inst.transform
            } else {
                motion * motion * inst.transform
            };
        }
        let d = csd(&moved);
        // Areas move by rounding only; at most one amplitude step when a value sits on a
        // quantisation boundary.
        for (a, b) in d.iter().zip(&reference) {
            assert!((a - b).abs() <= 1.0, "{d:?} vs {reference:?}");
        }
    }
}

#[test]
fn scaling_a_part_shifts_the_proportions() {
    // Red and blue squares of equal area split 0.5 / 0.5. Scaling red uniformly by 2 makes
    // it 4/5 of the area; stretching it along X only (a non-similarity, the general area
    // path) makes it 2/3; stretching it along Z, normal to the square, changes nothing.
    let mut mesh = model(
        vec![
            quad(0, Vec2::ZERO, Vec2::ONE),
            quad(1, Vec2::ZERO, Vec2::ONE),
        ],
        vec![flat(RED), flat(BLUE)],
        vec![],
    );
    let q = |v: f64| f32::from(quantize_amplitude(v));
    for (scale, red) in [
        (Vec3::splat(2.0), 0.8),
        (Vec3::new(2.0, 1.0, 1.0), 2.0 / 3.0),
        (Vec3::new(1.0, 1.0, 5.0), 0.5),
    ] {
        mesh.instances[0].transform = Affine3A::from_scale(scale);
        let d = csd(&mesh);
        assert_eq!(d, only(&[(0, q(red)), (2, q(1.0 - red))]), "scale {scale}");
    }
    // Two instances of the blue square weigh twice.
    mesh.instances[0].transform = Affine3A::IDENTITY;
    mesh.instances.push(Instance {
        submesh: 1,
        transform: Affine3A::from_translation(Vec3::X * 5.0),
    });
    assert_eq!(csd(&mesh), only(&[(0, q(1.0 / 3.0)), (2, q(2.0 / 3.0))]));
}

// ---------------------------------------------------------------------------------------------
// Errors and ugly input
// ---------------------------------------------------------------------------------------------

#[test]
fn models_without_area_are_empty() {
    let nothing = InstancedMesh::default();
    assert_eq!(
        color_structure(&nothing, &CsdOptions::default()),
        Err(DescriptorError::Empty)
    );
    // A square without instances, and a degenerate triangle, have no surface.
    let mut uninstanced = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![flat(RED)],
        vec![],
    );
    uninstanced.instances.clear();
    assert_eq!(
        color_structure(&uninstanced, &CsdOptions::default()),
        Err(DescriptorError::Empty)
    );
    let mut flat_tri = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![flat(RED)],
        vec![],
    );
    flat_tri.submeshes[0].indices = vec![0, 1, 1];
    assert_eq!(
        color_structure(&flat_tri, &CsdOptions::default()),
        Err(DescriptorError::Empty)
    );
    // A zero scale flattens everything.
    let mut squashed = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![flat(RED)],
        vec![],
    );
    squashed.instances[0].transform = Affine3A::from_scale(Vec3::ZERO);
    assert_eq!(
        color_structure(&squashed, &CsdOptions::default()),
        Err(DescriptorError::Empty)
    );
}

#[test]
fn undecodable_textures_are_reported() {
    let mut tex = red_blue_halves(Wrap::Repeat);
    tex.bytes.truncate(20);
    let mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![flat(RED), textured(0)],
        vec![tex.clone(), tex],
    );
    // Texture 0 is never shown (material 0 is flat), so only a model that shows it fails.
    assert!(color_structure(&mesh, &CsdOptions::default()).is_ok());
    let mut shown = mesh.clone();
    shown.materials[0] = textured(1);
    assert!(matches!(
        color_structure(&shown, &CsdOptions::default()),
        Err(DescriptorError::Texture { texture: 1, .. })
    ));
}

#[test]
fn invalid_meshes_are_refused() {
    let mut mesh = model(
        vec![quad(0, Vec2::ZERO, Vec2::ONE)],
        vec![flat(RED)],
        vec![],
    );
    mesh.submeshes[0].uvs = Some(vec![Vec2::NAN; 4]);
    assert!(matches!(
        color_structure(&mesh, &CsdOptions::default()),
        Err(DescriptorError::InvalidMesh(_))
    ));
}

#[test]
fn huge_uvs_are_bounded() {
    // UVs far beyond any texture (1e30), spanning 2e6 repeats, or reaching f32's largest
    // values: charted with a capped number of repeats, with some colour showing.
    for (lo, hi) in [
        (Vec2::splat(1e30), Vec2::splat(1e30 + 1e24)),
        (Vec2::splat(-1e6), Vec2::splat(1e6)),
        (Vec2::new(0.0, 0.0), Vec2::new(3.0e38, 1.0)),
    ] {
        for wrap in [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge] {
            let mesh = model(
                vec![quad(0, lo, hi)],
                vec![textured(0)],
                vec![red_blue_halves(wrap)],
            );
            let d = csd(&mesh);
            assert!(d.iter().all(|v| (0.0..=255.0).contains(v)), "{d:?}");
            assert!(d.iter().any(|&v| v > 0.0));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Shared models
// ---------------------------------------------------------------------------------------------

#[test]
fn shared_models_give_finite_descriptors() {
    for name in SHARED_MODELS {
        let d = csd(&shared_model(name));
        assert!(
            d.iter()
                .all(|v| v.is_finite() && (0.0..=255.0).contains(v) && v.fract() == 0.0),
            "{name}: {d:?}"
        );
        assert!(d.iter().any(|&v| v > 0.0), "{name}: {d:?}");
    }
}

#[test]
fn a_slight_recolouring_is_closer_than_another_model() {
    let boxed = shared_model("BoxTextured/BoxTextured.glb");
    let truck = shared_model("CesiumMilkTruck/CesiumMilkTruck.glb");
    // 3% darker. (A hue tint is not slight for HMMD: white tinted by 5% green has diff 6 and
    // leaves the grey bins, as MPEG-7 intends.)
    let mut tinted = boxed.clone();
    tinted.materials[0].base_color_factor = Vec4::new(0.97, 0.97, 0.97, 1.0);
    let (b, t, r) = (csd(&boxed), csd(&truck), csd(&tinted));
    let (near, far) = (l1(&b, &r), l1(&b, &t));
    assert!(
        near < far / 4.0,
        "recoloured {near}, truck {far}: {b:?} {r:?} {t:?}"
    );
    assert_eq!(l1(&b, &b), 0.0);
}

// ---------------------------------------------------------------------------------------------
// Property test
// ---------------------------------------------------------------------------------------------

/// A random small model: up to three submeshes of up to six triangles, with random UVs
/// (sometimes huge), vertex colours, materials (flat, textured, masked) and instances
/// (mirrors, shears, zero scales included).
fn arbitrary_model() -> impl Strategy<Value = InstancedMesh> {
    let coordinate = prop_oneof![8 => -4.0f32..4.0, 1 => -1e7f32..1e7, 1 => Just(0.0f32)];
    let vertex = (
        prop::array::uniform3(-2.0f32..2.0),
        prop::array::uniform2(coordinate),
        prop::array::uniform4(0.0f32..1.0),
    );
    let submesh = (
        prop::collection::vec(vertex, 3..8),
        prop::collection::vec(any::<prop::sample::Index>(), 3..18),
        0usize..4,
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(|(vertices, picks, material, has_uvs, has_colors)| {
            let n = vertices.len();
            let count = picks.len() / 3 * 3;
            Submesh {
                positions: vertices.iter().map(|v| Vec3::from(v.0)).collect(),
                uvs: has_uvs.then(|| vertices.iter().map(|v| Vec2::from(v.1)).collect()),
                colors: has_colors.then(|| vertices.iter().map(|v| Vec4::from(v.2)).collect()),
                indices: picks[..count].iter().map(|p| p.index(n) as u32).collect(),
                material: Some(material),
                ..Submesh::default()
            }
        });
    let transform = (
        prop::array::uniform9(-2.0f32..2.0),
        prop::array::uniform3(-5.0f32..5.0),
    )
        .prop_map(|(m, t)| {
            Affine3A::from_mat3_translation(glam::Mat3::from_cols_array(&m), Vec3::from(t))
        });
    let texel = prop::array::uniform4(any::<u8>());
    (
        prop::collection::vec(submesh, 1..4),
        prop::collection::vec((0usize..3, transform), 1..5),
        prop::array::uniform4(prop::array::uniform4(0.0f32..1.0)),
        prop::collection::vec(texel, 16),
        prop::sample::select(vec![Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge]),
    )
        .prop_map(|(submeshes, instances, factors, texels, wrap)| {
            let instances = instances
                .into_iter()
                .map(|(s, transform)| Instance {
                    submesh: s % submeshes.len(),
                    transform,
                })
                .collect();
            let tex = texture(4, 4, wrap, |x, y| texels[(y * 4 + x) as usize]);
            let materials = vec![
                flat([200, 30, 30]),
                Material {
                    base_color_factor: Vec4::from(factors[1]),
                    ..textured(0)
                },
                Material {
                    base_color_factor: Vec4::from(factors[2]),
                    alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
                    ..textured(0)
                },
                Material {
                    base_color_factor: Vec4::from(factors[3]),
                    ..Material::default()
                },
            ];
            InstancedMesh {
                submeshes,
                instances,
                materials,
                textures: vec![tex],
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn random_models_give_valid_deterministic_descriptors(mesh in arbitrary_model()) {
        match color_structure(&mesh, &CsdOptions::default()) {
            Ok(d) => {
                prop_assert!(d.iter().all(|v| v.is_finite() && (0.0..=255.0).contains(v)));
                prop_assert!(d.iter().all(|v| v.fract() == 0.0));
                prop_assert_eq!(color_structure(&mesh, &CsdOptions::default()), Ok(d));
            }
            Err(e) => prop_assert_eq!(e, DescriptorError::Empty),
        }
    }
}
