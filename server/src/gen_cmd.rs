//! `horizon gen model`: the seeded benchmark models of `horizon-worldgen`.

use std::path::Path;
use std::time::Instant;

use horizon_mesh::{export_glb, ExportOptions, MeshStats};
use serde::Serialize;

use crate::mesh_cmd::write_atomically;

/// What `horizon gen model --json` prints.
#[derive(Serialize)]
struct Report<'a> {
    name: &'a str,
    seed: u64,
    seconds: f64,
    output_bytes: u64,
    stats: MeshStats,
}

/// Generates the model `name` from `seed` and writes it as GLB.
pub fn model(name: &str, output: &Path, seed: u64, json: bool) -> anyhow::Result<()> {
    let started = Instant::now();
    let mesh = horizon_worldgen::generate_model(name, seed)?;
    let seconds = started.elapsed().as_secs_f64();
    let glb = export_glb(&mesh, &ExportOptions::plain())?;
    write_atomically(output, &glb)?;
    let report = Report {
        name,
        seed,
        seconds,
        output_bytes: glb.len() as u64,
        stats: MeshStats::of(&mesh),
    };
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{name} (seed {seed}) -> {}: {} submeshes, {} instances, {} unique / {} expanded triangles, {} bytes",
            output.display(),
            report.stats.submeshes,
            report.stats.instances,
            report.stats.triangles_unique,
            report.stats.triangles_expanded,
            report.output_bytes
        );
    }
    Ok(())
}
