//! Texture atlasing (Azim et al. 2014, section 7 "Texture Management"): every aggregate is drawn
//! with one draw call, so it references exactly one material and one texture of at most 128 KB.
//!
//! The paper atlases "charted, combined" textures (its section 4.1 CDN step) so that wrapping
//! coordinates and partly used images are handled before packing. Here both steps are one
//! pipeline: [`build_atlas`] charts the used texture regions, packs them, bakes them and encodes
//! the result under a byte budget.
//!
//! # Layout
//!
//! - `lib.rs`: options, report, errors and the [`build_atlas`] pipeline.
//! - `chart.rs`: stage 1. UV islands (triangles connected through shared vertex indices) of
//!   each textured submesh, mapped through KHR_texture_transform into the source's texel space;
//!   each island's chart is its bounding box widened to whole texels; overlapping charts of one
//!   material merge. Untextured materials (and submeshes without UVs) share one flat patch per
//!   material.
//! - `pack.rs`: stage 2. [`Layout`] (rectangles plus gutters, with [`Layout::validate`]) and the
//!   search for the largest global texel scale <= 1 at which the charts fit; placement is the
//!   `crunch` packer's.
//! - `bake.rs`: stage 3. Decoding, wrap-aware bilinear sampling in linear light, base colour
//!   factors, alpha modes, gutters.
//! - `remap.rs`: stage 4. The new UVs.
//! - `encode.rs`: stage 5. PNG or JPEG under the byte budget.
//!
//! # Choices
//!
//! - **Texel space.** A chart lives in its source's texel space (`uv * size`, after the UV
//!   transform), and its box is widened to whole texels, so at scale 1 every atlas texel centre
//!   maps onto a source texel centre and the atlas holds the source texels exactly. The chart box
//!   maps onto its rectangle edge to edge; the same affine map drives baking (atlas texel centre
//!   -> source point) and UV remapping (source point -> atlas), so they agree by construction.
//! - **Wrapping.** A chart is the source *sampled with its wrap mode* over the chart's box, which
//!   may span several tiles or lie outside [0, 1]; this is the same as shifting the island by
//!   whole tiles. A chart spans at most [`MAX_TILES_PER_AXIS`] source widths of texels per axis;
//!   a chart that tiles further keeps that many texels and is sampled at lower density.
//! - **Scale.** One global texel scale for every chart (textured and patch): the largest <= 1
//!   at which the crunch packer places all padded rectangles in `max_side` squared, found by
//!   shrinking 10% at a time from the area bound and then bisecting the last step. The packer
//!   spreads rectangles over the square it is given, so the square is then tightened from the
//!   area bound up in 5% steps. Below scale 1, each atlas texel is a trilinear sample of the
//!   source's mip chain (built in linear light), so that downscaled detail of any frequency
//!   is averaged rather than aliased.
//! - **Colour.** glTF base colour textures are sRGB and the factor is linear: texels are decoded
//!   to linear light, filtered, multiplied by the factor and encoded back to sRGB. Alpha is
//!   linear. A `Mask` material's alpha is baked as 0 or 1 against its own cut-off, so masks with
//!   different cut-offs survive one output cut-off of 0.5.
//! - **Gutters.** `gutter` texels around every chart repeat the chart's edge texels, so bilinear
//!   filtering (and the first mip levels) at chart borders do not bleed in neighbours.
//! - **Budget.** The atlas is cropped to the packed extent. An opaque atlas is a (fast) PNG
//!   when that fits `max_bytes` and is no larger than a quality-80 JPEG (flat patches and small
//!   atlases stay exact), otherwise the JPEG at the highest quality of a fixed ladder that fits;
//!   with `lossless`, a PNG that fits is always kept. An atlas whose alpha matters stays PNG. When nothing fits, the side shrinks by the square root of the overshoot (bytes
//!   grow with the texel count) and the charts are re-packed and re-baked, never resampled from
//!   the baked atlas, so gutters stay intact.
//!
//! # Limits
//!
//! - Charts are axis-aligned UV boxes, never rotated: a diagonal island wastes its box's corners.
//! - Filtering is not alpha-premultiplied: below scale 1, colour of transparent texels can bleed
//!   into the edges of `Blend` cut-outs.
//! - The level of detail follows the larger of a chart's two steps, as a GPU's isotropic
//!   filtering does: a chart shrunk much more along one axis than the other is blurred along
//!   the other. A shrunk chart's border texels also average source texels just outside its
//!   box (at most the footprint of one atlas texel).
//! - Gutters guard bilinear filtering and the first mip levels only; deep mips and JPEG's 8x8
//!   blocks (and chroma subsampling) can still mix neighbouring charts slightly.
//! - crunch's packing time grows about quadratically with the chart count (one to two seconds
//!   per packing of 3,000 charts), and a build packs a dozen or so times; an aggregate with
//!   thousands of islands would want islands grouped into fewer charts first.

mod bake;
mod cache;
mod chart;
mod encode;
mod pack;
mod remap;

use glam::Vec4;
use horizon_mesh::model::{
    AlphaMode, InstancedMesh, InvalidMesh, Material, Submesh, Texture, TextureRef, Wrap,
};

pub use cache::{DecodedTexture, TextureCache};
pub use pack::{pack_rects, Layout, LayoutError, PackedRect, MAXRECTS_MAX_CHARTS};

/// Most source widths (or heights) of texels a chart keeps along one axis; a chart tiling more
/// often than this is sampled at a lower density instead of filling the atlas with repeats.
pub const MAX_TILES_PER_AXIS: f64 = 4.0;

/// Builds the atlased copy of `mesh`: the same submeshes (positions, normals, colours, indices,
/// order) and instances, with new UVs, one material and one texture of at most
/// `options.max_bytes` bytes.
pub fn build_atlas(
    mesh: &InstancedMesh,
    options: &AtlasOptions,
) -> Result<(InstancedMesh, AtlasReport), AtlasError> {
    build_atlas_with(mesh, options, &TextureCache::new(0))
}

/// [`build_atlas`], decoding source textures through `cache` (which may already hold them,
/// from earlier atlases of the same world).
pub fn build_atlas_with(
    mesh: &InstancedMesh,
    options: &AtlasOptions,
    cache: &TextureCache,
) -> Result<(InstancedMesh, AtlasReport), AtlasError> {
    // Refuse broken input before touching any pixel.
    mesh.validate()?;
    // Decode every texture a used material references, once.
    let sources = bake::decode_sources(mesh, cache)?;
    // Stage 1: chart the used texture regions and the flat-colour patches.
    let charting = chart::chart_mesh(mesh, &sources, options);
    // The one output material decides whether alpha must survive encoding.
    let material = merge_materials(mesh);
    let opaque = material.alpha_mode == AlphaMode::Opaque;
    // Stages 2, 3 and 5: pack at the largest scale, bake, encode; shrink the side until the
    // encoded atlas fits the budget.
    let mut side = options.max_side;
    let (layout, scale, encoded) = loop {
        // Stage 2: scale and pack.
        let (layout, scale) =
            pack::pack_charts(&charting.charts, options.gutter, side).map_err(|e| match e {
                // Charts that fit the full side but not a shrunk one: the budget is the cause.
                AtlasError::DoesNotFit { .. } if side < options.max_side => {
                    AtlasError::OverBudget {
                        max_bytes: options.max_bytes,
                    }
                }
                e => e,
            })?;
        // Stage 3: bake.
        let image = bake::bake_atlas(&charting.charts, &layout, &sources, opaque);
        // Stage 5: encode under the byte budget.
        let smallest =
            match encode::encode_within(&image, opaque, options.max_bytes, options.lossless)? {
                Ok(encoded) => break (layout, scale, encoded),
                Err(smallest) => smallest,
            };
        side = encode::next_side(&layout, smallest, options.max_bytes).ok_or(
            AtlasError::OverBudget {
                max_bytes: options.max_bytes,
            },
        )?;
    };
    // Stage 4: remap every vertex's UV into the atlas.
    let submeshes = remap::remap_uvs(mesh, &charting, &layout);
    // Assemble the output mesh around the one material and the one texture.
    let report = AtlasReport {
        charts: charting.charts.len(),
        patches: charting.charts.iter().filter(|c| c.is_patch()).count(),
        width: layout.width,
        height: layout.height,
        bytes: encoded.bytes.len(),
        texel_scale: scale,
        mime_type: encoded.mime_type.to_string(),
        jpeg_quality: encoded.jpeg_quality,
    };
    let out = assemble(mesh, submeshes, material, encoded, &layout);
    debug_assert!(out.validate().is_ok(), "atlas output must be a valid mesh");
    Ok((out, report))
}

/// Knobs of [`build_atlas`].
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasOptions {
    /// Budget for the encoded texture in bytes; the paper's limit is 128 KB per aggregate.
    pub max_bytes: usize,
    /// Largest atlas side in pixels. The caller lowers it for aggregates that are small on
    /// screen.
    pub max_side: u32,
    /// Texels of padding around each chart, filled with the chart's edge texels.
    pub gutter: u32,
    /// Side in texels (at scale 1) of the flat colour patch of an untextured material.
    pub patch_side: u32,
    /// Keep a lossless PNG whenever it fits the budget, even when a JPEG would be smaller
    /// (exact texels). Default false: the smaller encoding, since every byte is downloaded.
    pub lossless: bool,
}

impl Default for AtlasOptions {
    fn default() -> Self {
        Self {
            max_bytes: 128 * 1024,
            max_side: 1024,
            gutter: 2,
            patch_side: 4,
            lossless: false,
        }
    }
}

/// What [`build_atlas`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasReport {
    /// Charts packed, patches included.
    pub charts: usize,
    /// Of those, flat colour patches.
    pub patches: usize,
    /// Atlas width in pixels.
    pub width: u32,
    /// Atlas height in pixels.
    pub height: u32,
    /// Encoded texture size in bytes.
    pub bytes: usize,
    /// Global texel scale: atlas texels per source texel (1 = full resolution).
    pub texel_scale: f32,
    /// `image/png` or `image/jpeg`.
    pub mime_type: String,
    /// The JPEG quality used, for a JPEG atlas.
    pub jpeg_quality: Option<u8>,
}

/// Why no atlas could be built.
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
    /// The input mesh breaks one of its invariants.
    #[error("invalid input mesh: {0}")]
    InvalidMesh(#[from] InvalidMesh),
    /// A referenced texture could not be decoded.
    #[error("texture {texture} does not decode: {source}")]
    Decode {
        /// Index of the texture in the input mesh.
        texture: usize,
        /// The decoder's complaint.
        source: image::ImageError,
    },
    /// Even one texel per chart does not pack into the allowed side.
    #[error("{charts} charts do not fit a {side}x{side} atlas even at one texel each")]
    DoesNotFit {
        /// Number of charts.
        charts: usize,
        /// The side tried.
        side: u32,
    },
    /// The packer produced an invalid layout (a bug, reported rather than drawn).
    #[error("packed layout is invalid: {0}")]
    Layout(#[from] LayoutError),
    /// No side and quality bring the encoded atlas under the budget.
    #[error("the atlas cannot be encoded in {max_bytes} bytes")]
    OverBudget {
        /// The budget.
        max_bytes: usize,
    },
    /// The image encoder failed.
    #[error("atlas encoding failed: {0}")]
    Encode(image::ImageError),
}

/// The material of a submesh, with `None` meaning the glTF default material.
fn material_of<'a>(mesh: &'a InstancedMesh, sub: &Submesh, default: &'a Material) -> &'a Material {
    sub.material
        .and_then(|m| mesh.materials.get(m))
        .unwrap_or(default)
}

/// The one output material: factors baked (white), no UV transform, alpha mode strong enough for
/// every input (Blend > Mask > Opaque), double-sided if any input is, and the mean metallic and
/// roughness over the submeshes' materials (one vote per submesh).
fn merge_materials(mesh: &InstancedMesh) -> Material {
    let default = Material::default();
    let used: Vec<&Material> = mesh
        .submeshes
        .iter()
        .map(|s| material_of(mesh, s, &default))
        .collect();
    let n = used.len().max(1) as f32;
    let blend = used.iter().any(|m| m.alpha_mode == AlphaMode::Blend);
    let mask = used
        .iter()
        .any(|m| matches!(m.alpha_mode, AlphaMode::Mask { .. }));
    let alpha_mode = if blend {
        AlphaMode::Blend
    } else if mask {
        AlphaMode::Mask { cutoff: 0.5 }
    } else {
        AlphaMode::Opaque
    };
    Material {
        name: Some("atlas".to_string()),
        base_color_factor: Vec4::ONE,
        base_color_texture: Some(TextureRef {
            texture: 0,
            transform: None,
        }),
        metallic_factor: if used.is_empty() {
            0.0
        } else {
            used.iter().map(|m| m.metallic_factor).sum::<f32>() / n
        },
        roughness_factor: if used.is_empty() {
            1.0
        } else {
            used.iter().map(|m| m.roughness_factor).sum::<f32>() / n
        },
        alpha_mode,
        double_sided: used.iter().any(|m| m.double_sided),
    }
}

/// Puts the output mesh together.
fn assemble(
    mesh: &InstancedMesh,
    submeshes: Vec<Submesh>,
    material: Material,
    encoded: encode::Encoded,
    layout: &Layout,
) -> InstancedMesh {
    InstancedMesh {
        submeshes,
        instances: mesh.instances.clone(),
        materials: vec![material],
        textures: vec![Texture {
            bytes: encoded.bytes,
            mime_type: encoded.mime_type.to_string(),
            size: (layout.width, layout.height),
            wrap_u: Wrap::ClampToEdge,
            wrap_v: Wrap::ClampToEdge,
        }],
    }
}
