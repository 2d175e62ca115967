//! The options of [`export_glb`](super::export_glb) and their presets.

/// Options for [`export_glb`](super::export_glb).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExportOptions {
    /// Quantize and meshopt-encode geometry (lossy for positions at 16 bits per axis).
    pub compress: bool,
    /// Store instance rotations as normalized 16-bit quaternions (EXT_mesh_gpu_instancing
    /// allows it without KHR_mesh_quantization): 8 bytes instead of 16 per instance, at most
    /// about 3e-5 rad off.
    pub short_rotations: bool,
    /// Let submeshes of one attribute layout share their vertex accessors, up to 65,535
    /// vertices per shared run, each primitive keeping its own 16-bit index accessor into the
    /// run (see `vertex_runs`). Ignored when compressing (each submesh then has its own
    /// quantisation grid).
    pub share_vertices: bool,
    /// Normals as 8-bit and UVs in [0, 1] and colours as 16-bit normalized integers
    /// (KHR_mesh_quantization): with float positions 20 bytes a vertex instead of 32, normals
    /// within about 0.5 degrees. Compression always does this (and quantizes positions too).
    pub short_attributes: bool,
    /// Positions as unsigned 16-bit integers over each vertex run's box (KHR_mesh_quantization),
    /// 8 bytes a vertex instead of 12, for every run whose rounding keeps each of its vertices,
    /// in every placement, within this distance (world units) of where it was; the other runs
    /// keep float positions. `None`: float positions (unless compressing).
    pub position_tolerance: Option<f32>,
}

impl ExportOptions {
    /// Plain float attributes, readable by every glTF loader.
    pub fn plain() -> Self {
        Self {
            compress: false,
            short_rotations: false,
            share_vertices: false,
            short_attributes: false,
            position_tolerance: None,
        }
    }

    /// Quantized, meshopt-compressed output for serving.
    pub fn compressed() -> Self {
        Self {
            compress: true,
            short_rotations: true,
            share_vertices: false,
            short_attributes: true,
            position_tolerance: None,
        }
    }

    /// Lossless and compact, for files only Horizon reads back (an aggregate's parts): float
    /// attributes and rotations exactly as in memory, vertices shared in runs.
    pub fn parts() -> Self {
        Self {
            share_vertices: true,
            ..Self::plain()
        }
    }

    /// What aggregates are written as, seen from afar and made mostly of instances: short
    /// normals, UVs and instance rotations, vertices shared in runs, and positions 16-bit
    /// wherever that keeps them within `position_tolerance` (world units) of their place.
    pub fn aggregate(position_tolerance: f32) -> Self {
        Self {
            compress: false,
            short_rotations: true,
            share_vertices: true,
            short_attributes: true,
            position_tolerance: Some(position_tolerance),
        }
    }
}
