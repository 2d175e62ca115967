//! A rendered image: sRGB colour, and for every pixel how much of it geometry covers and how
//! far the nearest surface is.

/// One rendered frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// sRGB colour, row-major from the top left.
    pub color: Vec<[u8; 3]>,
    /// Share of the pixel's samples that hit geometry, 0 to 1 (the rest see the sky).
    pub coverage: Vec<f32>,
    /// Distance along the ray to the nearest hit among the pixel's samples; infinity where
    /// none hit.
    pub depth: Vec<f32>,
}

impl Frame {
    /// The colour as an image.
    pub fn to_image(&self) -> image::RgbImage {
        let raw = self.color.iter().flatten().copied().collect();
        image::RgbImage::from_raw(self.width, self.height, raw).unwrap_or_default()
    }

    /// Writes the colour as a PNG.
    pub fn save_png(&self, path: &std::path::Path) -> Result<(), image::ImageError> {
        self.to_image()
            .save_with_format(path, image::ImageFormat::Png)
    }

    /// Share of the image covered by geometry.
    pub fn covered(&self) -> f64 {
        self.coverage.iter().map(|&c| f64::from(c)).sum::<f64>() / self.pixels().max(1) as f64
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Checks the buffers' sizes and values: one entry per pixel each, coverage in [0, 1],
    /// depth positive (or infinite exactly where nothing is covered).
    pub fn validate(&self) -> Result<(), String> {
        let n = self.pixels();
        if self.color.len() != n || self.coverage.len() != n || self.depth.len() != n {
            return Err(format!(
                "frame {}x{} has {} colours, {} coverages and {} depths",
                self.width,
                self.height,
                self.color.len(),
                self.coverage.len(),
                self.depth.len()
            ));
        }
        for (i, (&c, &d)) in self.coverage.iter().zip(&self.depth).enumerate() {
            if !(0.0..=1.0).contains(&c) {
                return Err(format!("pixel {i}: coverage {c} is not in [0, 1]"));
            }
            if (c > 0.0) != d.is_finite() || d.is_nan() || d < 0.0 {
                return Err(format!("pixel {i}: depth {d} does not match coverage {c}"));
            }
        }
        Ok(())
    }
}
