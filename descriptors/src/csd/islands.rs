//! UV islands: the connected pieces of a submesh's texture mapping, and how each is placed in
//! its own chart in unwrapped texel space.

use std::collections::HashMap;

use glam::{DVec2, Vec2};

/// Groups triangles into UV islands: two triangles are in one island when they share a
/// vertex in UV space, i.e. a vertex index or two vertices with bit-identical UVs (a seam
/// split only for normals stays one island). Returns, per island, indices into `triangles`,
/// in first-seen order.
pub(super) fn uv_islands(uvs: &[Vec2], triangles: &[[u32; 3]]) -> Vec<Vec<usize>> {
    // Weld vertices by their UV bits, then union the corners of every triangle.
    let mut weld: HashMap<[u32; 2], usize> = HashMap::new();
    let mut node_of = |v: u32| -> usize {
        let uv = uvs.get(v as usize).copied().unwrap_or(Vec2::ZERO);
        let next = weld.len();
        *weld.entry([uv.x.to_bits(), uv.y.to_bits()]).or_insert(next)
    };
    let corners: Vec<[usize; 3]> = triangles
        .iter()
        .map(|t| [node_of(t[0]), node_of(t[1]), node_of(t[2])])
        .collect();
    let mut sets = DisjointSets::new(weld.len());
    for &[a, b, c] in &corners {
        sets.union(a, b);
        sets.union(a, c);
    }

    let mut island_of_root: HashMap<usize, usize> = HashMap::new();
    let mut islands: Vec<Vec<usize>> = Vec::new();
    for (t, &[a, _, _]) in corners.iter().enumerate() {
        let root = sets.find(a);
        let next = islands.len();
        let island = *island_of_root.entry(root).or_insert(next);
        if island == islands.len() {
            islands.push(Vec::new());
        }
        islands[island].push(t);
    }
    islands
}

/// Union-find with path halving and union by size.
#[derive(Debug)]
struct DisjointSets {
    /// Parent of each node; a root is its own parent.
    parent: Vec<usize>,
    /// Size of each root's set.
    size: Vec<usize>,
}

impl DisjointSets {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n).collect(),
            size: vec![1; n],
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
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a;
        self.size[a] += self.size[b];
    }
}

/// An island placed in its own chart, in *unwrapped* texel space: a UV range of 0..3 is three
/// texture widths, so repeats are charted (and counted) as often as the surface shows them.
#[derive(Debug)]
pub(super) struct Placement {
    /// Absolute texel coordinate of the chart's local origin. It is the floor of the island's
    /// lowest texel coordinate, so local texel centres are texture texel centres.
    pub(super) origin: [i64; 2],
    /// Largest local coordinate along each axis, in texels.
    pub(super) extent: DVec2,
    /// The island's triangles in local texel coordinates (`absolute - origin`).
    pub(super) triangles: Vec<[DVec2; 3]>,
    /// Sum of the triangles' texel areas: the island's share of the charted atlas.
    pub(super) footprint: f64,
}

/// Places triangles given in absolute texel coordinates into a local chart.
///
/// An island spanning more than `max_repeats` texture sizes along an axis (a floor tiled a
/// thousand times, or garbage UVs) is shrunk along that axis to exactly `max_repeats`
/// repeats, keeping its texel density: beyond that many repeats one more changes the look of
/// the surface little, and the chart stays bounded. Texel coordinates are `f64`, so UVs of
/// any finite size place without overflow.
pub(super) fn place_island(
    triangles: &[[DVec2; 3]],
    texture_size: DVec2,
    max_repeats: f64,
) -> Placement {
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for p in triangles.iter().flatten() {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        lo = DVec2::ZERO;
        hi = DVec2::ZERO;
    }
    let origin = lo.floor();
    let cap = texture_size * max_repeats;
    let span = hi - origin;
    let scale = DVec2::new(shrink(span.x, cap.x), shrink(span.y, cap.y));
    let local: Vec<[DVec2; 3]> = triangles
        .iter()
        .map(|t| t.map(|p| ((p - origin) * scale).max(DVec2::ZERO)))
        .collect();
    let footprint = local
        .iter()
        .map(|[a, b, c]| 0.5 * (*b - *a).perp_dot(*c - *a).abs())
        .filter(|a| a.is_finite())
        .sum();
    Placement {
        // `as` saturates: an island at 1e30 texels samples the same texel everywhere, which
        // is all such UVs can mean in f32.
        origin: [origin.x as i64, origin.y as i64],
        extent: (span * scale).min(cap).max(DVec2::ZERO),
        triangles: local,
        footprint,
    }
}

/// The factor that shrinks `span` to `cap`, or 1 when it fits.
fn shrink(span: f64, cap: f64) -> f64 {
    if span > cap && span > 0.0 {
        cap / span
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn islands_join_through_welded_uvs() {
        // Triangles 0 and 1 share vertex 1; triangle 2 shares no index with them, but its
        // vertex 5 has the same UV as vertex 2, so it joins too; triangle 3 is apart.
        let uvs = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.5, 2.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(5.0, 5.0),
            Vec2::new(6.0, 5.0),
            Vec2::new(5.0, 6.0),
            Vec2::new(-1.0, 2.0),
            Vec2::new(-1.0, 3.0),
        ];
        let tris = [[0, 1, 2], [1, 3, 4], [5, 9, 10], [6, 7, 8]];
        assert_eq!(uv_islands(&uvs, &tris), vec![vec![0, 1, 2], vec![3]]);
    }

    #[test]
    fn placement_caps_repeats() {
        // 1000 repeats of a 4-texel texture along U, one along V: capped to 8 repeats.
        let t = [[
            DVec2::new(0.0, 0.0),
            DVec2::new(4000.0, 0.0),
            DVec2::new(0.0, 4.0),
        ]];
        let p = place_island(&t, DVec2::new(4.0, 4.0), 8.0);
        assert_eq!(p.extent, DVec2::new(32.0, 4.0));
        assert_eq!(p.footprint, 0.5 * 32.0 * 4.0);
        assert_eq!(p.origin, [0, 0]);
    }

    #[test]
    fn placement_starts_at_a_texel_corner() {
        let t = [[
            DVec2::new(-2.5, 7.25),
            DVec2::new(1.0, 7.25),
            DVec2::new(-2.5, 9.0),
        ]];
        let p = place_island(&t, DVec2::new(16.0, 16.0), 8.0);
        assert_eq!(p.origin, [-3, 7]);
        assert_eq!(p.triangles[0][0], DVec2::new(0.5, 0.25));
        assert_eq!(p.extent, DVec2::new(4.0, 2.0));
    }
}
