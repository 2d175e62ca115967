//! Decoded textures and how a texel is fetched at an unwrapped integer coordinate (glTF's
//! sampler wrap modes, nearest filtering).

use horizon_mesh::{Texture, Wrap};
use image::DynamicImage;

use crate::DescriptorError;

/// A decoded texture kept in the decoder's own 8-bit layout (RGB or RGBA), so that a JPEG is
/// not expanded to RGBA only to be point-sampled.
#[derive(Debug)]
pub(super) struct Texels {
    /// Width in texels; at least 1.
    width: i64,
    /// Height in texels; at least 1.
    height: i64,
    /// Bytes per texel: 3 or 4.
    channels: usize,
    /// Row-major texels, row 0 at the top (glTF's v = 0).
    data: Vec<u8>,
}

impl Texels {
    /// Decodes `texture` (index `index` in the mesh, for the error). The texture's wrap modes
    /// are applied at [`Texels::fetch`], so textures with the same bytes share one decode.
    pub(super) fn decode(index: usize, texture: &Texture) -> Result<Self, DescriptorError> {
        let fail = |message: String| DescriptorError::Texture {
            texture: index,
            message,
        };
        let format = image::ImageFormat::from_mime_type(&texture.mime_type)
            .or_else(|| image::guess_format(&texture.bytes).ok())
            .unwrap_or(image::ImageFormat::Png);
        let image = image::load_from_memory_with_format(&texture.bytes, format)
            .map_err(|e| fail(e.to_string()))?;
        let (width, height) = (image.width(), image.height());
        if width == 0 || height == 0 {
            return Err(fail("the image has no pixels".into()));
        }
        let (channels, data) = match image {
            DynamicImage::ImageRgb8(buffer) => (3, buffer.into_raw()),
            DynamicImage::ImageRgba8(buffer) => (4, buffer.into_raw()),
            other => (4, other.to_rgba8().into_raw()),
        };
        Ok(Self {
            width: i64::from(width),
            height: i64::from(height),
            channels,
            data,
        })
    }

    /// Width and height in texels.
    pub(super) fn size(&self) -> (f64, f64) {
        (self.width as f64, self.height as f64)
    }

    /// The RGBA texel at unwrapped texel coordinate `(x, y)`, folded back by the wrap modes
    /// along U and V.
    pub(super) fn fetch(&self, x: i64, y: i64, modes: [Wrap; 2]) -> [u8; 4] {
        let col = wrap(x, self.width, modes[0]);
        let row = wrap(y, self.height, modes[1]);
        let i = (row * self.width + col) as usize * self.channels;
        match self.data.get(i..i + self.channels) {
            Some(&[r, g, b]) => [r, g, b, 255],
            Some(&[r, g, b, a]) => [r, g, b, a],
            _ => [0, 0, 0, 255],
        }
    }
}

/// Folds an unwrapped texel index into `0..size`.
fn wrap(i: i64, size: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => i.rem_euclid(size),
        Wrap::MirroredRepeat => {
            // Period 2 * size; the second half runs backwards.
            let m = i.rem_euclid(2 * size);
            if m < size {
                m
            } else {
                2 * size - 1 - m
            }
        }
        Wrap::ClampToEdge => i.clamp(0, size - 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes_fold_indices() {
        assert_eq!(wrap(5, 4, Wrap::Repeat), 1);
        assert_eq!(wrap(-1, 4, Wrap::Repeat), 3);
        // Mirrored: 0 1 2 3 | 3 2 1 0 | 0 1 ...
        assert_eq!(wrap(4, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(7, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(-1, 4, Wrap::MirroredRepeat), 0);
        assert_eq!(wrap(-5, 4, Wrap::MirroredRepeat), 3);
        assert_eq!(wrap(9, 4, Wrap::ClampToEdge), 3);
        assert_eq!(wrap(i64::MIN, 4, Wrap::ClampToEdge), 0);
        assert_eq!(wrap(i64::MAX, 4, Wrap::Repeat), i64::MAX % 4);
    }
}
