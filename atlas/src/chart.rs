//! Stage 1: charts (Azim et al. 2014, section 7: "some models use wrapping texture coordinates
//! ... others reference only a small part of the actual texture image").
//!
//! A chart is a box in its source's texel space: the UV bounding box of one UV island (the
//! triangles connected through shared vertex indices), after KHR_texture_transform, scaled by
//! the decoded texture size and widened to whole texels. The box may leave [0, size] when the
//! texture wraps; baking samples the source with its wrap mode there, which is the same as
//! shifting the island by whole tiles. Charts of one material whose boxes overlap merge into
//! their union, so a texture used by many islands is stored once; so do all the charts of one
//! texture that fill at least [`DENSE_FILL`] of their union's box (a box proxy's six face tiles
//! become one chart with one gutter, not six). Untextured materials, and
//! submeshes without UVs, get one flat patch per material whose every vertex maps to its centre.

use std::collections::HashMap;

use glam::{DVec2, Vec2, Vec4};
use horizon_mesh::model::{AlphaMode, InstancedMesh, Material};

use crate::color::mean_linear;
use crate::material::material_of;
use crate::options::{AtlasOptions, MAX_TILES_PER_AXIS};
use crate::source::Source;

/// One rectangle's worth of atlas content.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Chart {
    /// Decoded texture this chart samples; `None` for a flat patch.
    pub texture: Option<usize>,
    /// Which material the chart belongs to (`None` is the glTF default material); charts merge
    /// only within one material, since each carries that material's factor and alpha mode.
    pub material: Option<usize>,
    /// Linear RGBA multiplier: the base colour factor (for a patch, times the texture's mean
    /// colour when a textured material is drawn without UVs).
    pub factor: Vec4,
    /// The material's alpha mode, applied when baking.
    pub alpha: AlphaMode,
    /// Smallest corner of the box, in source texels (patch texels for a patch); integral.
    pub min: DVec2,
    /// Largest corner, strictly greater than `min` on both axes; integral.
    pub max: DVec2,
    /// Most atlas texels per axis at scale 1: [`MAX_TILES_PER_AXIS`] source sizes.
    pub cap: DVec2,
}

impl Chart {
    /// Size in atlas texels at texel scale 1: the box size, capped per axis.
    pub fn natural(&self) -> DVec2 {
        (self.max - self.min).min(self.cap)
    }

    /// Whether this chart is a flat colour patch.
    pub fn is_patch(&self) -> bool {
        self.texture.is_none()
    }
}

/// The charts of a mesh and where each vertex lands in them.
#[derive(Clone, Debug, Default)]
pub(crate) struct Charting {
    /// Every chart, at least one.
    pub charts: Vec<Chart>,
    /// Per submesh, per vertex: the chart and the point in that chart's space. `None` for a
    /// vertex no triangle uses; remapping sends it to the centre of chart 0.
    pub placements: Vec<Vec<Option<(usize, DVec2)>>>,
}

/// Charts every submesh of `mesh`; `sources` holds the decoded textures by texture index.
pub(crate) fn chart_mesh(
    mesh: &InstancedMesh,
    sources: &[Option<Source>],
    options: &AtlasOptions,
) -> Charting {
    let default = Material::default();
    let mut out = Charting::default();
    let mut patches: HashMap<Option<usize>, usize> = HashMap::new();
    for sub in &mesh.submeshes {
        let mut placed = vec![None; sub.positions.len()];
        let material = material_of(mesh, sub, &default);
        let textured = material
            .base_color_texture
            .and_then(|t| sources.get(t.texture)?.as_ref().map(|s| (t, s)));
        match (textured, &sub.uvs) {
            (Some((tref, source)), Some(uvs)) => {
                let (w, h) = source.image().dimensions();
                let size = DVec2::new(f64::from(w), f64::from(h));
                let texel = |uv: Vec2| -> DVec2 {
                    let t = tref.transform.map_or(uv, |x| x.apply(uv));
                    t.as_dvec2() * size
                };
                for island in uv_islands(sub.positions.len(), &sub.indices) {
                    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::NEG_INFINITY);
                    for &v in &island {
                        let p = texel(uvs[v]);
                        lo = lo.min(p);
                        hi = hi.max(p);
                    }
                    let chart = out.charts.len();
                    for &v in &island {
                        placed[v] = Some((chart, texel(uvs[v])));
                    }
                    let (min, max) = whole_texels(lo, hi);
                    out.charts.push(Chart {
                        texture: Some(tref.texture),
                        material: sub.material,
                        factor: material.base_color_factor,
                        alpha: material.alpha_mode,
                        min,
                        max,
                        cap: size * MAX_TILES_PER_AXIS,
                    });
                }
            }
            _ => {
                let chart = *patches.entry(sub.material).or_insert_with(|| {
                    let mean = textured.map_or(Vec4::ONE, |(_, s)| mean_linear(s.image()));
                    out.charts
                        .push(patch(sub.material, material, mean, options.patch_side));
                    out.charts.len() - 1
                });
                let centre = (out.charts[chart].min + out.charts[chart].max) * 0.5;
                for &i in &sub.indices {
                    placed[i as usize] = Some((chart, centre));
                }
            }
        }
        out.placements.push(placed);
    }
    if out.charts.is_empty() {
        // Nothing is drawn; one white patch keeps "exactly one texture" meaningful.
        out.charts
            .push(patch(None, &default, Vec4::ONE, options.patch_side));
    }
    merge_overlapping(&mut out);
    merge_dense(&mut out);
    out
}

/// The least share of their union's box that a texture's charts must fill to be stored as that
/// one box: a texture laid out as tiles (a box proxy's faces, a hand-made atlas) is copied
/// whole, one chart and one gutter instead of one per tile, while a texture whose islands are
/// scattered over it keeps only what they use.
pub(crate) const DENSE_FILL: f64 = 0.5;

/// A flat patch of `material`'s base colour times `mean`; `key` is the material's index.
fn patch(key: Option<usize>, material: &Material, mean: Vec4, side: u32) -> Chart {
    let side = f64::from(side.max(1));
    Chart {
        texture: None,
        material: key,
        factor: material.base_color_factor * mean,
        alpha: material.alpha_mode,
        min: DVec2::ZERO,
        max: DVec2::splat(side),
        cap: DVec2::splat(side),
    }
}

/// Widens a box to whole texels, at least one texel per axis, so that at scale 1 texel centres
/// of the atlas land on texel centres of the source.
fn whole_texels(lo: DVec2, hi: DVec2) -> (DVec2, DVec2) {
    let min = lo.floor();
    let max = hi.ceil().max(min + DVec2::ONE);
    (min, max)
}

/// Groups the vertices used by `indices` into islands: two vertices are in one island when a
/// chain of triangles joins them. Returns each island's vertices, in first-seen order.
fn uv_islands(vertex_count: usize, indices: &[u32]) -> Vec<Vec<usize>> {
    let mut sets = DisjointSets::new(vertex_count);
    for t in indices.chunks_exact(3) {
        sets.union(t[0] as usize, t[1] as usize);
        sets.union(t[0] as usize, t[2] as usize);
    }
    let mut used = vec![false; vertex_count];
    for &i in indices {
        used[i as usize] = true;
    }
    let mut island_of_root: HashMap<usize, usize> = HashMap::new();
    let mut islands: Vec<Vec<usize>> = Vec::new();
    for v in (0..vertex_count).filter(|&v| used[v]) {
        let root = sets.find(v);
        let next = islands.len();
        let island = *island_of_root.entry(root).or_insert(next);
        if island == islands.len() {
            islands.push(Vec::new());
        }
        islands[island].push(v);
    }
    islands
}

/// Merges textured charts of one material whose boxes overlap (with positive area) into their
/// union, until no two overlap, and renumbers the placements.
fn merge_overlapping(charting: &mut Charting) {
    let charts = &mut charting.charts;
    let mut sets = DisjointSets::new(charts.len());
    loop {
        // Live textured charts, sorted by material then left edge, so that only a short run
        // after each chart can overlap it.
        let mut live: Vec<usize> = (0..charts.len())
            .filter(|&c| sets.find(c) == c && !charts[c].is_patch())
            .collect();
        live.sort_by(|&a, &b| {
            (charts[a].material, charts[a].texture)
                .cmp(&(charts[b].material, charts[b].texture))
                .then(charts[a].min.x.total_cmp(&charts[b].min.x))
        });
        let mut changed = false;
        for (k, &a) in live.iter().enumerate() {
            if sets.find(a) != a {
                continue;
            }
            for &b in &live[k + 1..] {
                let (ca, cb) = (&charts[a], &charts[b]);
                if (ca.material, ca.texture) != (cb.material, cb.texture) || cb.min.x >= ca.max.x {
                    break;
                }
                let overlap = cb.min.y < ca.max.y && ca.min.y < cb.max.y;
                if sets.find(b) == b && overlap {
                    sets.join_into(b, a);
                    let (min, max) = (ca.min.min(cb.min), ca.max.max(cb.max));
                    let chart = &mut charts[a];
                    chart.min = min;
                    chart.max = max;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    renumber(charting, &mut sets);
}

/// Merges all the textured charts of one material and texture into their union when they fill
/// at least [`DENSE_FILL`] of it (and the union stays within the chart cap), and renumbers the
/// placements. Runs after [`merge_overlapping`], so the charts of a group are disjoint and
/// their areas add up.
fn merge_dense(charting: &mut Charting) {
    let charts = &charting.charts;
    let mut groups: HashMap<(Option<usize>, Option<usize>), Vec<usize>> = HashMap::new();
    for (c, chart) in charts.iter().enumerate().filter(|(_, c)| !c.is_patch()) {
        groups
            .entry((chart.material, chart.texture))
            .or_default()
            .push(c);
    }
    let mut sets = DisjointSets::new(charts.len());
    let mut unions = Vec::new();
    for members in groups.values().filter(|m| m.len() > 1) {
        let (mut min, mut max) = (DVec2::splat(f64::INFINITY), DVec2::NEG_INFINITY);
        let mut filled = 0.0;
        for &c in members {
            let size = charts[c].max - charts[c].min;
            filled += size.x * size.y;
            min = min.min(charts[c].min);
            max = max.max(charts[c].max);
        }
        let size = max - min;
        let first = members[0];
        if filled >= DENSE_FILL * size.x * size.y && size.cmple(charts[first].cap).all() {
            for &c in &members[1..] {
                sets.join_into(c, first);
            }
            unions.push((first, min, max));
        }
    }
    if unions.is_empty() {
        return;
    }
    for (c, min, max) in unions {
        charting.charts[c].min = min;
        charting.charts[c].max = max;
    }
    renumber(charting, &mut sets);
}

/// Keeps the charts that are their own set's root, in order, and points every placement at
/// its set's surviving chart.
fn renumber(charting: &mut Charting, sets: &mut DisjointSets) {
    let charts = &mut charting.charts;
    let mut new_index = vec![usize::MAX; charts.len()];
    let mut kept = Vec::new();
    for c in 0..charts.len() {
        if sets.find(c) == c {
            new_index[c] = kept.len();
            kept.push(charts[c].clone());
        }
    }
    for placed in &mut charting.placements {
        for (chart, _) in placed.iter_mut().flatten() {
            *chart = new_index[sets.find(*chart)];
        }
    }
    *charts = kept;
}

/// Union-find with path halving.
#[derive(Debug)]
struct DisjointSets {
    /// Parent of each node; a root is its own parent.
    parent: Vec<usize>,
}

impl DisjointSets {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n).collect(),
        }
    }

    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] != x {
            self.parent[x] = self.parent[self.parent[x]];
            x = self.parent[x];
        }
        x
    }

    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb)] = ra.min(rb);
        }
    }

    /// Makes root `b` a child of root `a`.
    fn join_into(&mut self, b: usize, a: usize) {
        self.parent[b] = a;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn islands_follow_shared_vertices() {
        // Triangles 0-1-2 and 2-3-4 share vertex 2; 5-6-7 is alone; vertex 8 is unused.
        let islands = uv_islands(9, &[0, 1, 2, 2, 3, 4, 5, 6, 7]);
        assert_eq!(islands, vec![vec![0, 1, 2, 3, 4], vec![5, 6, 7]]);
    }

    #[test]
    fn boxes_widen_to_whole_texels() {
        // (0.5, 1.0)..(2.5, 1.0) covers texels 0..3 in x and the zero-height row needs one texel.
        let (min, max) = whole_texels(DVec2::new(0.5, 1.0), DVec2::new(2.5, 1.0));
        assert_eq!((min, max), (DVec2::new(0.0, 1.0), DVec2::new(3.0, 2.0)));
    }
}
