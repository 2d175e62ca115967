//! `horizon mesh stats` and `horizon mesh convert`.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use horizon_mesh::{export_glb, import_file, ExportOptions, ImportOptions, MeshStats};
use serde::Serialize;

/// Prints the statistics of a model file.
pub fn stats(file: &Path, json: bool) -> anyhow::Result<()> {
    let imported = import_file(file, &ImportOptions::default())?;
    for w in &imported.warnings {
        eprintln!("horizon: warning: {w}");
    }
    let stats = MeshStats::of(&imported.mesh);
    if json {
        println!("{}", serde_json::to_string(&stats)?);
    } else {
        print_stats(&stats);
    }
    Ok(())
}

fn print_stats(s: &MeshStats) {
    println!("submeshes           {}", s.submeshes);
    println!("instances           {}", s.instances);
    println!("triangles unique    {}", s.triangles_unique);
    println!("triangles expanded  {}", s.triangles_expanded);
    println!("materials           {}", s.materials);
    println!("textures            {}", s.textures);
    match (s.bounds.min, s.bounds.max) {
        (Some(min), Some(max)) => println!("bounds              {min:?} .. {max:?}"),
        _ => println!("bounds              empty"),
    }
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
        println!("{}", serde_json::to_string(&report)?);
    } else {
        for w in &report.warnings {
            eprintln!("horizon: warning: {w}");
        }
        println!(
            "{} -> {}: {} submeshes, {} instances, {} expanded triangles, {} bytes",
            input.display(),
            output.display(),
            report.stats.submeshes,
            report.stats.instances,
            report.stats.triangles_expanded,
            report.output_bytes
        );
    }
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    // The store's writer: temporary file, fsync, rename, fsync of the folder.
    horizon_aggregate::store::write_atomically(path, bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Prints the symmetric Metro-style Hausdorff distance between two model files, each expanded
/// into world space.
pub fn distance(a: &Path, b: &Path, samples: usize, json: bool) -> anyhow::Result<()> {
    let ma = import_file(a, &ImportOptions::default())?.mesh.expand();
    let mb = import_file(b, &ImportOptions::default())?.mesh.expand();
    let options = horizon_simplify::distance::DistanceOptions {
        samples,
        ..Default::default()
    };
    let report = horizon_simplify::distance::hausdorff(&ma, &mb, &options)?;
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "hausdorff {:.6e} ({:.4e} of the diagonal {:.4}); mean {:.4e} / {:.4e}; {:.3} s",
            report.hausdorff,
            report.hausdorff_rel_diag,
            report.diagonal,
            report.forward.mean,
            report.backward.mean,
            report.seconds
        );
    }
    Ok(())
}
