//! Checking encoded images at import: the format from the magic bytes, the size from the
//! header, and (with [`ImageCheck::Decode`]) one full decode whose pixels are dropped.

use std::io::Cursor;

use super::{ImageCheck, Limits, TEXTURE_PIXELS, TEXTURE_SIDE};
use crate::error::ImportError;
use crate::model::{Texture, Wrap};

/// Builds a [`Texture`] from encoded bytes after checking them. `declared_mime` is what the
/// file says; the magic bytes win when they disagree, since renderers sniff too. The
/// image's pixels are taken from `pixel_budget`.
pub(crate) fn checked_texture(
    name: &str,
    bytes: Vec<u8>,
    declared_mime: Option<&str>,
    wrap: (Wrap, Wrap),
    check: ImageCheck,
    max_side: u64,
    pixel_budget: &mut u64,
) -> Result<Texture, ImportError> {
    let fail = |reason: String| ImportError::ImageDecode {
        image: name.into(),
        reason,
    };
    let format = image::guess_format(&bytes).map_err(|e| fail(e.to_string()))?;
    let mime_type = match format {
        image::ImageFormat::Png => "image/png",
        image::ImageFormat::Jpeg => "image/jpeg",
        other => {
            return Err(ImportError::Unsupported(format!(
                "image {name} is {other:?} (declared {}); only PNG and JPEG are read",
                declared_mime.unwrap_or("no MIME type")
            )))
        }
    };
    let size = image::ImageReader::with_format(Cursor::new(&bytes), format)
        .into_dimensions()
        .map_err(|e| fail(e.to_string()))?;
    // Check the side and count the pixels against the budget before any decode allocates them.
    Limits::check(TEXTURE_SIDE, u64::from(size.0.max(size.1)), max_side)?;
    let pixels = u64::from(size.0) * u64::from(size.1);
    *pixel_budget = pixel_budget
        .checked_sub(pixels)
        .ok_or(ImportError::LimitExceeded {
            what: TEXTURE_PIXELS,
            value: pixels,
            limit: *pixel_budget,
        })?;
    if check == ImageCheck::Decode {
        image::ImageReader::with_format(Cursor::new(&bytes), format)
            .decode()
            .map_err(|e| fail(e.to_string()))?;
    }
    if size.0 == 0 || size.1 == 0 {
        return Err(fail("it has no pixels".into()));
    }
    Ok(Texture {
        bytes,
        mime_type: mime_type.into(),
        size,
        wrap_u: wrap.0,
        wrap_v: wrap.1,
    })
}
