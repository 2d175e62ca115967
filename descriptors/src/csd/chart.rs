//! The charting rasteriser: one placed UV island becomes a grid of 256-cell colour codes, one
//! cell per `k x k` block of unwrapped texels, with the cells outside the island's footprint
//! left uncovered.
//!
//! Each cell has one sample point, a texel centre inside its block. A cell is covered when
//! its sample point lies in one of the island's triangles (edges included), and its colour is
//! the texel under that point, tinted by the material and the interpolated vertex colour.
//! With `k = 1` the sample is the cell's own texel, so every texel of the footprint counts
//! and none outside it does. With `k > 1` this is MPEG-7's subsampling of large images
//! (one pixel per `k x k` block), except that the pixel is chosen by a fixed hash rather
//! than always the block's corner: when a texture is tiled so often that `k` nears its size,
//! corner samples would pick the same few texels in every tile.

use glam::{DVec2, Vec4};
use horizon_mesh::rng::mix;
use horizon_mesh::Wrap;

use super::hmmd::{linear_to_srgb8, srgb8_to_linear, Hmmd};
use super::islands::Placement;
use super::structure::{Chart, NO_OWNER};
use super::texels::Texels;

/// How a sampled texel becomes a visible colour.
#[derive(Debug)]
pub(super) struct Shading<'a> {
    /// The decoded base colour texture.
    pub(super) texels: &'a Texels,
    /// Its wrap modes along U and V.
    pub(super) wrap: [Wrap; 2],
    /// The material's linear base colour factor.
    pub(super) factor: Vec4,
    /// Linear vertex colours of each triangle's corners, when the submesh has colours.
    pub(super) vertex_colors: Option<&'a [[Vec4; 3]]>,
    /// The alpha cut-off of a masked material: texels below it are not drawn.
    pub(super) cutoff: Option<f32>,
}

/// Rasterises `island` into `chart` at one cell per `k x k` texels. Returns the fraction of
/// the covered cells that an alpha mask leaves visible (1 without a mask).
///
/// Two passes: coverage (which triangle owns each cell's sample point), then shading in row
/// order, so that texels are fetched along texture rows: a large texture sampled every `k`
/// texels triangle by triangle would miss the cache on nearly every fetch.
pub(super) fn rasterize_island(
    island: &Placement,
    shading: &Shading,
    k: u64,
    chart: &mut Chart,
) -> f64 {
    let (width, height) = chart_size(island.extent, k);
    chart.reset(width, height);
    let covered = cover_cells(island, k, chart);
    if covered == 0 {
        return mark_centroids(island, shading, k, chart);
    }

    let mut memo = ShadeMemo::default();
    let mut visible = 0usize;
    for cy in 0..height {
        let row = sample_texel(cy, k, row_jitter(cy, k));
        let ys = row as f64 + 0.5;
        for cx in 0..width {
            let cell = cy * width + cx;
            let t = chart.owner[cell];
            if t == NO_OWNER {
                continue;
            }
            let column = sample_texel(cx, k, column_jitter(cx, cy, k));
            let tint = shading.vertex_colors.map(|colors| {
                let triangle = &island.triangles[t as usize];
                let w = barycentric(triangle, DVec2::new(column as f64 + 0.5, ys));
                let [ca, cb, cc] = colors[t as usize];
                ca * w[0] + cb * w[1] + cc * w[2]
            });
            let texel = [
                island.origin[0].saturating_add(column as i64),
                island.origin[1].saturating_add(row as i64),
            ];
            if let Some(code) = shading.code(texel, tint, &mut memo) {
                chart.codes[cell] = code;
                visible += 1;
            }
        }
    }
    visible as f64 / covered as f64
}

/// Marks in `chart.owner` the triangle whose footprint holds each cell's sample point (edges
/// included; the last triangle wins where footprints overlap). Returns the covered cells.
fn cover_cells(island: &Placement, k: u64, chart: &mut Chart) -> usize {
    let (width, height) = (chart.width, chart.height);
    let kf = k as f64;
    let mut covered = 0usize;
    for (t, triangle) in island.triangles.iter().enumerate() {
        let [a, b, c] = *triangle;
        // Zero-area (and NaN) footprints cover no sample point; the centroid fallback
        // catches islands made only of them.
        let doubled_area = (b - a).perp_dot(c - a).abs();
        if doubled_area.is_nan() || doubled_area == 0.0 {
            continue;
        }
        let ymin = a.y.min(b.y).min(c.y);
        let ymax = a.y.max(b.y).max(c.y);
        // Rows whose sample band [cy*k + 0.5, cy*k + k - 0.5] meets [ymin, ymax].
        let Some((row0, row1)) = cell_range(ymin, ymax, kf, height) else {
            continue;
        };
        for cy in row0..=row1 {
            // Sample points are texel centres.
            let ys = sample_texel(cy, k, row_jitter(cy, k)) as f64 + 0.5;
            let Some((xl, xr)) = span_at(triangle, ys) else {
                continue;
            };
            let Some((col0, col1)) = cell_range(xl, xr, kf, width) else {
                continue;
            };
            for cx in col0..=col1 {
                let xs = sample_texel(cx, k, column_jitter(cx, cy, k)) as f64 + 0.5;
                if xl <= xs && xs <= xr {
                    let owner = &mut chart.owner[cy * width + cx];
                    covered += usize::from(*owner == NO_OWNER);
                    *owner = t as u32;
                }
            }
        }
    }
    covered
}

/// Chart columns and rows for a local extent at `k` texels per cell.
pub(super) fn chart_size(extent: DVec2, k: u64) -> (usize, usize) {
    // `as` saturates, so absurd extents give huge counts rather than overflow.
    let cells = |e: f64| ((e.max(0.0) / k as f64).floor() as usize).saturating_add(1);
    (cells(extent.x), cells(extent.y))
}

/// An island whose footprint covers no sample point (all its triangles collapse in UV space,
/// as when a model paints a part with one texel of a palette, or it is smaller than a cell)
/// would vanish; instead each triangle marks the cell under its centroid with the texel
/// there, so the island shows the colours it maps to. Returns the fraction of centroids an
/// alpha mask leaves visible.
fn mark_centroids(island: &Placement, shading: &Shading, k: u64, chart: &mut Chart) -> f64 {
    let mut visible = 0usize;
    for (t, &[a, b, c]) in island.triangles.iter().enumerate() {
        let g = (a + b + c) / 3.0;
        let cx = ((g.x / k as f64) as usize).min(chart.width - 1);
        let cy = ((g.y / k as f64) as usize).min(chart.height - 1);
        let tint = shading
            .vertex_colors
            .map(|colors| (colors[t][0] + colors[t][1] + colors[t][2]) / 3.0);
        let texel = [
            island.origin[0].saturating_add(g.x as i64),
            island.origin[1].saturating_add(g.y as i64),
        ];
        if let Some(code) = shading.code(texel, tint, &mut ShadeMemo::default()) {
            chart.codes[cy * chart.width + cx] = code;
            visible += 1;
        }
    }
    visible as f64 / island.triangles.len().max(1) as f64
}

impl Shading<'_> {
    /// The 256-cell code of the visible colour at absolute texel `texel`, or `None` when a
    /// masked material cuts it out.
    ///
    /// Texels are sRGB as stored; the linear factor and vertex colour multiply the texel's
    /// linear value and the product is re-encoded to 8-bit sRGB, which is what a renderer
    /// shows. A white factor without vertex colours keeps the stored bytes exactly.
    fn code(&self, texel: [i64; 2], vertex: Option<Vec4>, memo: &mut ShadeMemo) -> Option<u16> {
        let [r, g, b, a] = self.texels.fetch(texel[0], texel[1], self.wrap);
        let tint = vertex.map_or(self.factor, |v| self.factor * v);
        if let Some(cutoff) = self.cutoff {
            let alpha = f32::from(a) / 255.0 * tint.w;
            // NaN alpha is not visible either.
            if alpha.is_nan() || alpha < cutoff {
                return None;
            }
        }
        // Textures are mostly runs of equal texels; under one tint (no vertex colours) equal
        // texels have equal codes.
        let key = u32::from_le_bytes([r, g, b, 1]);
        if vertex.is_none() && memo.texel == key {
            return Some(memo.code);
        }
        let rgb = if tint.truncate() == glam::Vec3::ONE {
            [r, g, b]
        } else {
            let shade = |code: u8, f: f32| linear_to_srgb8(srgb8_to_linear(code) * f);
            [shade(r, tint.x), shade(g, tint.y), shade(b, tint.z)]
        };
        let code = Hmmd::from_rgb8(rgb).bin_256() as u16;
        *memo = ShadeMemo { texel: key, code };
        Some(code)
    }
}

/// The last texel shaded under the island's own tint, and its code.
#[derive(Debug, Default)]
struct ShadeMemo {
    /// The texel's RGB bytes and a 1 (so that 0 means none yet).
    texel: u32,
    /// Its 256-cell code.
    code: u16,
}

/// The cells `lo..=hi` whose sample band `[i*k + 0.5, i*k + k - 0.5]` meets `[from, to]`,
/// clipped to `0..count`.
fn cell_range(from: f64, to: f64, k: f64, count: usize) -> Option<(usize, usize)> {
    let lo = ((from + 0.5) / k - 1.0).ceil().max(0.0);
    let hi = ((to - 0.5) / k).floor().min(count as f64 - 1.0);
    // NaN compares false and skips too.
    if lo <= hi {
        Some((lo as usize, hi as usize))
    } else {
        None
    }
}

/// Local texel index of the sample of cell `i` at `k` texels per cell with jitter `j < k`.
fn sample_texel(i: usize, k: u64, j: u64) -> u64 {
    i as u64 * k + j
}

/// The x-interval of triangle `t` on the horizontal line at `y`, edges included.
fn span_at(t: &[DVec2; 3], y: f64) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for i in 0..3 {
        let (p, q) = (t[i], t[(i + 1) % 3]);
        if (p.y <= y && y <= q.y) || (q.y <= y && y <= p.y) {
            if p.y == q.y {
                lo = lo.min(p.x.min(q.x));
                hi = hi.max(p.x.max(q.x));
            } else {
                let x = p.x + (y - p.y) * (q.x - p.x) / (q.y - p.y);
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// Barycentric weights of `p` in triangle `t` (of non-zero area), clamped to the triangle so
/// that a point a rounding error outside still gets a convex blend.
fn barycentric(t: &[DVec2; 3], p: DVec2) -> [f32; 3] {
    let [a, b, c] = *t;
    let doubled_area = (b - a).perp_dot(c - a);
    let wa = ((c - b).perp_dot(p - b) / doubled_area).clamp(0.0, 1.0);
    let wb = ((a - c).perp_dot(p - c) / doubled_area).clamp(0.0, 1.0);
    let wc = (1.0 - wa - wb).clamp(0.0, 1.0);
    [wa as f32, wb as f32, wc as f32]
}

/// Jitter of the sample row of cell row `cy`, in `0..k`. The constant salts the key, so that
/// row `cy`'s jitter is not the column jitter of cell `(cy, 0)`.
fn row_jitter(cy: usize, k: u64) -> u64 {
    mix(cy as u64 ^ 0x9e37_79b9_7f4a_7c15) % k
}

/// Jitter of the sample column of cell `(cx, cy)`, in `0..k`.
fn column_jitter(cx: usize, cy: usize, k: u64) -> u64 {
    mix((cy as u64).rotate_left(32) ^ cx as u64) % k
}
