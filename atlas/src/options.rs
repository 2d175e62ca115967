//! The knobs of an atlas build and the fixed limit on how often a chart may tile.

/// Most source widths (or heights) of texels a chart keeps along one axis; a chart tiling more
/// often than this is sampled at a lower density instead of filling the atlas with repeats.
pub const MAX_TILES_PER_AXIS: f64 = 4.0;

/// Knobs of [`build_atlas`](crate::build_atlas).
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
