//! Property tests of the geometric promises: packed rectangles never overlap and stay inside
//! the atlas; at texel scale 1 every texel a triangle covers survives atlasing unchanged.

mod common;

use common::*;
use glam::{DVec2, Vec2, Vec3, Vec4};
use horizon_atlas::{pack_rects, AtlasOptions};
use horizon_mesh::model::{AlphaMode, Submesh, Wrap};
use image::{Rgba, RgbaImage};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn packed_rectangles_are_disjoint_and_inside(
        sizes in prop::collection::vec((1u32..40, 1u32..40), 0..40),
        gutter in 0u32..4,
        side in 1u32..300,
    ) {
        packs_fairly(&sizes, gutter, side)?;
    }

    /// The same promises past `MAXRECTS_MAX_CHARTS`, where the guillotine allocator packs.
    #[test]
    fn many_packed_rectangles_are_disjoint_and_inside(
        sizes in prop::collection::vec((1u32..12, 1u32..12), 201..600),
        gutter in 0u32..3,
        side in 16u32..400,
    ) {
        prop_assert!(sizes.len() > horizon_atlas::MAXRECTS_MAX_CHARTS);
        packs_fairly(&sizes, gutter, side)?;
    }

    #[test]
    fn covered_texels_survive_at_scale_one(
        (w, h) in (1u32..9, 1u32..9),
        seed in any::<u64>(),
        triangles in prop::collection::vec(
            prop::array::uniform3((-1.0f32..2.0, -1.0f32..2.0)),
            1..5,
        ),
        mode in prop::sample::select(vec![Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge]),
    ) {
        // A few triangles, each its own island, with UVs in [-1, 2] (three tiles, under the
        // four-tile cap) on a random opaque texture; islands whose boxes overlap merge. The
        // atlas stays at scale 1 and lossless (a small PNG), so the atlas texel under the
        // remapped UV of every covered source texel centre is that texel, fetched with the
        // texture's wrap mode. Exact equality is the honest tolerance: at scale 1 atlas texel
        // centres are source texel centres and sRGB round trips exactly.
        let tex = noise(w, h, seed, false);
        let uvs: Vec<Vec2> = triangles.iter().flatten().map(|&(u, v)| Vec2::new(u, v)).collect();
        let sub = Submesh {
            positions: vec![Vec3::ZERO; uvs.len()],
            normals: None,
            uvs: Some(uvs.clone()),
            colors: None,
            indices: (0..uvs.len() as u32).collect(),
            material: Some(0),
        };
        let input = mesh(
            vec![sub],
            vec![material(Vec4::ONE, Some(0), AlphaMode::Opaque)],
            vec![png_texture(&tex, mode)],
        );
        // Lossless, so that what is checked is charting, packing and remapping, not JPEG.
        let lossless = AtlasOptions { lossless: true, ..AtlasOptions::default() };
        let (out, report, atlas) = atlased(&input, &lossless);
        prop_assert_eq!(report.texel_scale, 1.0);
        prop_assert_eq!(report.mime_type.as_str(), "image/png");
        let atlas_uvs = out.submeshes[0].uvs.clone().expect("uvs");
        for (tri, out_tri) in uvs.chunks_exact(3).zip(atlas_uvs.chunks_exact(3)) {
            for (x, y, want) in covered_texels(&tex, tri, mode) {
                let size = DVec2::new(w as f64, h as f64);
                let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5) / size;
                let Some(b) = barycentric(tri, p) else { continue };
                let uv = out_tri[0] * b[0] as f32
                    + out_tri[1] * b[1] as f32
                    + out_tri[2] * b[2] as f32;
                prop_assert_eq!(texel_at(&atlas, uv), want, "texel ({}, {})", x, y);
            }
        }
    }
}

/// Total area and longest side of the rectangles with their gutters.
/// A packing is valid, inside the square and keeps every size; or it is refused, which is only
/// fair when the square is tight: the packers are not optimal, but with at most half the area
/// used and no rectangle over half the side they always fit.
fn packs_fairly(sizes: &[(u32, u32)], gutter: u32, side: u32) -> Result<(), TestCaseError> {
    if let Some(layout) = pack_rects(sizes, gutter, side) {
        prop_assert_eq!(layout.validate(), Ok(()));
        prop_assert!(layout.width <= side && layout.height <= side);
        prop_assert_eq!(layout.rects.len(), sizes.len());
        for (r, &(w, h)) in layout.rects.iter().zip(sizes) {
            prop_assert_eq!((r.width, r.height), (w, h));
        }
    } else {
        let (area, longest) = padded_area_and_longest(sizes, gutter);
        let side = u64::from(side);
        prop_assert!(area * 2 > side * side || longest * 2 > side);
    }
    Ok(())
}

fn padded_area_and_longest(sizes: &[(u32, u32)], gutter: u32) -> (u64, u64) {
    let g = 2 * u64::from(gutter);
    let padded = || {
        sizes
            .iter()
            .map(|&(w, h)| (u64::from(w) + g, u64::from(h) + g))
    };
    let area = padded().map(|(w, h)| w * h).sum();
    let longest = padded().map(|(w, h)| w.max(h)).max().unwrap_or(0);
    (area, longest)
}

/// Source texel centres (as unwrapped integer texel coordinates) inside the UV triangle, with
/// the texel the wrap mode fetches there.
fn covered_texels(tex: &RgbaImage, uvs: &[Vec2], mode: Wrap) -> Vec<(i64, i64, Rgba<u8>)> {
    let (w, h) = tex.dimensions();
    let size = DVec2::new(w as f64, h as f64);
    let pts: Vec<DVec2> = uvs.iter().map(|uv| uv.as_dvec2() * size).collect();
    let lo = pts[0].min(pts[1]).min(pts[2]).floor();
    let hi = pts[0].max(pts[1]).max(pts[2]).ceil();
    let mut out = Vec::new();
    for y in lo.y as i64..hi.y as i64 {
        for x in lo.x as i64..hi.x as i64 {
            let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5) / size;
            if barycentric(uvs, p).is_some() {
                out.push((x, y, *tex.get_pixel(wrap(x, w, mode), wrap(y, h, mode))));
            }
        }
    }
    out
}

/// Barycentric coordinates of `p` in the UV triangle, when it is inside (boundary included) and
/// the triangle is not degenerate.
fn barycentric(uvs: &[Vec2], p: DVec2) -> Option<[f64; 3]> {
    let (a, b, c) = (uvs[0].as_dvec2(), uvs[1].as_dvec2(), uvs[2].as_dvec2());
    let det = (b - a).perp_dot(c - a);
    if det.abs() < 1e-12 {
        return None;
    }
    let l1 = (p - a).perp_dot(c - a) / det;
    let l2 = (b - a).perp_dot(p - a) / det;
    let l0 = 1.0 - l1 - l2;
    (l0 >= 0.0 && l1 >= 0.0 && l2 >= 0.0).then_some([l0, l1, l2])
}
