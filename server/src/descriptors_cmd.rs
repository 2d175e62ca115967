//! `horizon descriptors`: a model's shape (3D Zernike) and texture (Color Structure)
//! descriptors, the vectors the BVH and dedup compare.

use std::path::Path;

use horizon_descriptors::{describe, DescriptorOptions};
use horizon_mesh::{import_file, ImportOptions};
use horizon_server::outln;
use serde::Serialize;

/// What `horizon descriptors --json` prints.
#[derive(Serialize)]
struct Report {
    zernike: Vec<f32>,
    csd: Vec<f32>,
    seconds: f64,
    voxels: usize,
    voxelize_seconds: f64,
    zernike_seconds: f64,
    csd_seconds: f64,
}

/// Prints both descriptors of a model and the time they took (import excluded).
pub fn describe_file(file: &Path, solid: bool, json: bool) -> anyhow::Result<()> {
    let imported = import_file(file, &ImportOptions::default())?;
    for w in &imported.warnings {
        eprintln!("horizon: warning: {w}");
    }
    let mut options = DescriptorOptions::default();
    options.voxelize.solid = solid;
    let r = describe(&imported.mesh, &options)?;
    let report = Report {
        zernike: r.descriptors.zernike,
        csd: r.descriptors.csd,
        seconds: r.seconds,
        voxels: r.voxels,
        voxelize_seconds: r.voxelize_seconds,
        zernike_seconds: r.zernike_seconds,
        csd_seconds: r.csd_seconds,
    };
    if json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        let list = |v: &[f32]| {
            v.iter()
                .map(|x| format!("{x:.4}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        outln!(
            "zernike ({} values)  {}",
            report.zernike.len(),
            list(&report.zernike)
        )?;
        outln!(
            "csd ({} bins)        {}",
            report.csd.len(),
            list(&report.csd)
        )?;
        outln!(
            "{} voxels; {:.1} ms (voxelize {:.1}, zernike {:.1}, csd {:.1})",
            report.voxels,
            report.seconds * 1e3,
            report.voxelize_seconds * 1e3,
            report.zernike_seconds * 1e3,
            report.csd_seconds * 1e3
        )?;
    }
    Ok(())
}
