//! The colour structure histogram of one chart: MPEG-7's structuring element (Messing et al.
//! 2001) slid over a grid of 256-cell colour codes in which some cells are not covered.
//!
//! MPEG-7 slides an 8x8 element over every position fully inside a rectangular image and, at
//! each position, adds one to every colour present in it. A chart is not a rectangle: its
//! covered cells are the footprint of a UV island. Here the element is anchored on each
//! covered cell instead (it spans offsets -4..=3 around the anchor, clipped to the grid) and
//! looks only at covered cells. So the histogram is normalised by the number of covered
//! cells, empty space around a chart neither adds positions nor dilutes them, and a chart
//! thinner than 8 cells is still measured. On a fully covered image this is MPEG-7's
//! histogram up to the positions near the border.

use super::hmmd::unify_bin;
use super::{CSD_BASE_CELLS, CSD_BINS};

/// The code of a cell no triangle covers (or whose texel an alpha mask cuts out).
pub(super) const UNCOVERED: u16 = u16::MAX;

/// The owner of a cell no triangle covers.
pub(super) const NO_OWNER: u32 = u32::MAX;

/// Which of the 256 colour cells are present: one bit per cell.
type CellSet = [u64; 4];

/// A chart: a `width x height` grid of 256-cell colour codes or [`UNCOVERED`].
#[derive(Debug, Default)]
pub(super) struct Chart {
    /// Columns.
    pub(super) width: usize,
    /// Rows.
    pub(super) height: usize,
    /// Row-major codes.
    pub(super) codes: Vec<u16>,
    /// Row-major index of the island triangle whose footprint holds each cell's sample point,
    /// or [`NO_OWNER`]: the rasteriser's coverage pass, kept here to reuse the allocation.
    pub(super) owner: Vec<u32>,
}

impl Chart {
    /// Clears the chart to `width x height` uncovered cells, keeping the allocation.
    pub(super) fn reset(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.codes.clear();
        self.codes.resize(width * height, UNCOVERED);
        self.owner.clear();
        self.owner.resize(width * height, NO_OWNER);
    }
}

/// Reusable buffers of [`structure_histogram`].
#[derive(Debug, Default)]
pub(super) struct StructureScratch {
    /// Ring of horizontal window sets, one row per row a window spans, indexed by row
    /// modulo the ring's height.
    rows: Vec<CellSet>,
}

/// The normalised 32-bin structure histogram of `chart`, or `None` when no cell is covered.
///
/// Each covered cell anchors one element position; every 256-cell colour present among the
/// covered cells of the `element x element` window counts once. The 256-cell counts are then
/// unified into the 32 bins by summing (MPEG-7's bin unification, which can count a window
/// twice in one bin when two of its 256-cell colours unify), divided by the number of
/// positions and clipped to 1, as the reference clips to its normalisation.
pub(super) fn structure_histogram(
    chart: &Chart,
    element: usize,
    scratch: &mut StructureScratch,
) -> Option<[f64; CSD_BINS]> {
    let (w, h) = (chart.width, chart.height);
    let element = element.max(1);
    // The window around an anchor at x spans x - before ..= x + after.
    let before = element / 2;
    let after = element - 1 - before;
    // A window spans at most `element` rows; a chart lower than that keeps all its rows.
    let ring = element.min(h).max(1);
    scratch.rows.clear();
    scratch.rows.resize(ring * w, [0; 4]);

    let mut counts = [0u64; CSD_BASE_CELLS];
    let mut positions = 0u64;
    let mut next_row = 0; // rows below this one have their window sets in the ring
    for y in 0..h {
        // Bring the rows y - before ..= y + after into the ring.
        while next_row < h && next_row <= y + after {
            let slot = (next_row % ring) * w;
            let codes = &chart.codes[next_row * w..(next_row + 1) * w];
            horizontal_sets(codes, before, after, &mut scratch.rows[slot..slot + w]);
            next_row += 1;
        }
        let first = y.saturating_sub(before);
        let last = (y + after).min(h - 1);
        for x in 0..w {
            if chart.codes[y * w + x] == UNCOVERED {
                continue;
            }
            let mut present: CellSet = [0; 4];
            for row in first..=last {
                let set = &scratch.rows[(row % ring) * w + x];
                for (p, s) in present.iter_mut().zip(set) {
                    *p |= s;
                }
            }
            positions += 1;
            for (word, &bits) in present.iter().enumerate() {
                let mut bits = bits;
                while bits != 0 {
                    counts[word * 64 + bits.trailing_zeros() as usize] += 1;
                    bits &= bits - 1;
                }
            }
        }
    }
    if positions == 0 {
        return None;
    }

    let mut unified = [0u64; CSD_BINS];
    for (cell, &count) in counts.iter().enumerate() {
        unified[unify_bin(cell)] += count;
    }
    Some(unified.map(|c| (c as f64 / positions as f64).min(1.0)))
}

/// For each cell of one row, the set of colours in the window `x - before ..= x + after` of
/// that row.
fn horizontal_sets(codes: &[u16], before: usize, after: usize, out: &mut [CellSet]) {
    let w = codes.len();
    for (x, set) in out.iter_mut().enumerate() {
        *set = [0; 4];
        let lo = x.saturating_sub(before);
        let hi = (x + after).min(w - 1);
        for &code in &codes[lo..=hi] {
            if code != UNCOVERED {
                let c = usize::from(code);
                set[c >> 6] |= 1 << (c & 63);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(width: usize, height: usize, code: impl Fn(usize, usize) -> u16) -> Chart {
        let mut c = Chart::default();
        c.reset(width, height);
        for y in 0..height {
            for x in 0..width {
                c.codes[y * width + x] = code(x, y);
            }
        }
        c
    }

    #[test]
    fn uniform_chart_fills_one_bin() {
        // Every window holds only black (256-cell 224 -> bin 24).
        let c = chart(20, 5, |_, _| 224);
        let h = structure_histogram(&c, 8, &mut StructureScratch::default());
        let h = h.unwrap_or_default();
        assert_eq!(h[24], 1.0);
        assert_eq!(h.iter().sum::<f64>(), 1.0);
    }

    #[test]
    fn empty_chart_has_no_histogram() {
        let c = chart(3, 3, |_, _| UNCOVERED);
        assert!(structure_histogram(&c, 8, &mut StructureScratch::default()).is_none());
        let c = chart(0, 0, |_, _| 0);
        assert!(structure_histogram(&c, 8, &mut StructureScratch::default()).is_none());
    }

    #[test]
    fn two_halves_overlap_near_the_border() {
        // 16 columns: 0..8 black (224 -> bin 24), 8..16 white (255 -> bin 31). An anchor at
        // column x sees columns x-4..=x+3: black when x <= 11 (12 anchors of 16 per row),
        // white when x >= 5 (11 anchors).
        let c = chart(16, 4, |x, _| if x < 8 { 224 } else { 255 });
        let h = structure_histogram(&c, 8, &mut StructureScratch::default()).unwrap_or_default();
        assert_eq!(h[24], 12.0 / 16.0);
        assert_eq!(h[31], 11.0 / 16.0);
    }

    #[test]
    fn uncovered_cells_do_not_count() {
        // A covered 2x2 block of red in a 12x12 chart: four anchors, each seeing red only.
        let c = chart(12, 12, |x, y| {
            if (5..7).contains(&x) && (5..7).contains(&y) {
                0
            } else {
                UNCOVERED
            }
        });
        let h = structure_histogram(&c, 8, &mut StructureScratch::default()).unwrap_or_default();
        assert_eq!(h[0], 1.0);
        assert_eq!(h.iter().sum::<f64>(), 1.0);
    }

    #[test]
    fn unification_adds_and_clips() {
        // Two greys of the same 32-bin (256-cells 224 and 225 both unify to bin 24) in every
        // window: each counts once, the sum is 2, clipped to 1.
        let c = chart(4, 4, |x, _| if x % 2 == 0 { 224 } else { 225 });
        let h = structure_histogram(&c, 8, &mut StructureScratch::default()).unwrap_or_default();
        assert_eq!(h[24], 1.0);
    }
}
