//! The colour side of MPEG-7's Color Structure Descriptor (ISO/IEC 15938-3; Manjunath et al.
//! 2001, section IV.C; Messing et al. 2001): the HMMD colour space, its non-uniform
//! quantisation into 256 and 32 cells, the unification of the 256 cells into the 32, the
//! non-uniform 8-bit amplitude quantisation of a bin, and sRGB encoding.
//!
//! The quantisation tables below are the standard's (they match the MPEG-7 eXperimentation
//! Model's `ColorStructureExtraction`): the Diff axis is cut into subspaces, and each subspace
//! is cut uniformly along Hue and Sum.

use std::sync::OnceLock;

/// A colour in MPEG-7's HMMD space, in the standard's integer units.
///
/// `hue` is the HSV hue in degrees (0..=360, rounded; 0 for greys, whose hue is undefined),
/// `sum` is `(max + min) / 2` rounded and `diff` is `max - min`, both on the 0..=255 scale
/// of the 8-bit RGB components.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hmmd {
    /// Hue in degrees, 0..=360.
    pub hue: u16,
    /// `(max + min) / 2`, rounded half up.
    pub sum: u8,
    /// `max - min`: how far from grey the colour is.
    pub diff: u8,
}

impl Hmmd {
    /// Converts an 8-bit RGB colour (as stored in an sRGB image) to HMMD, rounding as the
    /// standard does.
    pub fn from_rgb8(rgb: [u8; 3]) -> Self {
        let [r, g, b] = rgb.map(i32::from);
        let max = r.max(g).max(b);
        let min = r.min(g).min(b);
        let diff = max - min;
        let hue = if diff == 0 {
            0.0
        } else {
            let d = diff as f32;
            // HSV's hexcone hue: which component is largest picks the sextant pair.
            let sextant = if r == max {
                (g - b) as f32 / d
            } else if g == max {
                2.0 + (b - r) as f32 / d
            } else {
                4.0 + (r - g) as f32 / d
            };
            let degrees = sextant * 60.0;
            if degrees < 0.0 {
                degrees + 360.0
            } else {
                degrees
            }
        };
        Self {
            // Rounded half up like the reference; 359.6 rounds to 360, which the quantiser
            // folds back to hue 0.
            hue: (hue + 0.5) as u16,
            sum: ((max + min + 1) / 2) as u8,
            diff: diff as u8,
        }
    }

    /// The cell of the 256-cell quantisation: the space the structure is extracted in.
    pub fn bin_256(self) -> usize {
        QUANT_256.bin(self)
    }

    /// The cell of the 32-cell quantisation, the descriptor's bins.
    ///
    /// Bins 0..=3 are saturated colours (diff >= 110) by hue quadrant, 4..=7 strong colours
    /// (60 <= diff < 110), 8..=23 moderate colours (6 <= diff < 60, 4 hues x 4 sums) and
    /// 24..=31 the greys (diff < 6), from black to white.
    pub fn bin_32(self) -> usize {
        QUANT_32.bin(self)
    }
}

/// One of MPEG-7's HMMD quantisations: the Diff axis cut into subspaces at `diff_thresholds`,
/// each subspace cut uniformly into `hue_levels x sum_levels` cells; `offsets` is where each
/// subspace's cells start (the standard numbers the greys last).
#[derive(Debug)]
struct HmmdQuantisation {
    /// Lower bound of each subspace's Diff range, then 256.
    diff_thresholds: &'static [i32],
    /// Hue cells per subspace.
    hue_levels: &'static [i32],
    /// Sum cells per subspace.
    sum_levels: &'static [i32],
    /// First cell of each subspace.
    offsets: &'static [i32],
}

/// The 256-cell quantisation (ISO/IEC 15938-3, colour structure, 256 cells).
const QUANT_256: HmmdQuantisation = HmmdQuantisation {
    diff_thresholds: &[0, 6, 20, 60, 110, 256],
    hue_levels: &[1, 4, 16, 16, 16],
    sum_levels: &[32, 8, 4, 4, 4],
    offsets: &[224, 192, 128, 64, 0],
};

/// The 32-cell quantisation (ISO/IEC 15938-3, colour structure, 32 cells).
const QUANT_32: HmmdQuantisation = HmmdQuantisation {
    diff_thresholds: &[0, 6, 60, 110, 256],
    hue_levels: &[1, 4, 4, 4],
    sum_levels: &[8, 4, 1, 1],
    offsets: &[24, 8, 4, 0],
};

impl HmmdQuantisation {
    /// The cell of `c`: Diff picks the subspace, then Hue and Sum are cut uniformly inside it.
    fn bin(&self, c: Hmmd) -> usize {
        let (hue, sum, diff) = (i32::from(c.hue), i32::from(c.sum), i32::from(c.diff));
        let sub = self.diff_thresholds[1..]
            .iter()
            .position(|&upper| diff < upper)
            .unwrap_or(self.hue_levels.len() - 1);
        let (n_hue, n_sum) = (self.hue_levels[sub], self.sum_levels[sub]);
        // Hue 360 is hue 0.
        let h = (hue * n_hue / 360) % n_hue;
        // Inside subspace `sub` the Sum axis runs from threshold / 2 to 255 - threshold / 2
        // (the HMMD double cone), so the reference cuts (sum - t/2) / (255 - t); doubled
        // here to stay in integers. The numerator is never negative: sum >= diff / 2.
        let t = self.diff_thresholds[sub];
        let s = ((2 * sum - t).max(0) * n_sum / (2 * (255 - t))).min(n_sum - 1);
        (self.offsets[sub] + h * n_sum + s) as usize
    }
}

/// The 32-cell bin each of the 256 cells falls in: MPEG-7's bin unification, which is how a
/// 32-bin descriptor is derived from the 256-cell extraction.
///
/// Each entry is the 32-cell bin that most of the 256-cell's HMMD values quantise to (the
/// reference's rule; the test `unification_table_is_the_majority_vote` recomputes it over the
/// whole HMMD lattice). Cells straddle 32-cell boundaries only along Sum in the moderate
/// subspace, where the two quantisations cut Sum with different offsets.
pub fn unify_bin(bin_256: usize) -> usize {
    usize::from(UNIFY_256_TO_32[bin_256 % 256])
}

/// [`unify_bin`]'s table.
const UNIFY_256_TO_32: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        table[i] = unify_cell(i);
        i += 1;
    }
    table
};

/// The majority 32-cell bin of 256-cell `i`, by subspace (see [`QUANT_256`], [`QUANT_32`]).
const fn unify_cell(i: usize) -> u8 {
    let i = i as u8;
    match i {
        // diff >= 110: 16 hues x 4 sums -> 4 hues x 1 sum.
        0..=63 => i / 16,
        // 60 <= diff < 110: 16 hues x 4 sums -> 4 hues x 1 sum.
        64..=127 => 4 + (i - 64) / 16,
        // 20 <= diff < 60: 16 hues x 4 sums -> 4 hues x 4 sums, same Sum cells.
        128..=191 => {
            let (h, s) = ((i - 128) / 4, (i - 128) % 4);
            8 + (h / 4) * 4 + s
        }
        // 6 <= diff < 20: 4 hues x 8 sums -> 4 hues x 4 sums.
        192..=223 => {
            let (h, s) = ((i - 192) / 8, (i - 192) % 8);
            8 + h * 4 + s / 2
        }
        // Greys: 32 sums -> 8 sums.
        _ => 24 + (i - 224) / 4,
    }
}

/// Width of each linear segment of MPEG-7's amplitude quantisation: a normalised bin value in
/// `[AMPLITUDE_THRESHOLDS[i], AMPLITUDE_THRESHOLDS[i + 1])` gets one of `AMPLITUDE_LEVELS[i]`
/// codes. Small values get finer steps (Messing et al. 2001; the standard's table).
const AMPLITUDE_THRESHOLDS: [f64; 7] = [0.0, 1e-12, 0.037, 0.08, 0.195, 0.32, 1.0];

/// Codes per segment of [`AMPLITUDE_THRESHOLDS`]; they add up to 256.
const AMPLITUDE_LEVELS: [u32; 6] = [1, 25, 20, 35, 35, 140];

/// MPEG-7's non-uniform 8-bit quantisation of a normalised bin value (the fraction of
/// structuring-element positions holding the colour, 0..=1).
///
/// 0 stays 0, anything present is at least 1, and 1.0 is 255. Values outside 0..=1 (and NaN)
/// are clamped.
pub fn quantize_amplitude(value: f64) -> u8 {
    let v = if value.is_nan() {
        0.0
    } else {
        value.clamp(0.0, 1.0)
    };
    let mut base = 0u32;
    for (i, &levels) in AMPLITUDE_LEVELS.iter().enumerate() {
        let (lo, hi) = (AMPLITUDE_THRESHOLDS[i], AMPLITUDE_THRESHOLDS[i + 1]);
        if v < hi || i + 1 == AMPLITUDE_LEVELS.len() {
            let step = ((v - lo) * f64::from(levels) / (hi - lo)).floor() as u32;
            return (base + step.min(levels - 1)) as u8;
        }
        base += levels;
    }
    255
}

/// The linear value of each 8-bit sRGB code (IEC 61966-2-1).
pub(super) fn srgb8_to_linear(code: u8) -> f32 {
    tables().to_linear[usize::from(code)]
}

/// The nearest 8-bit sRGB code of a linear value; values outside 0..=1 (and NaN) clamp.
pub(super) fn linear_to_srgb8(linear: f32) -> u8 {
    // `midpoints[i]` is the linear value halfway (in sRGB) between codes i and i + 1, so the
    // number of midpoints below `linear` is the nearest code.
    tables().midpoints.partition_point(|&m| m <= linear) as u8
}

/// The sRGB lookup tables, built once.
#[derive(Debug)]
struct SrgbTables {
    /// Linear value of each code.
    to_linear: [f32; 256],
    /// Linear values of the sRGB half-codes 0.5 ..= 254.5: the rounding boundaries.
    midpoints: [f32; 255],
}

fn tables() -> &'static SrgbTables {
    static TABLES: OnceLock<SrgbTables> = OnceLock::new();
    TABLES.get_or_init(|| {
        let decode = |s: f64| {
            if s <= 0.04045 {
                s / 12.92
            } else {
                ((s + 0.055) / 1.055).powf(2.4)
            }
        };
        let mut t = SrgbTables {
            to_linear: [0.0; 256],
            midpoints: [0.0; 255],
        };
        for (i, v) in t.to_linear.iter_mut().enumerate() {
            *v = decode(i as f64 / 255.0) as f32;
        }
        for (i, v) in t.midpoints.iter_mut().enumerate() {
            *v = decode((i as f64 + 0.5) / 255.0) as f32;
        }
        t
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every valid HMMD triple: `sum` lies between `diff / 2` and `255 - diff / 2`, the
    /// double cone the conversion can reach (the reference's lattice).
    fn hmmd_lattice() -> impl Iterator<Item = Hmmd> {
        (0u16..=360).flat_map(|hue| {
            (0u16..256).flat_map(move |diff| {
                (diff.div_ceil(2)..256 - diff / 2).map(move |sum| Hmmd {
                    hue,
                    sum: sum as u8,
                    diff: diff as u8,
                })
            })
        })
    }

    #[test]
    fn unification_table_is_the_majority_vote() {
        // For each 256-cell, count which 32-cell its HMMD values land in; the table must name
        // the most frequent one. Counting over a 1-in-3 subsample of hues keeps the test fast
        // in debug builds; every cell spans at least 22 hues, so none is missed.
        let mut votes = vec![[0u32; 32]; 256];
        for c in hmmd_lattice().filter(|c| c.hue % 3 == 0) {
            votes[c.bin_256()][c.bin_32()] += 1;
        }
        for (cell, counts) in votes.iter().enumerate() {
            let best = (0..32).max_by_key(|&b| (counts[b], 32 - b)).unwrap_or(0);
            assert!(counts[best] > 0, "cell {cell} is never reached");
            assert_eq!(unify_bin(cell), best, "cell {cell}: votes {counts:?}");
        }
    }

    #[test]
    fn quantisers_cover_every_cell() {
        let mut seen256 = [false; 256];
        let mut seen32 = [false; 32];
        for c in hmmd_lattice().filter(|c| c.hue % 5 == 0) {
            seen256[c.bin_256()] = true;
            seen32[c.bin_32()] = true;
        }
        assert!(seen256.iter().all(|&s| s));
        assert!(seen32.iter().all(|&s| s));
    }

    #[test]
    fn srgb_round_trips_every_code() {
        for code in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(code)), code);
        }
        assert_eq!(linear_to_srgb8(-1.0), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        // Mid-grey: linear 0.2158605 is sRGB 128 (0.5019...).
        assert_eq!(linear_to_srgb8(0.2158605), 128);
    }

    #[test]
    fn amplitude_segments_meet() {
        // The first code of each segment sits at its threshold.
        assert_eq!(quantize_amplitude(0.0), 0);
        assert_eq!(quantize_amplitude(1e-9), 1);
        assert_eq!(quantize_amplitude(0.037), 26);
        assert_eq!(quantize_amplitude(0.08), 46);
        assert_eq!(quantize_amplitude(0.195), 81);
        assert_eq!(quantize_amplitude(0.32), 116);
        assert_eq!(quantize_amplitude(1.0), 255);
        assert_eq!(quantize_amplitude(f64::NAN), 0);
        let mut last = 0;
        for i in 0..=10_000 {
            let q = quantize_amplitude(f64::from(i) / 10_000.0);
            assert!(q >= last);
            last = q;
        }
    }
}
