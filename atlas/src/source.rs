//! The source textures of one atlas build: every texture a used material references, decoded
//! (through the shared [`TextureCache`]) and paired with the wrap modes it is sampled with.

use std::sync::Arc;

use horizon_mesh::model::{InstancedMesh, Wrap};
use image::RgbaImage;
use rayon::prelude::*;

use crate::cache::{DecodedTexture, TextureCache};
use crate::error::AtlasError;

/// A decoded texture with the wrap modes it is sampled with.
#[derive(Clone, Debug)]
pub(crate) struct Source {
    /// RGBA8, sRGB colour and linear alpha, with its mip chain (shared through the
    /// [`TextureCache`]).
    pub texture: Arc<DecodedTexture>,
    /// Wrap modes along U and V.
    pub wrap: [Wrap; 2],
}

impl Source {
    /// Level 0: the image itself.
    pub fn image(&self) -> &RgbaImage {
        &self.texture.image
    }
}

/// Decodes every texture referenced by a material that some submesh uses; the others stay
/// `None`. A texture that decodes to no pixels also stays `None` and its materials fall back to
/// flat patches.
pub(crate) fn decode_sources(
    mesh: &InstancedMesh,
    cache: &TextureCache,
) -> Result<Vec<Option<Source>>, AtlasError> {
    let mut used = vec![false; mesh.textures.len()];
    for sub in &mesh.submeshes {
        let tref = sub
            .material
            .and_then(|m| mesh.materials.get(m))
            .and_then(|m| m.base_color_texture);
        if let Some(t) = tref {
            used[t.texture] = true;
        }
    }
    // In parallel: an upper aggregate decodes thousands of textures, and the top of the tree
    // has too few aggregates to keep the cores busy by itself.
    mesh.textures
        .par_iter()
        .zip(used)
        .enumerate()
        .map(|(texture, (tex, used))| {
            if !used {
                return Ok(None);
            }
            let decoded = cache
                .decode(tex)
                .map_err(|source| AtlasError::Decode { texture, source })?;
            let nonempty = decoded.image.width() > 0 && decoded.image.height() > 0;
            Ok(nonempty.then_some(Source {
                texture: decoded,
                wrap: [tex.wrap_u, tex.wrap_v],
            }))
        })
        .collect()
}
