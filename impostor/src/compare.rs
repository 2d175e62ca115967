//! How far one render is from another: PSNR, SSIM (Wang, Bovik, Sheikh and Simoncelli 2004:
//! an 11 x 11 Gaussian window of sigma 1.5 on luma, K1 = 0.01, K2 = 0.03), the share of pixels
//! off by more than 16 levels, and holes: where the reference covers a pixel with geometry and
//! the other shows sky.

use crate::frame::Frame;

/// How a test frame differs from a reference frame of the same size.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Comparison {
    /// Peak signal-to-noise ratio over the RGB channels, dB; [`IDENTICAL_PSNR`] for identical
    /// frames.
    pub psnr: f64,
    /// Mean SSIM of luma, at most 1.
    pub ssim: f64,
    /// Share of pixels where some channel differs by more than 16 levels.
    pub off16: f64,
    /// Share of the image the reference covers and the test leaves to the sky: the sum over
    /// pixels of max(0, reference coverage - test coverage), over the pixel count.
    pub holes: f64,
}

/// PSNR reported for identical frames (where the ratio is infinite).
pub const IDENTICAL_PSNR: f64 = 100.0;

/// Compares `test` with `reference`. Panics if their sizes differ (a caller's bug).
pub fn compare(reference: &Frame, test: &Frame) -> Comparison {
    assert_eq!(
        (reference.width, reference.height),
        (test.width, test.height),
        "frames of different sizes"
    );
    let n = reference.pixels().max(1) as f64;
    let mut squared = 0.0f64;
    let mut off = 0usize;
    for (a, b) in reference.color.iter().zip(&test.color) {
        let mut worst = 0;
        for c in 0..3 {
            let d = i32::from(a[c]) - i32::from(b[c]);
            squared += f64::from(d * d);
            worst = worst.max(d.abs());
        }
        if worst > 16 {
            off += 1;
        }
    }
    let mse = squared / (3.0 * n);
    let psnr = if mse == 0.0 {
        IDENTICAL_PSNR
    } else {
        (10.0 * (255.0f64 * 255.0 / mse).log10()).min(IDENTICAL_PSNR)
    };
    let holes = reference
        .coverage
        .iter()
        .zip(&test.coverage)
        .map(|(&r, &t)| f64::from((r - t).max(0.0)))
        .sum::<f64>()
        / n;
    Comparison {
        psnr,
        ssim: ssim(reference, test),
        off16: off as f64 / n,
        holes,
    }
}

/// Mean SSIM of the two frames' luma.
fn ssim(a: &Frame, b: &Frame) -> f64 {
    let (w, h) = (a.width as usize, a.height as usize);
    let luma = |f: &Frame| -> Vec<f64> {
        f.color
            .iter()
            .map(|c| 0.299 * f64::from(c[0]) + 0.587 * f64::from(c[1]) + 0.114 * f64::from(c[2]))
            .collect()
    };
    let (x, y) = (luma(a), luma(b));
    let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
    let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
    let xy: Vec<f64> = x.iter().zip(&y).map(|(p, q)| p * q).collect();
    let [mx, my, sxx, syy, sxy] = [&x, &y, &xx, &yy, &xy].map(|v| blur(v, w, h));
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let mut sum = 0.0;
    for i in 0..w * h {
        let (mx, my) = (mx[i], my[i]);
        let vx = sxx[i] - mx * mx;
        let vy = syy[i] - my * my;
        let cov = sxy[i] - mx * my;
        sum +=
            ((2.0 * mx * my + c1) * (2.0 * cov + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2));
    }
    sum / (w * h).max(1) as f64
}

/// A separable Gaussian blur (sigma 1.5, radius 5), renormalised where the window leaves the
/// image.
fn blur(v: &[f64], w: usize, h: usize) -> Vec<f64> {
    const R: isize = 5;
    let kernel: Vec<f64> = (-R..=R)
        .map(|d| (-((d * d) as f64) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let pass = |src: &[f64], along_x: bool| -> Vec<f64> {
        let mut out = vec![0.0; w * h];
        for yy in 0..h {
            for xx in 0..w {
                let (mut s, mut k) = (0.0, 0.0);
                for d in -R..=R {
                    let (px, py) = if along_x {
                        (xx as isize + d, yy as isize)
                    } else {
                        (xx as isize, yy as isize + d)
                    };
                    if px < 0 || py < 0 || px >= w as isize || py >= h as isize {
                        continue;
                    }
                    let weight = kernel[(d + R) as usize];
                    s += weight * src[py as usize * w + px as usize];
                    k += weight;
                }
                out[yy * w + xx] = s / k;
            }
        }
        out
    };
    pass(&pass(v, true), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: u32, h: u32, f: impl Fn(u32, u32) -> ([u8; 3], f32)) -> Frame {
        let mut out = Frame {
            width: w,
            height: h,
            color: Vec::new(),
            coverage: Vec::new(),
            depth: Vec::new(),
        };
        for y in 0..h {
            for x in 0..w {
                let (c, cov) = f(x, y);
                out.color.push(c);
                out.coverage.push(cov);
                out.depth.push(if cov > 0.0 { 1.0 } else { f32::INFINITY });
            }
        }
        out.validate().expect("a valid frame");
        out
    }

    fn pattern(x: u32, y: u32) -> ([u8; 3], f32) {
        let v = ((x * 37 + y * 11) % 200) as u8;
        ([v, v / 2, 255 - v], 1.0)
    }

    #[test]
    fn identical_frames_score_perfectly() {
        let a = frame(40, 30, pattern);
        let c = compare(&a, &a);
        assert_eq!(c.psnr, IDENTICAL_PSNR);
        assert!((c.ssim - 1.0).abs() < 1e-12);
        assert_eq!((c.off16, c.holes), (0.0, 0.0));
    }

    #[test]
    fn a_uniform_error_gives_the_textbook_psnr() {
        // Every channel off by 10: MSE 100, PSNR = 10 log10(255^2 / 100) = 28.13 dB.
        let a = frame(16, 16, |_, _| ([100, 100, 100], 1.0));
        let b = frame(16, 16, |_, _| ([110, 90, 110], 1.0));
        let c = compare(&a, &b);
        assert!((c.psnr - 28.1308).abs() < 1e-3, "{}", c.psnr);
        assert_eq!(c.off16, 0.0);
    }

    #[test]
    fn a_missing_quarter_is_a_quarter_of_holes_and_lowers_ssim() {
        let a = frame(40, 40, pattern);
        let b = frame(40, 40, |x, y| {
            if x < 20 && y < 20 {
                ([180, 200, 225], 0.0)
            } else {
                pattern(x, y)
            }
        });
        let c = compare(&a, &b);
        assert!((c.holes - 0.25).abs() < 1e-9, "{}", c.holes);
        assert!(c.ssim < 0.9, "{}", c.ssim);
        assert!(c.off16 > 0.2 && c.off16 <= 0.25, "{}", c.off16);
        // Holes count only what the reference covers.
        assert_eq!(compare(&b, &a).holes, 0.0);
    }
}
