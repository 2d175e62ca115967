//! `horizon simplify`: IAS, our quadric baseline, or meshoptimizer, on any model file.

use std::path::Path;
use std::time::Instant;

use horizon_mesh::{export_glb, import_file, ExportOptions, ImportOptions};
use horizon_server::outln;
use horizon_simplify::{simplify, simplify_meshopt, simplify_qem, SimplifyOptions, Target};
use horizon_world::write_atomically;
use serde::Serialize;

/// Which simplifier to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Instance-aware simplification on the instanced mesh.
    Ias,
    /// The same engine on the mesh expanded into one instance.
    Qem,
    /// meshoptimizer's simplifier on the expanded, position-welded mesh (positions only).
    Meshopt,
}

/// What `horizon simplify --json` prints.
#[derive(Serialize)]
struct Report {
    method: &'static str,
    triangles_in: u64,
    triangles_out: u64,
    triangles_target: u64,
    unique_triangles_in: u64,
    unique_triangles_out: u64,
    collapses: u64,
    /// Largest quadric error reached, in world units (RMS distance).
    error: f64,
    /// `error` over the input's bounding-box diagonal.
    error_rel_diag: f64,
    /// The simplification proper.
    seconds: f64,
    import_seconds: f64,
    export_seconds: f64,
    output_bytes: u64,
}

/// Simplifies `input` to `ratio` of its expanded triangles and writes `output` as GLB.
pub fn run(
    input: &Path,
    output: &Path,
    ratio: f64,
    method: Method,
    compress: bool,
    json: bool,
) -> anyhow::Result<()> {
    if !(0.0..=1.0).contains(&ratio) {
        anyhow::bail!("--ratio {ratio} is not a fraction between 0 and 1");
    }
    let started = Instant::now();
    let imported = import_file(input, &ImportOptions::default())?;
    let import_seconds = started.elapsed().as_secs_f64();
    let mesh = imported.mesh;
    let target = Target::Ratio(ratio);
    let options = SimplifyOptions::default();
    let result = match method {
        Method::Ias => simplify(&mesh, target, &options)?,
        Method::Qem => simplify_qem(&mesh, target, &options)?,
        Method::Meshopt => simplify_meshopt(&mesh, target)?,
    };
    let started = Instant::now();
    let export = if compress {
        ExportOptions::compressed()
    } else {
        ExportOptions::plain()
    };
    let glb = export_glb(&result.mesh, &export)?;
    let export_seconds = started.elapsed().as_secs_f64();
    write_atomically(output, &glb)?;
    let r = &result.report;
    let diagonal = f64::from(mesh.bounds().diagonal());
    let report = Report {
        method: r.method,
        triangles_in: r.triangles_in,
        triangles_out: r.triangles_out,
        triangles_target: r.triangles_target,
        unique_triangles_in: r.unique_triangles_in,
        unique_triangles_out: r.unique_triangles_out,
        collapses: r.collapses,
        error: r.error,
        error_rel_diag: if diagonal > 0.0 {
            r.error / diagonal
        } else {
            0.0
        },
        seconds: r.seconds,
        import_seconds,
        export_seconds,
        output_bytes: glb.len() as u64,
    };
    for w in &imported.warnings {
        eprintln!("horizon: warning: {w}");
    }
    if json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        outln!(
            "{} -> {} ({}): {} -> {} expanded triangles (target {}), error {:.3e} ({:.2e} of the diagonal), {:.3} s, {} bytes",
            input.display(),
            output.display(),
            report.method,
            report.triangles_in,
            report.triangles_out,
            report.triangles_target,
            report.error,
            report.error_rel_diag,
            report.seconds,
            report.output_bytes
        )?;
    }
    Ok(())
}
