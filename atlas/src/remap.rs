//! Stage 4: remap UVs. A point `p` of a chart's box maps to
//! `rect origin + (p - chart min) / chart size * rect size`, normalised by the atlas size. The
//! box's edges land on the rectangle's edges (not on texel centres), which is the inverse of the
//! texel-centre mapping baking uses, so a source texel centre lands on the atlas texel centre
//! that holds it.

use glam::{DVec2, Vec2};
use horizon_mesh::model::{InstancedMesh, Submesh};

use crate::chart::{Chart, Charting};
use crate::layout::{Layout, PackedRect};

/// The submeshes of `mesh` with atlas UVs and material 0; everything else is copied.
pub(crate) fn remap_uvs(
    mesh: &InstancedMesh,
    charting: &Charting,
    layout: &Layout,
) -> Vec<Submesh> {
    let atlas = DVec2::new(f64::from(layout.width), f64::from(layout.height));
    let to_atlas = |chart: usize, at: DVec2| -> Vec2 {
        let (c, r) = (&charting.charts[chart], &layout.rects[chart]);
        (atlas_point(c, r, at) / atlas).as_vec2()
    };
    // A vertex no triangle uses still gets a UV inside the atlas: chart 0's centre.
    let spare = {
        let c = &charting.charts[0];
        to_atlas(0, (c.min + c.max) * 0.5)
    };
    mesh.submeshes
        .iter()
        .zip(&charting.placements)
        .map(|(sub, placed)| Submesh {
            uvs: Some(
                placed
                    .iter()
                    .map(|p| p.map_or(spare, |(chart, at)| to_atlas(chart, at)))
                    .collect(),
            ),
            material: Some(0),
            ..sub.clone()
        })
        .collect()
}

/// A chart point in atlas texels.
fn atlas_point(chart: &Chart, rect: &PackedRect, at: DVec2) -> DVec2 {
    let origin = DVec2::new(f64::from(rect.x), f64::from(rect.y));
    let size = DVec2::new(f64::from(rect.width), f64::from(rect.height));
    let extent = chart.max - chart.min;
    // Far from the origin (UVs near 1e16 and beyond) a box can lose its width to rounding; its
    // points then go to the middle rather than to NaN. Clamping keeps rounding inside the box.
    let rel = DVec2::select(
        extent.cmpgt(DVec2::ZERO),
        ((at - chart.min) / extent).clamp(DVec2::ZERO, DVec2::ONE),
        DVec2::splat(0.5),
    );
    origin + rel * size
}
