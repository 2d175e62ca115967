//! Tiny inputs whose right answer is obvious, wrapping, the byte budget and bad input.

mod common;

use common::*;
use glam::{Vec2, Vec3, Vec4};
use horizon_atlas::{build_atlas, build_atlas_with, AtlasError, AtlasOptions, TextureCache};
use horizon_mesh::model::{AlphaMode, InstancedMesh, Submesh, Texture, Wrap};
use image::Rgba;

#[test]
fn quadrant_of_a_texture_keeps_exactly_its_texels() {
    // UVs 0.5..1 x 0..0.5 of a 4x4 texture cover texels x 2..4, y 0..2: a 2x2 chart, which with
    // a 2-texel gutter on each side makes a 6x6 atlas whose centre is those four texels.
    let tex = gradient(4, 4);
    let input = mesh(
        vec![quad(
            box_uvs(Vec2::new(0.5, 0.0), Vec2::new(1.0, 0.5)),
            Some(0),
        )],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (out, report, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!((report.width, report.height), (6, 6));
    assert_eq!(report.charts, 1);
    assert_eq!(report.texel_scale, 1.0);
    assert_eq!(report.mime_type, "image/png");
    for y in 0..2 {
        for x in 0..2 {
            assert_eq!(atlas.get_pixel(2 + x, 2 + y), tex.get_pixel(2 + x, y));
        }
    }
    // The gutter repeats the edge: the atlas corner is the chart's corner texel (2, 0).
    assert_eq!(atlas.get_pixel(0, 0), tex.get_pixel(2, 0));
    assert_eq!(atlas.get_pixel(5, 5), tex.get_pixel(3, 1));
    // The quad's corners land on the chart's corners: texels 2 and 4 of the 6-wide atlas.
    let uvs = out.submeshes[0].uvs.as_ref().expect("uvs");
    let third = 2.0 / 6.0;
    let expected = box_uvs(Vec2::splat(third), Vec2::splat(2.0 * third));
    for (uv, want) in uvs.iter().zip(expected) {
        assert!((*uv - want).abs().max_element() < 1e-6, "{uv} vs {want}");
    }
}

#[test]
fn untextured_red_material_is_a_red_patch() {
    // Linear red (1, 0, 0) is sRGB (255, 0, 0); the 4x4 patch plus 2-texel gutters is 8x8, all
    // red, and every vertex samples its centre.
    let mut sub = quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0));
    sub.uvs = None;
    let input = mesh(
        vec![sub],
        vec![material(
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            None,
            AlphaMode::Opaque,
        )],
        vec![],
    );
    let (out, report, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!((report.width, report.height), (8, 8));
    assert_eq!(report.patches, 1);
    assert!(atlas.pixels().all(|p| *p == Rgba([255, 0, 0, 255])));
    let uvs = out.submeshes[0].uvs.as_ref().expect("uvs");
    assert!(uvs.iter().all(|&uv| uv == Vec2::splat(0.5)));
}

#[test]
fn factors_multiply_in_linear_light() {
    // A linear factor of 0.5 on a white texel is linear 0.5, which sRGB encodes as 188 (not the
    // 128 a multiplication of sRGB codes would give); a patch with factor 0.5 agrees.
    let white = image::RgbaImage::from_pixel(2, 2, Rgba([255, 255, 255, 255]));
    let input = mesh(
        vec![
            quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0)),
            quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(1)),
        ],
        vec![
            material(Vec4::new(0.5, 0.5, 0.5, 1.0), Some(0), AlphaMode::Opaque),
            material(Vec4::new(0.5, 0.5, 0.5, 1.0), None, AlphaMode::Opaque),
        ],
        vec![png_texture(&white, Wrap::Repeat)],
    );
    let (out, _, atlas) = atlased(&input, &AtlasOptions::default());
    for sub in &out.submeshes {
        for &uv in sub.uvs.as_ref().expect("uvs") {
            // Corners sit on chart edges; pull them a hair inside.
            let px = texel_at(&atlas, uv.clamp(Vec2::splat(0.001), Vec2::splat(0.999)));
            assert_eq!(px, Rgba([188, 188, 188, 255]));
        }
    }
}

#[test]
fn two_materials_become_one() {
    // A green patch and a blue patch, one double-sided: one material out, double-sided, both
    // submeshes on it, each sampling its own colour.
    let mut green = material(Vec4::new(0.0, 1.0, 0.0, 1.0), None, AlphaMode::Opaque);
    green.double_sided = true;
    let blue = material(Vec4::new(0.0, 0.0, 1.0, 1.0), None, AlphaMode::Opaque);
    let input = mesh(
        vec![
            quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0)),
            quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(1)),
        ],
        vec![green, blue],
        vec![],
    );
    let (out, report, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!(report.patches, 2);
    assert!(out.materials[0].double_sided);
    assert_eq!(out.materials[0].alpha_mode, AlphaMode::Opaque);
    let colour = |s: usize| texel_at(&atlas, out.submeshes[s].uvs.as_ref().expect("uvs")[0]);
    assert_eq!(colour(0), Rgba([0, 255, 0, 255]));
    assert_eq!(colour(1), Rgba([0, 0, 255, 255]));
}

#[test]
fn submeshes_sharing_a_material_share_its_patch() {
    // Two untextured submeshes of one material need one patch, not two.
    let red = material(Vec4::new(1.0, 0.0, 0.0, 1.0), None, AlphaMode::Opaque);
    let input = mesh(
        vec![
            quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0)),
            quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0)),
        ],
        vec![red],
        vec![],
    );
    let (_, report, _) = atlased(&input, &AtlasOptions::default());
    assert_eq!(report.charts, 1);
}

#[test]
fn overlapping_islands_of_one_texture_merge() {
    // Two separate quads (no shared vertices) over UVs 0..0.75 and 0.25..1 of one texture
    // overlap, so they share one 4x4 chart.
    let tex = gradient(4, 4);
    let input = mesh(
        vec![
            quad(box_uvs(Vec2::ZERO, Vec2::splat(0.75)), Some(0)),
            quad(box_uvs(Vec2::splat(0.25), Vec2::ONE), Some(0)),
        ],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (_, report, _) = atlased(&input, &AtlasOptions::default());
    assert_eq!(report.charts, 1);
    assert_eq!((report.width, report.height), (8, 8));
}

#[test]
fn tiles_that_fill_a_texture_share_one_chart_and_scattered_islands_do_not() {
    // Two disjoint quads over the left and right halves of an 8x8 texture (a box proxy's faces
    // side by side) fill their union: one 8x8 chart, one gutter.
    let tex = gradient(8, 8);
    let tiled = mesh(
        vec![
            quad(box_uvs(Vec2::ZERO, Vec2::new(0.5, 1.0)), Some(0)),
            quad(box_uvs(Vec2::new(0.5, 0.0), Vec2::ONE), Some(0)),
        ],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (out, report, atlas) = atlased(&tiled, &AtlasOptions::default());
    assert_eq!(report.charts, 1);
    assert_eq!((report.width, report.height), (12, 12));
    // Each quad still samples its own texels: a point 0.6 of the way across it lands on the
    // source texel under the same point.
    for s in 0..2 {
        let uvs = out.submeshes[s].uvs.as_ref().expect("uvs");
        let inside = uvs[0] + (uvs[2] - uvs[0]) * 0.6;
        let source = Vec2::new(0.5 * s as f32 + 0.3, 0.6) * 8.0;
        let want = tex.get_pixel(source.x as u32, source.y as u32);
        assert_eq!(texel_at(&atlas, inside), *want);
    }
    // Two one-texel islands in opposite corners fill 2 of 64 texels: two charts.
    let scattered = mesh(
        vec![
            quad(box_uvs(Vec2::ZERO, Vec2::splat(0.125)), Some(0)),
            quad(box_uvs(Vec2::splat(0.875), Vec2::ONE), Some(0)),
        ],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (_, report, _) = atlased(&scattered, &AtlasOptions::default());
    assert_eq!(report.charts, 2);
}

#[test]
fn repeat_and_mirror_wrapping_quads_sample_like_the_source() {
    // UVs 0..3 on a 4x4 texture span 12x12 source texels, three tiles. Every texel centre of
    // that range, remapped through the quad (an affine map), must show the wrapped source texel.
    for mode in [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge] {
        let tex = gradient(4, 4);
        let input = mesh(
            vec![quad(box_uvs(Vec2::ZERO, Vec2::splat(3.0)), Some(0))],
            vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
            vec![png_texture(&tex, mode)],
        );
        let (out, report, atlas) = atlased(&input, &AtlasOptions::default());
        assert_eq!(report.texel_scale, 1.0);
        assert_eq!((report.width, report.height), (16, 16));
        let uvs = out.submeshes[0].uvs.as_ref().expect("uvs");
        let (a0, a1) = (uvs[0], uvs[2]);
        for y in 0..12 {
            for x in 0..12 {
                let src = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) / 12.0;
                let uv = a0 + src * (a1 - a0);
                let want = tex.get_pixel(wrap(x, 4, mode), wrap(y, 4, mode));
                assert_eq!(texel_at(&atlas, uv), *want, "{mode:?} at texel ({x}, {y})");
            }
        }
    }
}

#[test]
fn tiling_beyond_the_cap_is_sampled_at_lower_density() {
    // UVs 0..40 tile a 4x4 texture forty times; the chart keeps at most 4 tiles (16 texels) per
    // axis, so the atlas is 16 + 4 = 20 texels wide at scale 1.
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::splat(40.0)), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&gradient(4, 4), Wrap::Repeat)],
    );
    let (_, report, _) = atlased(&input, &AtlasOptions::default());
    assert_eq!((report.width, report.height), (20, 20));
}

#[test]
fn uv_transform_is_applied_before_charting() {
    // Scale 0.5 with offset (0.5, 0) maps UVs 0..1 onto the quadrant 0.5..1 x 0..0.5: the same
    // 2x2 texels as the quadrant test.
    let tex = gradient(4, 4);
    let mut mat = material(Vec4::ONE, Some(0), AlphaMode::Opaque);
    mat.base_color_texture = Some(horizon_mesh::model::TextureRef {
        texture: 0,
        transform: Some(horizon_mesh::model::UvTransform {
            offset: Vec2::new(0.5, 0.0),
            rotation: 0.0,
            scale: Vec2::splat(0.5),
        }),
    });
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![mat],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (_, report, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!((report.width, report.height), (6, 6));
    assert_eq!(atlas.get_pixel(2, 2), tex.get_pixel(2, 0));
    assert_eq!(atlas.get_pixel(3, 3), tex.get_pixel(3, 1));
}

#[test]
fn alpha_modes_merge_to_the_strongest() {
    // Opaque + Mask(0.9) -> Mask(0.5) in a PNG; the mask's alpha 200/255 = 0.78 is below its own
    // cut-off 0.9 and so is baked as 0. Adding a Blend material makes the output Blend.
    let tex = image::RgbaImage::from_pixel(2, 2, Rgba([255, 255, 255, 200]));
    let mut materials = vec![
        material(Vec4::ONE, None, AlphaMode::Opaque),
        material(Vec4::ONE, Some(0), AlphaMode::Mask { cutoff: 0.9 }),
    ];
    let mut submeshes = vec![
        quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0)),
        quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(1)),
    ];
    let input = mesh(
        submeshes.clone(),
        materials.clone(),
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (out, report, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!(out.materials[0].alpha_mode, AlphaMode::Mask { cutoff: 0.5 });
    assert_eq!(report.mime_type, "image/png");
    assert_eq!(centre_texel(&out, &atlas, 0)[3], 255);
    assert_eq!(centre_texel(&out, &atlas, 1)[3], 0);

    materials.push(material(
        Vec4::new(1.0, 1.0, 1.0, 0.5),
        None,
        AlphaMode::Blend,
    ));
    submeshes.push(quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(2)));
    let input = mesh(submeshes, materials, vec![png_texture(&tex, Wrap::Repeat)]);
    let (out, _, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!(out.materials[0].alpha_mode, AlphaMode::Blend);
    assert_eq!(centre_texel(&out, &atlas, 2)[3], 128);
}

/// The atlas texel under the centre of submesh `s`'s quad.
fn centre_texel(out: &InstancedMesh, atlas: &image::RgbaImage, s: usize) -> Rgba<u8> {
    let uvs = out.submeshes[s].uvs.as_ref().expect("uvs");
    texel_at(atlas, (uvs[0] + uvs[2]) * 0.5)
}

#[test]
fn unused_vertices_and_default_material_get_valid_uvs() {
    // Vertex 4 is used by no triangle and the submesh has the default (white) material.
    let mut sub = quad(box_uvs(Vec2::ZERO, Vec2::ONE), None);
    sub.positions.push(Vec3::splat(9.0));
    sub.normals.as_mut().expect("normals").push(Vec3::Z);
    sub.uvs.as_mut().expect("uvs").push(Vec2::new(7.0, -3.0));
    let input = mesh(vec![sub], vec![], vec![]);
    let (out, _, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!(out.submeshes[0].uvs.as_ref().expect("uvs").len(), 5);
    assert!(atlas.pixels().all(|p| *p == Rgba([255, 255, 255, 255])));
}

#[test]
fn empty_mesh_still_gets_one_texture() {
    // Nothing to draw: one white patch, one material, no submeshes.
    let (out, report, _) = atlased(&mesh(vec![], vec![], vec![]), &AtlasOptions::default());
    assert!(out.submeshes.is_empty());
    assert_eq!(report.charts, 1);
}

#[test]
fn large_noise_meets_the_byte_budget() {
    // 2048x2048 noise is incompressible: 12 MB raw. The opaque atlas must become a JPEG under
    // 128 KiB, by lower quality and then a smaller side.
    let tex = noise(2048, 2048, 7, false);
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let options = AtlasOptions::default();
    let (_, report, _) = atlased(&input, &options);
    assert!(report.bytes <= 128 * 1024, "{report:?}");
    assert_eq!(report.mime_type, "image/jpeg");
    assert!(report.texel_scale < 0.5, "{report:?}");
    assert!(report.width <= 1024 && report.height <= 1024);
}

#[test]
fn noise_with_alpha_stays_png_under_the_budget() {
    // Alpha matters for a Blend material, so no JPEG: the side shrinks until the PNG fits.
    let tex = noise(512, 512, 11, true);
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Blend)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let options = AtlasOptions {
        max_bytes: 32 * 1024,
        ..AtlasOptions::default()
    };
    let (_, report, _) = atlased(&input, &options);
    assert_eq!(report.mime_type, "image/png");
    assert!(report.bytes <= 32 * 1024);
}

#[test]
fn undecodable_texture_is_a_typed_error() {
    // Bytes that are no PNG must fail as Decode for texture 0, not panic.
    let bad = Texture {
        bytes: b"definitely not a png".to_vec(),
        mime_type: "image/png".to_string(),
        size: (4, 4),
        wrap_u: Wrap::Repeat,
        wrap_v: Wrap::Repeat,
    };
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![bad],
    );
    let err = build_atlas(&input, &AtlasOptions::default()).expect_err("must fail");
    assert!(
        matches!(err, AtlasError::Decode { texture: 0, .. }),
        "{err}"
    );
}

#[test]
fn invalid_mesh_is_a_typed_error() {
    // Index 7 is past the quad's four vertices.
    let mut sub: Submesh = quad(box_uvs(Vec2::ZERO, Vec2::ONE), None);
    sub.indices[0] = 7;
    let err = build_atlas(&mesh(vec![sub], vec![], vec![]), &AtlasOptions::default())
        .expect_err("must fail");
    assert!(matches!(err, AtlasError::InvalidMesh(_)), "{err}");
}

#[test]
fn too_many_charts_for_a_tiny_side_do_not_fit() {
    // Each patch needs at least 1 + 2 x 2 = 5 texels per side; sixteen of them cannot share an
    // 8x8 atlas.
    let materials: Vec<_> = (0..16)
        .map(|i| {
            material(
                Vec4::new(i as f32 / 16.0, 0.0, 0.0, 1.0),
                None,
                AlphaMode::Opaque,
            )
        })
        .collect();
    let submeshes = (0..16)
        .map(|i| quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(i)))
        .collect();
    let options = AtlasOptions {
        max_side: 8,
        ..AtlasOptions::default()
    };
    let err = build_atlas(&mesh(submeshes, materials, vec![]), &options).expect_err("must fail");
    assert!(matches!(err, AtlasError::DoesNotFit { .. }), "{err}");
}

#[test]
fn smaller_max_side_lowers_the_texel_scale() {
    // A 64x64 chart plus gutters cannot keep scale 1 in a 32-texel atlas.
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&noise(64, 64, 3, false), Wrap::Repeat)],
    );
    let options = AtlasOptions {
        max_side: 32,
        ..AtlasOptions::default()
    };
    let (_, report, _) = atlased(&input, &options);
    assert!(report.texel_scale < 0.5);
    assert!(report.width <= 32 && report.height <= 32);
}

#[test]
fn impossible_budget_is_a_typed_error() {
    // No PNG or JPEG of even one texel fits in 16 bytes (the PNG signature alone is 8).
    let input = mesh(
        vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&noise(16, 16, 5, false), Wrap::Repeat)],
    );
    let options = AtlasOptions {
        max_bytes: 16,
        ..AtlasOptions::default()
    };
    let err = build_atlas(&input, &options).expect_err("must fail");
    assert!(
        matches!(err, AtlasError::OverBudget { max_bytes: 16 }),
        "{err}"
    );
}

#[test]
fn far_away_uvs_do_not_break_anything() {
    // UVs around 1e6 tile a Repeat texture a million times over; around 1e20 an f32 cannot even
    // tell the quad's corners apart. Both must give a valid mesh with UVs inside the atlas.
    for base in [1.0e6f32, 1.0e20] {
        let input = mesh(
            vec![quad(
                box_uvs(Vec2::splat(base), Vec2::splat(base + 0.5)),
                Some(0),
            )],
            vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
            vec![png_texture(&gradient(4, 4), Wrap::MirroredRepeat)],
        );
        atlased(&input, &AtlasOptions::default());
    }
}

#[test]
fn textured_material_without_uvs_is_its_mean_colour() {
    // A 2x1 texture of black and white has mean linear 0.5, sRGB 188: without UVs the submesh
    // gets a flat patch of that colour.
    let tex = image::RgbaImage::from_fn(2, 1, |x, _| {
        let v = if x == 0 { 0 } else { 255 };
        Rgba([v, v, v, 255])
    });
    let mut sub = quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0));
    sub.uvs = None;
    let input = mesh(
        vec![sub],
        vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
        vec![png_texture(&tex, Wrap::Repeat)],
    );
    let (_, report, atlas) = atlased(&input, &AtlasOptions::default());
    assert_eq!(report.patches, 1);
    assert!(atlas.pixels().all(|p| *p == Rgba([188, 188, 188, 255])));
}

/// Textures two atlases share decode once: the second atlas finds them in the cache, the
/// third mesh's different texture does not hit (equal size, other bytes), and an atlas built
/// through a warm cache is the one built cold, byte for byte.
#[test]
fn a_texture_cache_changes_no_atlas() {
    let textured = |seed: u64| {
        mesh(
            vec![quad(box_uvs(Vec2::ZERO, Vec2::ONE), Some(0))],
            vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
            vec![png_texture(&noise(64, 64, seed, false), Wrap::Repeat)],
        )
    };
    let (a, b) = (textured(1), textured(2));
    let cache = TextureCache::new(1 << 20);
    let cold_a = build_atlas(&a, &AtlasOptions::default()).expect("atlas");
    let cold_b = build_atlas(&b, &AtlasOptions::default()).expect("atlas");
    // An entry holds the RGBA8 image and its mip chain: 64, 32, ..., 1 texels a side.
    let held: usize = (0..7).map(|k| (64usize >> k).pow(2) * 4).sum();
    let warm_a = build_atlas_with(&a, &AtlasOptions::default(), &cache).expect("atlas");
    assert_eq!(cache.held_bytes(), held);
    let again_a = build_atlas_with(&a, &AtlasOptions::default(), &cache).expect("atlas");
    assert_eq!(cache.held_bytes(), held, "a hit adds nothing");
    let warm_b = build_atlas_with(&b, &AtlasOptions::default(), &cache).expect("atlas");
    assert_eq!(
        cache.held_bytes(),
        2 * held,
        "other bytes are another entry"
    );
    for (warm, cold) in [(&warm_a, &cold_a), (&again_a, &cold_a), (&warm_b, &cold_b)] {
        assert_eq!(warm.0, cold.0);
        assert_eq!(warm.1, cold.1);
    }
    assert_ne!(warm_a.0.textures[0].bytes, warm_b.0.textures[0].bytes);
}

/// The cache holds at most its budget, dropping the oldest images first; an image larger
/// than the budget is decoded but not kept.
#[test]
fn a_texture_cache_keeps_to_its_budget() {
    let tex = |seed: u64| png_texture(&noise(32, 32, seed, false), Wrap::Repeat);
    // The RGBA8 image and its mip chain: 32, 16, ..., 1 texels a side.
    let one: usize = (0..6).map(|k| (32usize >> k).pow(2) * 4).sum();
    let cache = TextureCache::new(2 * one);
    for seed in 0..5 {
        let image = cache.decode(&tex(seed)).expect("decodes");
        assert_eq!(image.image.dimensions(), (32, 32));
        assert!(cache.held_bytes() <= 2 * one);
    }
    assert_eq!(cache.held_bytes(), 2 * one);
    let none = TextureCache::new(one - 1);
    none.decode(&tex(9)).expect("decodes");
    assert_eq!(none.held_bytes(), 0);
}
