//! `horizon-lab gen model` and `gen world`: the seeded workloads of `horizon-worldgen`, the
//! Table 2 models as GLB files and the benchmark worlds as world directories.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use horizon_mesh::{export_glb, ExportOptions, InstancedMesh, MeshStats};
use horizon_server::outln;
use horizon_server::terminal::ProgressBar;
use horizon_world::ingest::import_model;
use horizon_world::{write_atomically, World, WorldError};
use horizon_worldgen::{city_distinct_layout, distinct_building, CITY_DISTINCT_OBJECTS};
use serde::Serialize;

/// Writes the world `name` generated from `seed` into `dir`. City and city9 replace 3% of
/// their objects by the models found in `assets` (the repository's `assets/models`);
/// city-distinct has `objects` distinct buildings (default 60,000).
pub fn world(
    name: &str,
    dir: &Path,
    seed: u64,
    assets: Option<&Path>,
    objects: Option<usize>,
) -> anyhow::Result<()> {
    if name == "city-distinct" {
        return city_distinct(dir, seed, objects.unwrap_or(CITY_DISTINCT_OBJECTS));
    }
    anyhow::ensure!(
        objects.is_none(),
        "--objects applies to city-distinct only; {name} has a fixed size"
    );
    let extra = if name.starts_with("city") {
        let folder = match assets {
            Some(a) => a.to_path_buf(),
            None => default_assets()?,
        };
        load_user_models(&folder)?
    } else {
        Vec::new()
    };
    let g = horizon_server::generated::write_world(name, dir, seed, &extra)?;
    let status = g.world.status()?;
    let rows = g.world.models().rows()?;
    let bytes: u64 = rows.iter().map(|m| m.bytes).sum();
    outln!(
        "{name} (seed {seed}) -> {}: {} objects, {} unique models ({} user), {bytes} model bytes; generated in {:.2} s, written in {:.2} s",
        dir.display(),
        status.objects,
        rows.len(),
        extra.len(),
        g.generate_seconds,
        g.write_seconds
    )?;
    Ok(())
}

/// `city-distinct`: `objects` distinct buildings (`horizon_worldgen::distinct_building`), made
/// and stored a batch at a time, never all in memory. Prints what naive costs: every
/// building's bytes.
fn city_distinct(dir: &Path, seed: u64, objects: usize) -> anyhow::Result<()> {
    anyhow::ensure!(objects > 0, "--objects must be at least 1");
    let started = Instant::now();
    let layout = city_distinct_layout(seed, objects);
    let placements: Vec<(usize, glam::Affine3A)> = layout.into_iter().enumerate().collect();
    let bar = ProgressBar::new("buildings");
    let make = |k: usize| {
        distinct_building(seed, k)
            .map(|m| (format!("building-{k}"), m))
            .map_err(|e| WorldError::Model {
                name: format!("building-{k}"),
                reason: e.to_string(),
            })
    };
    let world = World::create_with(
        dir,
        "city-distinct",
        seed,
        objects,
        &make,
        &placements,
        &|done, total| bar.show(done, total),
    )?;
    bar.finish();
    let rows = world.models().rows()?;
    let bytes: u64 = rows.iter().map(|m| m.bytes).sum();
    outln!(
        "city-distinct (seed {seed}) -> {}: {objects} objects, {} unique models, naive {bytes} bytes ({:.2} GB); generated and written in {:.1} s",
        dir.display(),
        rows.len(),
        bytes as f64 / 1e9,
        started.elapsed().as_secs_f64()
    )?;
    Ok(())
}

/// `assets/models` under the working directory, else the repository's copy.
fn default_assets() -> anyhow::Result<PathBuf> {
    let local = PathBuf::from("assets/models");
    if local.is_dir() {
        return Ok(local);
    }
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/models");
    if repo.is_dir() {
        return Ok(repo);
    }
    anyhow::bail!("no assets/models folder for the city's user models; pass --assets DIR")
}

/// Every model file one level below `folder` (sorted by path, so the world is deterministic).
/// Files that do not import are skipped with a note on stderr.
fn load_user_models(folder: &Path) -> anyhow::Result<Vec<InstancedMesh>> {
    let mut files = Vec::new();
    let entries =
        std::fs::read_dir(folder).with_context(|| format!("cannot read {}", folder.display()))?;
    for entry in entries {
        let path = entry?.path();
        let candidates: Vec<PathBuf> = if path.is_dir() {
            std::fs::read_dir(&path)?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .collect()
        } else {
            vec![path]
        };
        files.extend(candidates.into_iter().filter(|p| {
            matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("glb" | "gltf" | "ply" | "obj" | "stl")
            )
        }));
    }
    files.sort();
    let mut models = Vec::new();
    for f in &files {
        match import_model(f) {
            Ok(imported) => models.push(imported.mesh),
            Err(e) => eprintln!("horizon-lab: note: skipping {e}"),
        }
    }
    if models.is_empty() {
        anyhow::bail!("no importable models in {}", folder.display());
    }
    Ok(models)
}

/// What `horizon-lab gen model --json` prints.
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
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        outln!(
            "{name} (seed {seed}) -> {}: {} submeshes, {} instances, {} unique / {} expanded triangles, {} bytes",
            output.display(),
            report.stats.submeshes,
            report.stats.instances,
            report.stats.triangles_unique,
            report.stats.triangles_expanded,
            report.output_bytes
        )?;
    }
    Ok(())
}
