//! sRGB and linear light (IEC 61966-2-1): 8-bit texels decoded to linear RGB and alpha by exact
//! 256-entry tables, linear values encoded back to the nearest 8-bit sRGB code, and the mean
//! colour of an image. glTF base colour textures are sRGB and their alpha linear (glTF 2.0,
//! section 3.9.2), so filtering and averaging happen in linear light.

use std::sync::OnceLock;

use glam::Vec4;
use image::{Rgba, RgbaImage};

/// One texel as linear RGB and alpha.
pub(crate) fn texel_linear(px: &Rgba<u8>) -> Vec4 {
    let lut = srgb_to_linear_table();
    Vec4::new(
        lut[px[0] as usize],
        lut[px[1] as usize],
        lut[px[2] as usize],
        alpha_table()[px[3] as usize],
    )
}

/// The mean colour of an image in linear light, for a textured material drawn without UVs.
pub(crate) fn mean_linear(image: &RgbaImage) -> Vec4 {
    let n = (image.width() as f64 * image.height() as f64).max(1.0);
    let sum = image.pixels().fold(glam::DVec4::ZERO, |acc, px| {
        acc + texel_linear(px).as_dvec4()
    });
    (sum / n).as_vec4()
}

/// 8-bit alpha to [0, 1] (`a / 255`, looked up rather than divided in the bake's inner loop).
fn alpha_table() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|a| a as f32 / 255.0))
}

/// sRGB 8-bit code to linear light (IEC 61966-2-1).
fn srgb_to_linear_table() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|v| {
            let c = v as f64 / 255.0;
            let l = if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            };
            l as f32
        })
    })
}

/// Linear light to the nearest sRGB 8-bit code.
pub(crate) fn linear_to_srgb8(x: f32) -> u8 {
    // The code whose sRGB value rounds to x: the number of decision points at or below x,
    // where the decision point between codes v and v + 1 is the linear value of sRGB
    // (v + 0.5) / 255. A table over 4,096 equal steps of [0, 1] gives that count at the step's
    // lower end; the few decision points inside the step are then counted one by one.
    let thresholds = srgb_thresholds();
    let start = srgb_code_floor_table();
    // NaN and negatives go to step 0 (as `usize` saturates), beyond 1 to the last.
    let step = ((x * SRGB_STEPS as f32) as usize).min(SRGB_STEPS - 1);
    let mut code = usize::from(start[step]);
    while code < thresholds.len() && thresholds[code] <= x {
        code += 1;
    }
    code as u8
}

/// Steps of [`srgb_code_floor_table`].
const SRGB_STEPS: usize = 4096;

/// For step `s`, the count of decision points at or below `s / SRGB_STEPS`, a lower bound of
/// the code of every value in the step.
fn srgb_code_floor_table() -> &'static [u8; SRGB_STEPS] {
    static TABLE: OnceLock<[u8; SRGB_STEPS]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let thresholds = srgb_thresholds();
        std::array::from_fn(|s| {
            let low = s as f32 / SRGB_STEPS as f32;
            thresholds.partition_point(|&t| t <= low) as u8
        })
    })
}

/// Linear values at which the 8-bit sRGB code steps up (255 of them).
fn srgb_thresholds() -> &'static [f32; 255] {
    static TABLE: OnceLock<[f32; 255]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|v| {
            let c = (v as f64 + 0.5) / 255.0;
            let l = if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            };
            l as f32
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip_is_exact() {
        // Decoding then encoding must return every 8-bit code, or scale-1 charts would drift.
        let lut = srgb_to_linear_table();
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb8(lut[v as usize]), v);
        }
    }

    #[test]
    fn the_srgb_table_encodes_as_the_search_does() {
        // Every decision point and its neighbours one ulp away, a dense sweep, and the edges.
        let search = |x: f32| srgb_thresholds().partition_point(|&t| t <= x) as u8;
        let mut xs = vec![f32::NAN, -1.0, -0.0, 0.0, 1.0, 1.5, f32::INFINITY, f32::MAX];
        for &t in srgb_thresholds() {
            xs.extend([
                t,
                f32::from_bits(t.to_bits() - 1),
                f32::from_bits(t.to_bits() + 1),
            ]);
        }
        xs.extend((0..=200_000).map(|k| k as f32 / 200_000.0));
        for x in xs {
            assert_eq!(linear_to_srgb8(x), search(x), "{x}");
        }
    }
}
