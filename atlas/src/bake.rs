//! Stage 3: bake. Each chart's box is resampled into its rectangle, multiplied by its material's
//! base colour factor, and its gutter filled by extending the edge texels.
//!
//! Colour follows glTF 2.0 (section 3.9.2): the base colour texture is sRGB-encoded and the
//! factor is linear, so texels are decoded to linear light (`color.rs`), filtered and
//! multiplied there, and encoded back to sRGB with rounding. Alpha is linear throughout. An
//! atlas texel centre at `(i + 0.5, j + 0.5)` inside its rectangle maps to the chart point
//! `min + (i + 0.5, j + 0.5) * (box size / rect size)`, the inverse of the UV remapping; at scale
//! 1 that is a source texel centre and bilinear sampling returns the texel unchanged.
//!
//! A chart kept at full size or enlarged is sampled bilinearly. A shrunk one is sampled
//! trilinearly, as a GPU samples a mipmapped texture (OpenGL 4.6, section 8.14): the level of
//! detail is log2 of the larger of the two steps (source texels per atlas texel), and the two
//! mip levels around it (`cache.rs`, built in linear light) are each sampled bilinearly and
//! blended. Every shrink factor is thus filtered over its whole footprint at a cost of two
//! bilinear samples per texel, where a fixed box of bilinear samples costs more and aliases
//! once the shrink outgrows the box.

use glam::{DVec2, Vec4};
use horizon_mesh::model::{AlphaMode, Wrap};
use image::{Rgba, RgbaImage};
use rayon::prelude::*;

use crate::chart::Chart;
use crate::color::{linear_to_srgb8, texel_linear};
use crate::layout::{Layout, PackedRect};
use crate::source::Source;

/// Texel coordinates are clamped to +-2^52 before conversion to integers: beyond that an f64
/// has no fractional texels left, and the sum `x0 + 1` stays far from i64 overflow.
const FAR_TEXEL: f64 = 4_503_599_627_370_496.0;

/// Bakes every chart into an atlas of the layout's size. Texels outside every padded rectangle
/// stay transparent black. When `opaque`, every alpha is 255.
pub(crate) fn bake_atlas(
    charts: &[Chart],
    layout: &Layout,
    sources: &[Option<Source>],
    opaque: bool,
) -> RgbaImage {
    // Interiors in parallel (each chart into its own buffer: the rectangles are disjoint), then
    // copied in, then the gutters, which read the interiors.
    let interiors: Vec<Vec<Rgba<u8>>> = charts
        .par_iter()
        .zip(&layout.rects)
        .map(|(chart, rect)| bake_interior(chart, rect, sources, opaque))
        .collect();
    let mut atlas = RgbaImage::new(layout.width, layout.height);
    for (rect, texels) in layout.rects.iter().zip(&interiors) {
        for (k, px) in texels.iter().enumerate() {
            let (i, j) = (k as u32 % rect.width, k as u32 / rect.width);
            atlas.put_pixel(rect.x + i, rect.y + j, *px);
        }
    }
    for rect in &layout.rects {
        // Gutter: each texel repeats the nearest interior texel.
        let (x0, y0, x1, y1) = layout.padded(rect);
        for y in y0..y1 {
            for x in x0..x1 {
                let inside = (rect.x..rect.x + rect.width).contains(&x)
                    && (rect.y..rect.y + rect.height).contains(&y);
                if !inside {
                    let cx = x.clamp(rect.x, rect.x + rect.width - 1);
                    let cy = y.clamp(rect.y, rect.y + rect.height - 1);
                    let px = *atlas.get_pixel(cx, cy);
                    atlas.put_pixel(x, y, px);
                }
            }
        }
    }
    atlas
}

/// One chart's rectangle, row by row: resampled, multiplied, alpha resolved, encoded.
///
/// The sample grid is separable: a texel's bilinear sample of a level takes its column from
/// `i` alone and its row from `j` alone. So every column tap (two wrapped texel indices and a
/// weight) and every row tap is computed once per chart and level rather than once per texel,
/// with the same arithmetic as a bilinear sample of the whole point (`sample_bilinear`, the
/// tests' reference): the result is the same bit for bit.
fn bake_interior(
    chart: &Chart,
    rect: &PackedRect,
    sources: &[Option<Source>],
    opaque: bool,
) -> Vec<Rgba<u8>> {
    let source = chart.texture.and_then(|t| sources.get(t)?.as_ref());
    let step = (chart.max - chart.min) / DVec2::new(f64::from(rect.width), f64::from(rect.height));
    let texels = rect.width as usize * rect.height as usize;
    let Some(src) = source else {
        let flat = encode_texel(Vec4::ONE * chart.factor, chart.alpha, opaque);
        return vec![flat; texels];
    };
    let (lower, upper, blend) = lod_levels(step, src.texture.levels());
    let first = LevelTaps::new(chart, rect, step, src, lower);
    let second = (blend > 0.0).then(|| LevelTaps::new(chart, rect, step, src, upper));
    let mut out = Vec::with_capacity(texels);
    for j in 0..rect.height as usize {
        for i in 0..rect.width as usize {
            let mut colour = first.sample(i, j);
            if let Some(second) = &second {
                colour = colour * (1.0 - blend) + second.sample(i, j) * blend;
            }
            out.push(encode_texel(colour * chart.factor, chart.alpha, opaque));
        }
    }
    out
}

/// The mip levels a chart sampled at `step` source texels per atlas texel reads, and the
/// weight of the second: level of detail log2 of the larger step (0 when not shrunk), the
/// levels below and above it, clamped to the `levels` the chain has.
fn lod_levels(step: DVec2, levels: usize) -> (usize, usize, f32) {
    let last = levels.saturating_sub(1);
    let larger = step.x.max(step.y);
    if step.is_nan() || larger <= 1.0 {
        return (0, 0, 0.0);
    }
    let lod = larger.log2().min(last as f64);
    let lower = lod.floor() as usize;
    let upper = (lower + 1).min(last);
    let blend = if upper == lower {
        0.0
    } else {
        (lod - lower as f64) as f32
    };
    (lower, upper, blend)
}

/// Image texels to level-`level` texels: `2^-level`.
fn level_scale(level: usize) -> f64 {
    0.5f64.powi(i32::try_from(level).unwrap_or(i32::MAX))
}

/// The column and row taps of one mip level over a chart's rectangle.
struct LevelTaps<'a> {
    columns: Vec<Tap>,
    rows: Vec<Tap>,
    pixels: &'a [u8],
}

impl<'a> LevelTaps<'a> {
    /// Level `level` of `src`: the chart's box and step in that level's texels, `2^-level`
    /// of the image's (`cache.rs`: a level's texel covers `2^level` image texels a side).
    fn new(chart: &Chart, rect: &PackedRect, step: DVec2, src: &'a Source, level: usize) -> Self {
        let image = src.texture.level(level);
        let (w, h) = image.dimensions();
        let to_level = level_scale(level);
        let (min, step) = (chart.min * to_level, step * to_level);
        Self {
            // Byte offsets into the RGBA8 pixels: a column's texel times 4, a row's times the
            // row.
            columns: taps(min.x, step.x, rect.width, w, src.wrap[0], 4),
            rows: taps(min.y, step.y, rect.height, h, src.wrap[1], w as usize * 4),
            pixels: image.as_raw(),
        }
    }

    /// The bilinear sample of atlas texel (`i`, `j`) in linear light.
    #[inline]
    fn sample(&self, i: usize, j: usize) -> Vec4 {
        let (x, y) = (self.columns[i], self.rows[j]);
        let texel = |a: usize, b: usize| {
            let k = a + b;
            texel_linear(&Rgba([
                self.pixels[k],
                self.pixels[k + 1],
                self.pixels[k + 2],
                self.pixels[k + 3],
            ]))
        };
        let top = texel(x.at[0], y.at[0]) * (1.0 - x.t) + texel(x.at[1], y.at[0]) * x.t;
        let bottom = texel(x.at[0], y.at[1]) * (1.0 - x.t) + texel(x.at[1], y.at[1]) * x.t;
        top * (1.0 - y.t) + bottom * y.t
    }
}

/// One axis of a bilinear sample: where the two source texels it blends start (their index
/// times the axis' stride in bytes) and the second's weight.
#[derive(Clone, Copy, Debug)]
struct Tap {
    at: [usize; 2],
    t: f32,
}

/// The taps along one axis of a rectangle `size` texels long: texel `i` samples
/// `min + (i + 0.5) * step` in source texel space (the per-axis half of a bilinear sample,
/// computed the same way).
fn taps(min: f64, step: f64, size: u32, n: u32, wrap: Wrap, stride: usize) -> Vec<Tap> {
    (0..size)
        .map(|i| {
            let q = (min + (f64::from(i) + 0.5) * step) - 0.5;
            // The clamp of `sample_bilinear` (glam's, which also sends NaN to the low end).
            let f = floor(q);
            let f = if f > -FAR_TEXEL { f } else { -FAR_TEXEL };
            let f = if f < FAR_TEXEL { f } else { FAR_TEXEL };
            let t = (q - f) as f32;
            let i0 = f as i64;
            Tap {
                at: [wrap_index(i0, n, wrap), wrap_index(i0 + 1, n, wrap)]
                    .map(|i| i as usize * stride),
                t,
            }
        })
        .collect()
}

/// Linear RGBA to an sRGB texel, after the material's alpha mode: a mask becomes 0 or 1 against
/// its own cut-off, an opaque material (or atlas) gets alpha 1.
fn encode_texel(colour: Vec4, alpha: AlphaMode, opaque: bool) -> Rgba<u8> {
    let a = match alpha {
        _ if opaque => 1.0,
        AlphaMode::Opaque => 1.0,
        AlphaMode::Mask { cutoff } => {
            if colour.w >= cutoff {
                1.0
            } else {
                0.0
            }
        }
        AlphaMode::Blend => colour.w,
    };
    Rgba([
        linear_to_srgb8(colour.x),
        linear_to_srgb8(colour.y),
        linear_to_srgb8(colour.z),
        (a.clamp(0.0, 1.0) * 255.0).round() as u8,
    ])
}

/// Bilinear sample of `src` at `p` in texel space (texel centres at `i + 0.5`), honouring the
/// wrap modes; returns linear RGB and alpha. The bake does the same per axis ([`taps`]); this
/// whole-point form is the reference its tests hold it to.
#[cfg(test)]
fn sample_bilinear(image: &RgbaImage, wrap: [Wrap; 2], p: DVec2) -> Vec4 {
    let (w, h) = image.dimensions();
    let q = p - DVec2::splat(0.5);
    // Far tiles fold like near ones; clamping first keeps `x0 + 1` from overflowing i64.
    let f =
        DVec2::new(floor(q.x), floor(q.y)).clamp(DVec2::splat(-FAR_TEXEL), DVec2::splat(FAR_TEXEL));
    let t = (q - f).as_vec2();
    let (x0, y0) = (f.x as i64, f.y as i64);
    let xs = [wrap_index(x0, w, wrap[0]), wrap_index(x0 + 1, w, wrap[0])];
    let ys = [wrap_index(y0, h, wrap[1]), wrap_index(y0 + 1, h, wrap[1])];
    let texel = |x: u32, y: u32| texel_linear(image.get_pixel(x, y));
    let top = texel(xs[0], ys[0]) * (1.0 - t.x) + texel(xs[1], ys[0]) * t.x;
    let bottom = texel(xs[0], ys[1]) * (1.0 - t.x) + texel(xs[1], ys[1]) * t.x;
    top * (1.0 - t.y) + bottom * t.y
}

/// `x.floor()` without the libm call that baseline x86-64 (no SSE4.1 `roundsd`) makes of it:
/// the bake's inner loop calls it twice per bilinear sample. Exact for every finite `x`.
#[inline]
fn floor(x: f64) -> f64 {
    // Beyond 2^52 every f64 is an integer; NaN passes through to the clamp.
    if x.is_nan() || x.abs() >= FAR_TEXEL {
        return x;
    }
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Folds a texel index into `0..n` by a glTF wrap mode.
#[inline]
fn wrap_index(i: i64, n: u32, wrap: Wrap) -> u32 {
    // Most samples fall inside the texture, where every mode is the identity.
    if (0..i64::from(n)).contains(&i) {
        return i as u32;
    }
    let n = i64::from(n);
    let folded = match wrap {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m >= n {
                2 * n - 1 - m
            } else {
                m
            }
        }
        Wrap::ClampToEdge => i.clamp(0, n - 1),
    };
    folded as u32
}

#[cfg(test)]
mod floor_tests {
    #[test]
    fn floor_matches_the_library_floor() {
        let xs = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.999_999,
            -2.000_001,
            1e15 + 0.5,
            -1e15 - 0.5,
            4.6e18,
            -4.6e18,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        for x in xs {
            assert_eq!(super::floor(x), x.floor(), "{x}");
        }
        assert!(super::floor(f64::NAN).is_nan());
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::cache::DecodedTexture;

    #[test]
    fn wrap_modes_fold_indices() {
        // Width 3: repeat cycles 0 1 2, mirror goes 0 1 2 2 1 0, clamp sticks to the edges.
        let fold = |w| (-3..6).map(|i| wrap_index(i, 3, w)).collect::<Vec<_>>();
        assert_eq!(fold(Wrap::Repeat), vec![0, 1, 2, 0, 1, 2, 0, 1, 2]);
        assert_eq!(fold(Wrap::MirroredRepeat), vec![2, 1, 0, 0, 1, 2, 2, 1, 0]);
        assert_eq!(fold(Wrap::ClampToEdge), vec![0, 0, 0, 0, 1, 2, 2, 2, 2]);
    }

    #[test]
    fn texel_centres_sample_exactly() {
        // At a texel centre the bilinear weights are 1 and 0, so the texel comes back.
        let mut image = RgbaImage::new(2, 1);
        image.put_pixel(0, 0, Rgba([10, 20, 30, 255]));
        image.put_pixel(1, 0, Rgba([200, 100, 50, 128]));
        let wrap = [Wrap::Repeat; 2];
        let c = sample_bilinear(&image, wrap, DVec2::new(1.5, 0.5));
        assert_eq!(
            encode_texel(c, AlphaMode::Blend, false),
            Rgba([200, 100, 50, 128])
        );
        // Two texels to the right is the same texel again under Repeat.
        let c = sample_bilinear(&image, wrap, DVec2::new(3.5, 0.5));
        assert_eq!(
            encode_texel(c, AlphaMode::Blend, false),
            Rgba([200, 100, 50, 128])
        );
    }

    /// The bake without shared taps: every sample through [`sample_bilinear`], on the levels
    /// [`lod_levels`] picks, each point mapped into the level the way the taps are.
    fn bake_reference(chart: &Chart, rect: &PackedRect, src: &Source) -> Vec<Rgba<u8>> {
        let step =
            (chart.max - chart.min) / DVec2::new(f64::from(rect.width), f64::from(rect.height));
        let (lower, upper, blend) = lod_levels(step, src.texture.levels());
        let sample = |level: usize, i: u32, j: u32| {
            let image = src.texture.level(level);
            let to_level = 0.5f64.powi(level as i32);
            let (min, step) = (chart.min * to_level, step * to_level);
            let sub = DVec2::new(f64::from(i) + 0.5, f64::from(j) + 0.5);
            sample_bilinear(image, src.wrap, min + sub * step)
        };
        let mut out = Vec::new();
        for j in 0..rect.height {
            for i in 0..rect.width {
                let mut colour = sample(lower, i, j);
                if blend > 0.0 {
                    colour = colour * (1.0 - blend) + sample(upper, i, j) * blend;
                }
                out.push(encode_texel(colour * chart.factor, chart.alpha, false));
            }
        }
        out
    }

    /// A chart over the whole of a `side` x `side` texture, baked into `rect` x `rect` texels.
    fn bake_whole(image: RgbaImage, rect: u32) -> Vec<Rgba<u8>> {
        let (w, h) = image.dimensions();
        let src = Source {
            texture: Arc::new(DecodedTexture::new(image)),
            wrap: [Wrap::Repeat; 2],
        };
        let chart = Chart {
            texture: Some(0),
            material: None,
            factor: Vec4::ONE,
            alpha: AlphaMode::Opaque,
            min: DVec2::ZERO,
            max: DVec2::new(f64::from(w), f64::from(h)),
            cap: DVec2::splat(1e9),
        };
        let rect = PackedRect {
            x: 0,
            y: 0,
            width: rect,
            height: rect,
        };
        bake_interior(&chart, &rect, &[Some(src)], true)
    }

    #[test]
    fn a_shrunk_checkerboard_bakes_to_its_mean_not_to_one_of_its_colours() {
        // One-texel black and white squares shrunk 2, 5, 8 and 16 times: every texel is the
        // mean, mid grey (sRGB 188 is linear 0.5), within a few codes, not a coarser
        // checkerboard of aliased samples.
        for shrink in [2u32, 5, 8, 16] {
            let side = 16 * shrink;
            let board = RgbaImage::from_fn(side, side, |x, y| {
                let v = if (x + y) % 2 == 0 { 0 } else { 255 };
                Rgba([v, v, v, 255])
            });
            for px in bake_whole(board, 16) {
                assert!(
                    (i32::from(px[0]) - 188).abs() <= 6,
                    "shrunk {shrink}x: {px:?}"
                );
            }
        }
    }

    #[test]
    fn a_flat_texture_bakes_flat_at_every_scale() {
        let flat = RgbaImage::from_pixel(37, 23, Rgba([90, 160, 30, 255]));
        for rect in [1u32, 3, 10, 23, 37, 80] {
            for px in bake_whole(flat.clone(), rect) {
                assert_eq!(px, Rgba([90, 160, 30, 255]), "rect {rect}");
            }
        }
    }

    #[test]
    fn the_level_of_detail_follows_the_larger_step() {
        // Not shrunk: level 0 alone. Shrunk 2x: level 1 alone. 3x: between 1 and 2.
        assert_eq!(lod_levels(DVec2::new(1.0, 0.5), 8), (0, 0, 0.0));
        assert_eq!(lod_levels(DVec2::new(0.5, 2.0), 8), (1, 2, 0.0));
        let (lower, upper, blend) = lod_levels(DVec2::splat(3.0), 8);
        assert_eq!((lower, upper), (1, 2));
        assert!((blend - (3.0f32.log2() - 1.0)).abs() < 1e-6);
        // Beyond the chain: its last level.
        assert_eq!(lod_levels(DVec2::splat(1e6), 4), (3, 3, 0.0));
        assert_eq!(lod_levels(DVec2::splat(f64::NAN), 4), (0, 0, 0.0));
    }

    proptest::proptest! {
        #[test]
        fn shared_taps_bake_what_every_sample_alone_bakes(
            w in 1u32..9, h in 1u32..9,
            seed in proptest::prelude::any::<u64>(),
            min in (-40i32..40, -40i32..40),
            size in (1i32..60, 1i32..60),
            rect in (1u32..24, 1u32..24),
            wraps in (0usize..3, 0usize..3),
        ) {
            // Random texels, a random box anywhere (wrapping included), shrunk or enlarged.
            let mut state = seed | 1;
            let image = RgbaImage::from_fn(w, h, |_, _| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let b = state.to_le_bytes();
                Rgba([b[0], b[1], b[2], b[3]])
            });
            let modes = [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge];
            let src = Source {
                texture: Arc::new(DecodedTexture::new(image)),
                wrap: [modes[wraps.0], modes[wraps.1]],
            };
            let chart = Chart {
                texture: Some(0),
                material: None,
                factor: Vec4::new(0.9, 0.8, 1.0, 0.7),
                alpha: AlphaMode::Blend,
                min: DVec2::new(f64::from(min.0), f64::from(min.1)),
                max: DVec2::new(f64::from(min.0 + size.0), f64::from(min.1 + size.1)),
                cap: DVec2::splat(1e9),
            };
            let rect = PackedRect { x: 0, y: 0, width: rect.0, height: rect.1 };
            let fast = bake_interior(&chart, &rect, &[Some(src.clone())], false);
            proptest::prop_assert_eq!(fast, bake_reference(&chart, &rect, &src));
        }
    }
}
