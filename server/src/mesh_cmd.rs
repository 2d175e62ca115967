//! `horizon mesh stats` and `horizon mesh convert`.

use std::path::Path;
use std::time::Instant;

use horizon_mesh::{export_glb, import_file, ExportOptions, ImportOptions, MeshStats};
use horizon_server::outln;
use horizon_world::write_atomically;
use serde::Serialize;

/// Prints the statistics of a model file.
pub fn stats(file: &Path, json: bool) -> anyhow::Result<()> {
    let imported = import_file(file, &ImportOptions::default())?;
    for w in &imported.warnings {
        eprintln!("horizon: warning: {w}");
    }
    let s = MeshStats::of(&imported.mesh);
    if json {
        outln!("{}", serde_json::to_string(&s)?)?;
        return Ok(());
    }
    outln!("submeshes           {}", s.submeshes)?;
    outln!("instances           {}", s.instances)?;
    outln!("triangles unique    {}", s.triangles_unique)?;
    outln!("triangles expanded  {}", s.triangles_expanded)?;
    outln!("materials           {}", s.materials)?;
    outln!("textures            {}", s.textures)?;
    match (s.bounds.min, s.bounds.max) {
        (Some(min), Some(max)) => outln!("bounds              {min:?} .. {max:?}")?,
        _ => outln!("bounds              empty")?,
    }
    Ok(())
}

/// What `horizon mesh convert --json` prints.
#[derive(Serialize)]
struct ConvertReport {
    input_bytes: u64,
    output_bytes: u64,
    compress: bool,
    import_seconds: f64,
    export_seconds: f64,
    warnings: Vec<String>,
    stats: MeshStats,
}

/// Imports any supported model and writes it as GLB. The output is written to a temporary
/// file beside it and renamed into place, so a failure never leaves a half-written file.
pub fn convert(input: &Path, output: &Path, compress: bool, json: bool) -> anyhow::Result<()> {
    let started = Instant::now();
    let imported = import_file(input, &ImportOptions::default())?;
    let import_seconds = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let options = if compress {
        ExportOptions::compressed()
    } else {
        ExportOptions::plain()
    };
    let glb = export_glb(&imported.mesh, &options)?;
    let export_seconds = started.elapsed().as_secs_f64();
    write_atomically(output, &glb)?;
    let report = ConvertReport {
        input_bytes: std::fs::metadata(input).map(|m| m.len()).unwrap_or(0),
        output_bytes: glb.len() as u64,
        compress,
        import_seconds,
        export_seconds,
        warnings: imported.warnings.clone(),
        stats: MeshStats::of(&imported.mesh),
    };
    if json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        for w in &report.warnings {
            eprintln!("horizon: warning: {w}");
        }
        outln!(
            "{} -> {}: {} submeshes, {} instances, {} expanded triangles, {} bytes",
            input.display(),
            output.display(),
            report.stats.submeshes,
            report.stats.instances,
            report.stats.triangles_expanded,
            report.output_bytes
        )?;
    }
    Ok(())
}
