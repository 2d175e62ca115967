//! Shape and texture descriptors of a model (Azim et al. 2014, section 4.1 and Table 1):
//! similarity drives both the BVH's grouping and the aggregates' deduplication.
//!
//! # Layout
//! - [`describe`]: the entry point, a pipeline of three stages:
//!   [`voxel::voxelize`] (conservative 128^3 surface grid over the expanded model, every
//!   instance; each cell also weighted by the surface area inside it, so a surface weighs the
//!   same whatever its angle to the grid), then [`zernike::zernike_with`] (3D Zernike norms,
//!   Novotni and Klein 2004, order 20, 121 values, from separable geometric moments; mass
//!   normalised to 1 and the RMS radius scaled to 0.4), and [`csd::color_structure`] (MPEG-7
//!   Color Structure Descriptor, 32 bins, on charted textures with repeats unwrapped).
//! - [`z_diff`] (L2 on Zernike) and [`t_diff`] (L1 on CSD): the distances Table 1 thresholds.
//! - [`describe_batch`]: many models in parallel with rayon.
//! - [`calibrate`]: Table 1's deduplication thresholds, derived by the paper's procedure
//!   (renders from three directions, a perceptual metric, many model pairs), and the
//!   calibrated table the aggregate pipeline uses ([`calibrate::Table1::calibrated`]).

pub mod calibrate;
pub mod csd;
mod error;
pub mod voxel;
pub mod zernike;

use std::time::Instant;

use horizon_mesh::InstancedMesh;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use csd::{CsdOptions, CSD_BINS};
pub use error::DescriptorError;
pub use voxel::{VoxelGrid, VoxelizeOptions};
pub use zernike::{ZernikeOptions, ZERNIKE_LEN, ZERNIKE_ORDER};

/// Options for [`describe`]; the defaults are the paper's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DescriptorOptions {
    /// How the shape is voxelized.
    pub voxelize: VoxelizeOptions,
    /// How the voxels are normalised into the unit ball.
    pub zernike: ZernikeOptions,
    /// How the colour structure is measured.
    pub csd: CsdOptions,
}

/// A model's two descriptors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Descriptors {
    /// 3D Zernike norms ||Omega_nl|| for n <= 20, l <= n, n - l even: [`ZERNIKE_LEN`] values,
    /// ordered by n then l.
    pub zernike: Vec<f32>,
    /// Color Structure Descriptor: [`CSD_BINS`] values on MPEG-7's 0..=255 amplitude scale.
    pub csd: Vec<f32>,
}

/// [`Descriptors`] plus how long each stage took.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DescribeReport {
    /// The descriptors.
    pub descriptors: Descriptors,
    /// Occupied voxels in the grid.
    pub voxels: usize,
    /// Seconds spent voxelizing.
    pub voxelize_seconds: f64,
    /// Seconds spent on the Zernike moments and norms.
    pub zernike_seconds: f64,
    /// Seconds spent on the Color Structure Descriptor.
    pub csd_seconds: f64,
    /// Total seconds.
    pub seconds: f64,
}

/// Both descriptors of `mesh`, computed on the calling thread.
pub fn describe(
    mesh: &InstancedMesh,
    options: &DescriptorOptions,
) -> Result<DescribeReport, DescriptorError> {
    mesh.validate()?;
    let started = Instant::now();
    let grid = voxel::voxelize(mesh, &options.voxelize)?;
    let voxelized = Instant::now();
    let zernike = zernike::zernike_with(&grid, &options.zernike)?;
    let zernike_done = Instant::now();
    let csd = csd::color_structure(mesh, &options.csd)?;
    let done = Instant::now();
    Ok(DescribeReport {
        descriptors: Descriptors {
            zernike: zernike.to_vec(),
            csd: csd.to_vec(),
        },
        voxels: grid.occupied_count(),
        voxelize_seconds: (voxelized - started).as_secs_f64(),
        zernike_seconds: (zernike_done - voxelized).as_secs_f64(),
        csd_seconds: (done - zernike_done).as_secs_f64(),
        seconds: (done - started).as_secs_f64(),
    })
}

/// [`describe`] over many models in parallel (rayon), results in input order.
pub fn describe_batch(
    meshes: &[InstancedMesh],
    options: &DescriptorOptions,
) -> Vec<Result<DescribeReport, DescriptorError>> {
    meshes.par_iter().map(|m| describe(m, options)).collect()
}

/// Shape difference: the L2 distance between two Zernike descriptors (Table 1's z_diff).
pub fn z_diff(a: &Descriptors, b: &Descriptors) -> f32 {
    zernike_distance(&a.zernike, &b.zernike)
}

/// Texture difference: the L1 distance between two Color Structure Descriptors (Table 1's
/// t_diff).
pub fn t_diff(a: &Descriptors, b: &Descriptors) -> f32 {
    csd_distance(&a.csd, &b.csd)
}

/// [`z_diff`] on bare Zernike vectors (for descriptors stored apart from [`Descriptors`]).
pub fn zernike_distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f32>()
        .sqrt()
}

/// [`t_diff`] on bare CSD vectors.
pub fn csd_distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum()
}
