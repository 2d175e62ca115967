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
//! - `lib.rs`: the [`build_atlas`] pipeline, its report, and the public re-exports.
//! - `options.rs`: [`AtlasOptions`] (`max_bytes`, `max_side`, `gutter`, `patch_side`,
//!   `lossless`) and [`MAX_TILES_PER_AXIS`].
//! - `error.rs`: [`AtlasError`].
//! - `material.rs`: the material a submesh draws with, and the one merged output material.
//! - `source.rs`: the source textures a build reads, decoded once each, with their wrap modes.
//! - `cache.rs`: [`TextureCache`], decoded textures shared between atlases, each
//!   ([`DecodedTexture`]) with its mip chain, built in linear light on first use.
//! - `color.rs`: sRGB to linear light and back, texel reads, the mean colour of an image.
//! - `chart.rs`: stage 1. UV islands (triangles connected through shared vertex indices) of
//!   each textured submesh, mapped through KHR_texture_transform into the source's texel space;
//!   each island's chart is its bounding box widened to whole texels; overlapping charts of one
//!   material merge, and so do all the charts of one texture when they fill at least half of
//!   their union (a texture laid out as tiles is copied whole, with one gutter). Untextured materials (and submeshes without UVs) share one flat patch per
//!   material.
//! - `layout.rs`: [`Layout`] (rectangles plus gutters) and its invariants, checked by
//!   [`Layout::validate`].
//! - `pack.rs`: stage 2. The search for the largest global texel scale <= 1 at which the charts
//!   fit, and [`pack_rects`]; placement is the `crunch` packer's (maximal rectangles) up to
//!   [`MAXRECTS_MAX_CHARTS`] charts and the `guillotiere` allocator's beyond.
//! - `bake.rs`: stage 3. Wrap-aware bilinear and trilinear sampling in linear light, base
//!   colour factors, alpha modes, gutters.
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
//!   at which the packer places all padded rectangles in `max_side` squared, found by
//!   shrinking 10% at a time from the area bound and then bisecting the last step. The packers
//!   spread rectangles over the square they are given, so the square is then tightened from the
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
//!   with `lossless`, a PNG that fits is always kept. An atlas whose alpha matters stays PNG.
//!   When nothing fits, the side shrinks by the square root of the overshoot (bytes grow with
//!   the texel count) and the charts are re-packed and re-baked, never resampled from the
//!   baked atlas, so gutters stay intact.
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
//!   blocks can still mix neighbouring charts slightly.
//! - Maximal rectangles' packing time grows about quadratically with the chart count, and a
//!   build packs a dozen or so times, so past [`MAXRECTS_MAX_CHARTS`] charts the guillotine
//!   allocator packs instead: fast, but just past that count it fills a few percent less of
//!   the square, so the texel scale comes out a little lower.

mod bake;
mod cache;
mod chart;
mod color;
mod encode;
mod error;
mod layout;
mod material;
mod options;
mod pack;
mod remap;
mod source;

use horizon_mesh::model::{AlphaMode, InstancedMesh, Material, Submesh, Texture, Wrap};

pub use cache::{DecodedTexture, TextureCache};
pub use error::AtlasError;
pub use layout::{Layout, LayoutError, PackedRect};
pub use options::{AtlasOptions, MAX_TILES_PER_AXIS};
pub use pack::{pack_rects, MAXRECTS_MAX_CHARTS};

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
    let sources = source::decode_sources(mesh, cache)?;
    // Stage 1: chart the used texture regions and the flat-colour patches.
    let charting = chart::chart_mesh(mesh, &sources, options);
    // The one output material decides whether alpha must survive encoding.
    let material = material::merge_materials(mesh);
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
