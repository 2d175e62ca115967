//! Structural similarity (SSIM; Wang, Bovik, Sheikh and Simoncelli 2004, eq. 13), the
//! perceptual metric that decides "indistinguishable" in the Table 1 calibration.
//!
//! The paper used Yee and Newman's perceptual difference (pdiff). We use SSIM because it is
//! the standard full-reference metric with a published definition and constants, needs no
//! viewing-condition model, and stays defined on the tiny images Table 1 starts from (6x6):
//! the 11x11 Gaussian window (sigma 1.5) is renormalised where it leaves the image.
//!
//! Two adaptations to comparing renders of objects, both making the metric stricter:
//! - the SSIM map is averaged over the foreground only (pixels either image covers), so a
//!   small object on a large identical background does not score near 1 by default;
//! - colour images are scored per channel (R, G, B) and the worst channel is kept, so a
//!   recoloured model is told apart from its original even when its luminance barely moves.

use glam::Vec3;

use super::render::Image;

/// Dynamic range of the channels (they are in [0, 1]).
const RANGE: f64 = 1.0;
/// SSIM's stabilisers, K1 = 0.01 and K2 = 0.03 as published.
const C1: f64 = (0.01 * RANGE) * (0.01 * RANGE);
const C2: f64 = (0.03 * RANGE) * (0.03 * RANGE);
/// Gaussian window: sigma 1.5, radius 5 (11 taps), as published.
const SIGMA: f64 = 1.5;
const RADIUS: isize = 5;

/// SSIM of two renders of equal size: the mean of the SSIM map over the pixels where either
/// image differs from `background`, for the worst of R, G and B; 1 means identical (and two
/// empty renders score 1).
///
/// # Panics
/// If the images differ in size (the calibration always compares renders of equal size).
pub fn ssim(a: &Image, b: &Image, background: Vec3) -> f64 {
    assert_eq!(a.size, b.size, "SSIM compares images of equal size");
    let mask: Vec<bool> = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| *p != background || *q != background)
        .collect();
    if !mask.contains(&true) {
        return 1.0;
    }
    let taps: Vec<f64> = (-RADIUS..=RADIUS)
        .map(|i| (-((i * i) as f64) / (2.0 * SIGMA * SIGMA)).exp())
        .collect();
    (0..3)
        .map(|channel| {
            let x: Vec<f64> = a
                .pixels
                .iter()
                .map(|p| f64::from(pick(*p, channel)))
                .collect();
            let y: Vec<f64> = b
                .pixels
                .iter()
                .map(|p| f64::from(pick(*p, channel)))
                .collect();
            channel_ssim(&x, &y, a.size, &taps, &mask)
        })
        .fold(f64::INFINITY, f64::min)
}

fn pick(p: Vec3, channel: usize) -> f32 {
    p[channel]
}

/// Mean SSIM of one channel over `mask`: local means, variances and covariance under the
/// window.
fn channel_ssim(x: &[f64], y: &[f64], size: usize, taps: &[f64], mask: &[bool]) -> f64 {
    if size == 0 {
        return 1.0;
    }
    let products = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        x.iter().zip(y).map(|(&a, &b)| f(a, b)).collect()
    };
    let weight = blur(&vec![1.0; size * size], size, taps);
    let mean_x = blur(x, size, taps);
    let mean_y = blur(y, size, taps);
    let xx = blur(&products(&|a, _| a * a), size, taps);
    let yy = blur(&products(&|_, b| b * b), size, taps);
    let xy = blur(&products(&|a, b| a * b), size, taps);
    let mut sum = 0.0;
    let mut count = 0usize;
    for i in (0..size * size).filter(|&i| mask[i]) {
        count += 1;
        let w = weight[i];
        let (mx, my) = (mean_x[i] / w, mean_y[i] / w);
        let vx = (xx[i] / w - mx * mx).max(0.0);
        let vy = (yy[i] / w - my * my).max(0.0);
        let cov = xy[i] / w - mx * my;
        sum +=
            ((2.0 * mx * my + C1) * (2.0 * cov + C2)) / ((mx * mx + my * my + C1) * (vx + vy + C2));
    }
    sum / count.max(1) as f64
}

/// Separable Gaussian blur with the window cut at the image border (not renormalised here:
/// dividing by the blurred all-ones image does that).
fn blur(values: &[f64], size: usize, taps: &[f64]) -> Vec<f64> {
    let mut rows = vec![0.0; size * size];
    for y in 0..size {
        for x in 0..size {
            let mut s = 0.0;
            for (k, t) in taps.iter().enumerate() {
                let xx = x as isize + k as isize - RADIUS;
                if xx >= 0 && (xx as usize) < size {
                    s += t * values[y * size + xx as usize];
                }
            }
            rows[y * size + x] = s;
        }
    }
    let mut out = vec![0.0; size * size];
    for y in 0..size {
        for x in 0..size {
            let mut s = 0.0;
            for (k, t) in taps.iter().enumerate() {
                let yy = y as isize + k as isize - RADIUS;
                if yy >= 0 && (yy as usize) < size {
                    s += t * rows[yy as usize * size + x];
                }
            }
            out[y * size + x] = s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const BG: Vec3 = Vec3::splat(-1.0);

    fn checker(size: usize, a: f32, b: f32) -> Image {
        let mut img = Image::new(size, Vec3::ZERO);
        for y in 0..size {
            for x in 0..size {
                img.pixels[y * size + x] =
                    Vec3::splat(if (x / 4 + y / 4) % 2 == 0 { a } else { b });
            }
        }
        img
    }

    #[test]
    fn identical_images_score_one() {
        let img = checker(32, 0.2, 0.8);
        assert!((ssim(&img, &img, BG) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn more_distortion_scores_lower() {
        let img = checker(32, 0.2, 0.8);
        let slight = checker(32, 0.25, 0.75);
        let strong = checker(32, 0.45, 0.55);
        let inverted = checker(32, 0.8, 0.2);
        let (s1, s2, s3) = (
            ssim(&img, &slight, BG),
            ssim(&img, &strong, BG),
            ssim(&img, &inverted, BG),
        );
        assert!(s1 < 1.0 && s1 > s2 && s2 > s3, "{s1} {s2} {s3}");
        assert!(s3 < 0.0, "an inverted pattern anti-correlates: {s3}");
    }

    #[test]
    fn a_recolour_with_equal_structure_is_seen() {
        let mut red = Image::new(16, Vec3::new(0.8, 0.1, 0.1));
        let mut green = Image::new(16, Vec3::new(0.1, 0.8, 0.1));
        red.pixels[0] = Vec3::ZERO;
        green.pixels[0] = Vec3::ZERO;
        assert!(ssim(&red, &green, BG) < 0.9);
    }

    #[test]
    fn background_does_not_dilute_the_score() {
        let background = Vec3::splat(0.5);
        let mut a = Image::new(64, background);
        let mut b = Image::new(64, background);
        for y in 0..8 {
            for x in 0..8 {
                a.pixels[y * 64 + x] = Vec3::new(0.9, 0.9, 0.9);
                b.pixels[y * 64 + x] = Vec3::new(0.9, 0.2, 0.9);
            }
        }
        let with_mask = ssim(&a, &b, background);
        let whole = ssim(&a, &b, Vec3::splat(-1.0));
        assert!(with_mask < whole, "{with_mask} vs {whole}");
        assert!(with_mask < 0.8, "{with_mask}");
        assert_eq!(
            ssim(
                &Image::new(4, background),
                &Image::new(4, background),
                background
            ),
            1.0
        );
    }

    #[test]
    fn tiny_images_stay_defined() {
        let a = checker(1, 0.3, 0.3);
        let b = checker(1, 0.6, 0.6);
        let s = ssim(&a, &b, BG);
        assert!(s.is_finite() && s < 1.0);
    }
}
