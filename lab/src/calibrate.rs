//! `horizon-lab calibrate`: Table 1's deduplication thresholds derived by the core paper's
//! procedure (section 5.1) over the repository's models and the generated ones: renders from
//! three directions, SSIM, every pair of models and perturbed variants.

use std::io::IsTerminal;
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use horizon_descriptors::calibrate::{self, CalibrationModel, CalibrationOptions, Table1};
use horizon_mesh::{import_file, ImportOptions};
use horizon_server::outln;
use horizon_world::write_atomically;

/// The shared models the calibration starts from (third-party; licences beside them).
const SHARED_MODELS: &[&str] = &[
    "bunny_trimesh/bunny.ply",
    "BoxTextured/BoxTextured.glb",
    "CesiumMilkTruck/CesiumMilkTruck.glb",
    "DamagedHelmet/DamagedHelmet.glb",
    "GlassVaseFlowers/GlassVaseFlowers.glb",
    "SimpleInstancing/SimpleInstancing.glb",
    "NegativeScaleTest/NegativeScaleTest.glb",
    "GpuInstancesMetadata/GpuInstancesMetadata.gltf",
];

/// Derives Table 1 and writes `table1.json` and `table1.md` into `out`.
pub fn calibrate(
    assets: &Path,
    out: &Path,
    ssim: f64,
    seeds: u64,
    pairs_out: Option<&Path>,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        ssim.is_finite() && ssim > 0.0 && ssim <= 1.0,
        "--ssim {ssim} is not a score in (0, 1]"
    );
    anyhow::ensure!(
        (1..=16).contains(&seeds),
        "--seeds {seeds} is not between 1 and 16"
    );
    // Fail before the long run, not after it.
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    if let Some(parent) = pairs_out.and_then(Path::parent) {
        if !parent.as_os_str().is_empty() && !parent.is_dir() {
            anyhow::bail!("--pairs: folder {} does not exist", parent.display());
        }
    }
    let started = Instant::now();
    let mut bases = Vec::new();
    for rel in SHARED_MODELS {
        let path = assets.join(rel);
        let imported = import_file(&path, &ImportOptions::default())
            .with_context(|| format!("reading {}", path.display()))?;
        let name = rel.split('/').next().unwrap_or(rel).to_string();
        bases.push(CalibrationModel {
            family: name.clone(),
            name,
            mesh: imported.mesh,
        });
    }
    for name in horizon_worldgen::MODEL_NAMES {
        for seed in 1..=seeds {
            bases.push(CalibrationModel {
                name: format!("{name}#{seed}"),
                // Seeds of one generator are similar but distinct models: one family.
                family: (*name).to_string(),
                mesh: horizon_worldgen::generate_model(name, seed)?,
            });
        }
    }
    let options = CalibrationOptions {
        ssim_threshold: ssim,
        ..CalibrationOptions::default()
    };
    let terminal = std::io::stderr().is_terminal();
    let progress = move |stage: &str, done: usize, total: usize| {
        if terminal {
            eprint!("\r{stage:<12} {done:>6}/{total:<6}");
            if done == total {
                eprintln!();
            }
        } else if done == total {
            eprintln!("{stage}: {total} done");
        }
    };
    let calibration = calibrate::run(bases, &options, &progress)?;
    let (mut table, pairs) = (calibration.table, calibration.pairs);
    if let Some(path) = pairs_out {
        let rows: Vec<_> = pairs
            .iter()
            .map(|p| {
                (
                    &calibration.names[p.a],
                    &calibration.names[p.b],
                    p.z_diff,
                    p.t_diff,
                    &p.ssim,
                )
            })
            .collect();
        write_atomically(path, serde_json::to_string(&rows)?.as_bytes())?;
    }
    table.command = format!(
        "horizon-lab calibrate --out {} --ssim {ssim} --seeds {seeds}",
        out.display()
    );
    let json = serde_json::to_string_pretty(&table)?;
    write_atomically(&out.join("table1.json"), json.as_bytes())?;
    let markdown = markdown(&table, pairs.len(), started.elapsed().as_secs_f64());
    write_atomically(&out.join("table1.md"), markdown.as_bytes())?;
    outln!("{}", markdown.trim_end())?;
    Ok(())
}

fn markdown(c: &calibrate::CalibrationTable, pairs: usize, seconds: f64) -> String {
    let paper = Table1::paper();
    let mut s = String::new();
    s.push_str("# Table 1, derived\n\n");
    s.push_str(&format!(
        "{} models, {pairs} pairs, SSIM >= {} counts as indistinguishable; {:.0} s.\n\
         Regenerate with `{}`.\n\n",
        c.models, c.ssim_threshold, seconds, c.command
    ));
    s.push_str("| image size (pixels) | solid angle | z_diff | t_diff | paper z_diff | paper t_diff | indistinguishable pairs | admitted | distinguishable pairs |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for (k, row) in c.table.rows.iter().enumerate() {
        let p = &paper.rows[k];
        let cov = &c.coverage[k];
        s.push_str(&format!(
            "| < {} | < {:.2e} | {:.4} | {:.1} | {} | {} | {} | {} | {} |\n",
            row.max_pixels,
            row.max_solid_angle,
            row.z_diff,
            row.t_diff,
            p.z_diff,
            p.t_diff,
            cov.indistinguishable,
            cov.admitted,
            cov.distinguishable
        ));
    }
    s.push_str("\nSensitivity to the SSIM threshold (z_diff / t_diff per row):\n\n");
    for (t, table) in &c.sensitivity {
        let cells: Vec<String> = table
            .rows
            .iter()
            .map(|r| format!("{:.4} / {:.1}", r.z_diff, r.t_diff))
            .collect();
        s.push_str(&format!("- SSIM >= {t}: {}\n", cells.join(", ")));
    }
    s
}
