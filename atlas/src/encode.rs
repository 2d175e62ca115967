//! Stage 5: encode under the byte budget (the paper's 128 KB per aggregate texture).
//!
//! An opaque atlas is a lossless PNG when that is no larger than a JPEG at the top quality and
//! fits (flat patches and small atlases stay exact), else a JPEG at the highest quality of
//! [`JPEG_QUALITIES`] that fits; an atlas whose alpha matters stays PNG. When nothing fits,
//! the caller re-packs at [`next_side`].

use image::codecs::jpeg::JpegEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder, RgbaImage};

use crate::error::AtlasError;
use crate::layout::Layout;

/// JPEG qualities tried, best first. The top is 80, not 90: every atlas is downloaded, and 90
/// costs markedly more bytes per atlas for detail nobody sees on an aggregate seen from afar.
/// Below 30 blocking shows on every texture; the side shrinks instead.
const JPEG_QUALITIES: [u8; 5] = [80, 70, 60, 45, 30];

/// Aim at the side the square-root estimate predicts fits, without margin: downscaled charts
/// are smoother and compress better per texel, so the estimate already errs on the small side.
const SIDE_MARGIN: f64 = 1.0;

/// Each retry shrinks the side at least this much (to 90 percent), so retries end quickly.
const MIN_SIDE_STEP: f64 = 0.9;

/// Each retry shrinks the side at most this much (to 60 percent), so a bad estimate cannot skip
/// far past the largest side that fits.
const MAX_SIDE_STEP: f64 = 0.6;

/// An encoded atlas.
#[derive(Clone, Debug)]
pub(crate) struct Encoded {
    /// The PNG or JPEG bytes.
    pub bytes: Vec<u8>,
    /// `image/png` or `image/jpeg`.
    pub mime_type: &'static str,
    /// The JPEG quality, for a JPEG.
    pub jpeg_quality: Option<u8>,
}

/// The best encoding of `image` within `max_bytes`, or `Err(bytes)` with the smallest encoding
/// tried when none fits at this size.
pub(crate) fn encode_within(
    image: &RgbaImage,
    opaque: bool,
    max_bytes: usize,
    lossless: bool,
) -> Result<Result<Encoded, usize>, AtlasError> {
    let png = encode_png(image, opaque)?;
    if !opaque || (lossless && png.len() <= max_bytes) {
        if png.len() <= max_bytes {
            return Ok(Ok(Encoded {
                bytes: png,
                mime_type: "image/png",
                jpeg_quality: None,
            }));
        }
        return Ok(Err(png.len()));
    }
    // Opaque: the lossless PNG when it is no larger than a top-quality JPEG (flat patches and
    // small atlases stay exact), else the best JPEG that fits. Every byte is downloaded.
    let rgb = rgb_bytes(image);
    let top = encode_jpeg(&rgb, image.width(), image.height(), JPEG_QUALITIES[0])?;
    if png.len() <= max_bytes && png.len() <= top.len() {
        return Ok(Ok(Encoded {
            bytes: png,
            mime_type: "image/png",
            jpeg_quality: None,
        }));
    }
    if top.len() <= max_bytes {
        return Ok(Ok(Encoded {
            bytes: top,
            mime_type: "image/jpeg",
            jpeg_quality: Some(JPEG_QUALITIES[0]),
        }));
    }
    // Try the lowest quality first: when even that does not fit, shrink at once.
    let mut best = Err(png.len());
    for &quality in JPEG_QUALITIES.iter().rev() {
        let jpeg = encode_jpeg(&rgb, image.width(), image.height(), quality)?;
        if jpeg.len() > max_bytes {
            if best.is_err() {
                best = Err(jpeg.len().min(png.len()));
            }
            break;
        }
        best = Ok(Encoded {
            bytes: jpeg,
            mime_type: "image/jpeg",
            jpeg_quality: Some(quality),
        });
    }
    Ok(best)
}

/// The side to re-pack at after `layout` encoded to `bytes` over the budget, or `None` at one
/// texel. Encoded size is roughly proportional to the texel count, so the side scales by the
/// square root of the overshoot, with a margin of [`SIDE_MARGIN`], and by at least
/// [`MIN_SIDE_STEP`] and at most [`MAX_SIDE_STEP`] per retry.
pub(crate) fn next_side(layout: &Layout, bytes: usize, max_bytes: usize) -> Option<u32> {
    let side = layout.width.max(layout.height);
    let ratio = (max_bytes as f64 / bytes.max(1) as f64).sqrt() * SIDE_MARGIN;
    let step = ratio.clamp(MAX_SIDE_STEP, MIN_SIDE_STEP);
    (side > 1).then(|| ((f64::from(side) * step) as u32).clamp(1, side - 1))
}

/// PNG, RGB when opaque (a quarter smaller) and RGBA otherwise. Fast deflate: the best
/// setting costs about as much time as the rest of an aggregate build for a few percent of
/// bytes, and an opaque atlas that misses the budget falls through to JPEG anyway.
fn encode_png(image: &RgbaImage, opaque: bool) -> Result<Vec<u8>, AtlasError> {
    let mut out = Vec::new();
    let encoder =
        PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Adaptive);
    let result = if opaque {
        let rgb = rgb_bytes(image);
        encoder.write_image(&rgb, image.width(), image.height(), ExtendedColorType::Rgb8)
    } else {
        encoder.write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            ExtendedColorType::Rgba8,
        )
    };
    result.map_err(AtlasError::Encode)?;
    Ok(out)
}

/// Baseline JPEG of RGB bytes: `image`'s encoder, 4:4:4 with the standard Huffman tables.
///
/// Neither optimised Huffman tables nor 4:2:0 chroma is used. Optimised tables (the
/// `jpeg-encoder` crate, 0.7.1) make atlases a few percent smaller at identical pixels in
/// libjpeg and `jpeg-decoder`, but zune-jpeg 0.5.15 (`image`'s decoder, so most Rust engines')
/// decodes some of them wrongly. 4:2:0 chroma is smaller still but halves the colour
/// resolution of charts a few texels wide.
fn encode_jpeg(rgb: &[u8], width: u32, height: u32, quality: u8) -> Result<Vec<u8>, AtlasError> {
    let mut out = Vec::new();
    JpegEncoder::new_with_quality(&mut out, quality)
        .encode(rgb, width, height, ExtendedColorType::Rgb8)
        .map_err(AtlasError::Encode)?;
    Ok(out)
}

/// The RGB channels of an RGBA image.
fn rgb_bytes(image: &RgbaImage) -> Vec<u8> {
    image
        .as_raw()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect()
}
