//! `horizon build`'s aggregate stage and `horizon report` (issue 6): the offline rebuild of
//! every node's aggregate into `DIR/aggregates/`, and the join download it buys a client.

use std::collections::{BTreeSet, HashMap};
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use horizon_aggregate::{
    build_aggregates, AggregateManifest, AggregateOptions, AggregateStore, AtlasPolicy,
    BuildOptions, BuildReport, InMemoryModels, LevelTime, Progress, SourceModel,
};
use horizon_bvh::{Bvh, CutItem, CutQuery};
use horizon_mesh::{import_file, ImportOptions};
use rayon::prelude::*;
use serde::Serialize;

use crate::world_store::{DescriptorCache, WorldDir, WorldManifest};

/// The aggregate knobs of `horizon build`.
#[derive(Clone, Copy, Debug)]
pub struct AggregateArgs {
    /// See [`AggregateOptions::pixels_per_triangle`].
    pub pixels_per_triangle: f64,
    /// See [`AggregateOptions::min_solid_angle`].
    pub min_solid_angle: f64,
    /// When to atlas.
    pub atlas: AtlasPolicy,
}

impl AggregateArgs {
    /// The aggregate options these arguments ask for.
    pub fn options(&self) -> AggregateOptions {
        AggregateOptions {
            pixels_per_triangle: self.pixels_per_triangle,
            min_solid_angle: self.min_solid_angle,
            atlas: self.atlas,
            ..AggregateOptions::default()
        }
    }
}

/// `DIR/aggregates`.
pub fn aggregate_store(dir: &Path) -> AggregateStore {
    AggregateStore::new(&dir.join("aggregates"))
}

/// `DIR/baseline`: the unoptimised aggregates `horizon report` compares with, measured but
/// not kept (their sizes, parts and manifest are; their GLBs would take gigabytes).
pub fn baseline_store(dir: &Path) -> AggregateStore {
    AggregateStore::measuring(&dir.join("baseline"))
}

/// Every model of the world, imported and prepared, numbered as the BVH numbers them.
pub fn load_models(
    store: &WorldDir,
    manifest: &WorldManifest,
    cache: &DescriptorCache,
) -> anyhow::Result<InMemoryModels> {
    let models = manifest
        .models
        .par_iter()
        .map(|m| -> anyhow::Result<SourceModel> {
            let path = store.model(&m.hash);
            let mesh = import_file(&path, &ImportOptions::default())
                .with_context(|| format!("cannot load {}", path.display()))?
                .mesh;
            let d = cache
                .models
                .get(&m.hash)
                .with_context(|| format!("model {} has no descriptors", m.hash))?;
            Ok(SourceModel::new(
                m.hash.clone(),
                mesh,
                d.zernike.clone(),
                d.csd.clone(),
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(InMemoryModels::new(models))
}

/// Builds every aggregate of `bvh` into `store`, with a progress bar on a terminal.
pub fn build_into(
    bvh: &Bvh,
    models: &InMemoryModels,
    store: &AggregateStore,
    options: AggregateOptions,
    what: &str,
) -> anyhow::Result<BuildReport> {
    build_some_into(bvh, models, store, options, None, true, what)
}

/// Builds the aggregates of `only` (and every node below them; all nodes for `None`) into
/// `store`, with a progress bar on a terminal.
pub fn build_some_into(
    bvh: &Bvh,
    models: &InMemoryModels,
    store: &AggregateStore,
    options: AggregateOptions,
    only: Option<BTreeSet<u32>>,
    collect_garbage: bool,
    what: &str,
) -> anyhow::Result<BuildReport> {
    let bar = ProgressBar::new(what);
    let report = build_aggregates(
        bvh,
        models,
        store,
        &BuildOptions {
            aggregate: options,
            world_textures: models.texture_totals(),
            stop_after: None,
            only,
            collect_garbage,
        },
        &|p| bar.show(p),
    )?;
    bar.finish();
    Ok(report)
}

/// A one-line progress bar on stderr, drawn only on a terminal and at most every 1%.
struct ProgressBar {
    what: String,
    on: bool,
    last: AtomicUsize,
}

impl ProgressBar {
    fn new(what: &str) -> Self {
        Self {
            what: what.to_string(),
            on: std::io::stderr().is_terminal(),
            last: AtomicUsize::new(usize::MAX),
        }
    }

    fn show(&self, p: Progress) {
        if !self.on || p.total == 0 {
            return;
        }
        let percent = p.done * 100 / p.total;
        if self.last.swap(percent, Ordering::Relaxed) == percent {
            return;
        }
        let filled = percent * 30 / 100;
        let mut err = std::io::stderr().lock();
        let _ = write!(
            err,
            "\rhorizon: {} [{}{}] {}/{} ({percent}%)",
            self.what,
            "#".repeat(filled),
            "-".repeat(30 - filled),
            p.done,
            p.total
        );
        let _ = err.flush();
    }

    fn finish(&self) {
        if self.on {
            eprintln!();
        }
    }
}

/// `horizon report --json`.
#[derive(Debug, Serialize)]
pub struct Report {
    /// Viewpoints.
    pub views: usize,
    /// The cut's minimum solid angle.
    pub min_solid_angle: f32,
    /// Mean unique bytes of every asset in a cut (models of objects, aggregate GLBs).
    pub join_bytes_mean: f64,
    /// Every unique model of the world: what a client without aggregates downloads.
    pub naive_bytes: u64,
    /// Mean join download through the unoptimised aggregates (no dedup, QEM on the expanded
    /// merge, no atlas).
    pub unoptimized_join_bytes_mean: f64,
    /// `1 - join_bytes_mean / naive_bytes`.
    pub reduction_vs_naive: f64,
    /// `1 - join_bytes_mean / unoptimized_join_bytes_mean`.
    pub reduction_vs_unoptimized: f64,
    /// Mean draw calls per cut: one per submesh of every entry (instanced submeshes are one
    /// call each).
    pub draw_calls_mean: f64,
    /// The same through the unoptimised aggregates.
    pub unoptimized_draw_calls_mean: f64,
    /// Mean textures per cut (unique).
    pub textures_mean: f64,
    /// The same through the unoptimised aggregates.
    pub unoptimized_textures_mean: f64,
    /// Mean entries per cut, and how many of them are aggregates.
    pub entries_mean: f64,
    /// Mean aggregate entries per cut.
    pub aggregates_mean: f64,
    /// Per view: join bytes, unoptimised join bytes.
    pub per_view: Vec<(f64, f64)>,
    /// Seconds to build the unoptimised baseline (0 when reused).
    pub baseline_seconds: f64,
}

/// Per asset: bytes, draw calls and textures.
#[derive(Clone, Copy, Debug, Default)]
struct Asset {
    bytes: u64,
    draws: u64,
    textures: u64,
}

/// `horizon report DIR --views V --seed S [--min-solid-angle A] [--json]`.
pub fn report(
    dir: &Path,
    views: usize,
    seed: u64,
    min_solid_angle: f32,
    max_results: usize,
    json: bool,
) -> anyhow::Result<()> {
    if views == 0 {
        anyhow::bail!("--views must be at least 1");
    }
    if !(min_solid_angle.is_finite() && min_solid_angle > 0.0) {
        anyhow::bail!("--min-solid-angle {min_solid_angle} must be a positive number");
    }
    let world = WorldDir::new(dir);
    let (manifest, _objects) = world.load()?;
    let bvh: Bvh = WorldDir::read_json(&world.bvh())
        .with_context(|| format!("no built world in {} (run horizon build)", dir.display()))?;
    let ours = aggregate_store(dir)
        .manifest()?
        .with_context(|| format!("no aggregates in {} (run horizon build)", dir.display()))?;
    // The cuts of the seeded viewpoints.
    let bounds = bvh
        .node(bvh.root())
        .map(|n| n.aabb())
        .context("the world is empty")?;
    let positions: Vec<Vec3> = crate::world_cmd::viewpoints(&bounds, seed, views);
    let cuts: Vec<Vec<horizon_bvh::CutEntry>> = positions
        .iter()
        .map(|&position| {
            bvh.cut(&CutQuery {
                position,
                min_solid_angle,
                max_results,
            })
            .entries
        })
        .collect();
    // The unoptimised baseline, with the same display model, cached: only the aggregates in
    // these cuts and the nodes below them (its upper merges of whole world-space meshes
    // would not fit in memory on a large world, and no cut here shows them).
    let t = Instant::now();
    let baseline_options = ours.options.unoptimized();
    let base_store = baseline_store(dir);
    let cache: DescriptorCache = WorldDir::read_json(&world.descriptors())?;
    let models = load_models(&world, &manifest, &cache)?;
    let shown: BTreeSet<u32> = cuts
        .iter()
        .flatten()
        .filter_map(|e| match e.item {
            CutItem::Aggregate(n) => Some(n.0),
            CutItem::Object(_) => None,
        })
        .collect();
    let base_report = build_some_into(
        &bvh,
        &models,
        &base_store,
        baseline_options,
        Some(shown),
        true,
        "baseline",
    )?;
    let baseline_seconds = if base_report.built > 0 {
        t.elapsed().as_secs_f64()
    } else {
        0.0
    };
    let base = base_store
        .manifest()?
        .context("baseline build wrote no manifest")?;
    // Assets: models by BVH number (counted from the models already loaded for the
    // baseline, not read again), aggregates by node.
    let model_assets: Vec<Asset> = manifest
        .models
        .iter()
        .enumerate()
        .map(|(i, m)| -> anyhow::Result<Asset> {
            let mesh = &horizon_aggregate::ModelSource::model(&models, i as u64)?.mesh;
            Ok(Asset {
                bytes: m.bytes,
                draws: mesh.submeshes.len() as u64,
                textures: mesh.textures.len() as u64,
            })
        })
        .collect::<anyhow::Result<_>>()?;
    drop(models);
    let naive_bytes: u64 = manifest.models.iter().map(|m| m.bytes).sum();
    let aggregate_assets = |m: &AggregateManifest| -> HashMap<u32, (String, Asset)> {
        m.nodes
            .iter()
            .map(|(&n, e)| {
                (
                    n,
                    (
                        e.glb.clone(),
                        Asset {
                            bytes: e.stats.bytes as u64,
                            draws: e.stats.submeshes as u64,
                            textures: e.stats.textures as u64,
                        },
                    ),
                )
            })
            .collect()
    };
    let ours_assets = aggregate_assets(&ours);
    let base_assets = aggregate_assets(&base);

    let mut sums = [0.0f64; 8];
    let mut per_view = Vec::new();
    for entries in &cuts {
        let a = join(&bvh, entries, &model_assets, &ours_assets, &manifest)?;
        let b = join(&bvh, entries, &model_assets, &base_assets, &manifest)?;
        let aggregates = entries
            .iter()
            .filter(|e| matches!(e.item, CutItem::Aggregate(_)))
            .count();
        for (s, v) in sums.iter_mut().zip([
            a.bytes as f64,
            b.bytes as f64,
            a.draws as f64,
            b.draws as f64,
            a.textures as f64,
            b.textures as f64,
            entries.len() as f64,
            aggregates as f64,
        ]) {
            *s += v;
        }
        per_view.push((a.bytes as f64, b.bytes as f64));
    }
    let n = views as f64;
    let join_bytes_mean = sums[0] / n;
    let unoptimized_join_bytes_mean = sums[1] / n;
    let report = Report {
        views,
        min_solid_angle,
        join_bytes_mean,
        naive_bytes,
        unoptimized_join_bytes_mean,
        reduction_vs_naive: 1.0 - join_bytes_mean / naive_bytes.max(1) as f64,
        reduction_vs_unoptimized: 1.0 - join_bytes_mean / unoptimized_join_bytes_mean.max(1.0),
        draw_calls_mean: sums[2] / n,
        unoptimized_draw_calls_mean: sums[3] / n,
        textures_mean: sums[4] / n,
        unoptimized_textures_mean: sums[5] / n,
        entries_mean: sums[6] / n,
        aggregates_mean: sums[7] / n,
        per_view,
        baseline_seconds,
    };
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(dir, &report);
    }
    Ok(())
}

fn print_report(dir: &Path, r: &Report) {
    let mb = |b: f64| b / 1e6;
    println!(
        "join download of {} over {} views at Omega_min {}:",
        dir.display(),
        r.views,
        r.min_solid_angle
    );
    println!(
        "  ours:        {:>10.3} MB, {:>8.1} draw calls, {:>7.1} textures",
        mb(r.join_bytes_mean),
        r.draw_calls_mean,
        r.textures_mean
    );
    println!(
        "  unoptimised: {:>10.3} MB, {:>8.1} draw calls, {:>7.1} textures",
        mb(r.unoptimized_join_bytes_mean),
        r.unoptimized_draw_calls_mean,
        r.unoptimized_textures_mean
    );
    println!("  naive:       {:>10.3} MB", mb(r.naive_bytes as f64));
    println!(
        "  reduction: {:.1}% vs naive, {:.1}% vs unoptimised; {:.0} entries per cut, {:.0} aggregates",
        100.0 * r.reduction_vs_naive,
        100.0 * r.reduction_vs_unoptimized,
        r.entries_mean,
        r.aggregates_mean
    );
}

/// The join download of one cut: unique assets' bytes and textures; draw calls per entry.
fn join(
    bvh: &Bvh,
    entries: &[horizon_bvh::CutEntry],
    models: &[Asset],
    aggregates: &HashMap<u32, (String, Asset)>,
    manifest: &WorldManifest,
) -> anyhow::Result<Asset> {
    let mut seen_models = BTreeSet::new();
    let mut seen_aggregates = BTreeSet::new();
    let mut out = Asset::default();
    for e in entries {
        match e.item {
            CutItem::Object(o) => {
                let model = bvh.object(o).context("cut names a missing object")?.model() as usize;
                let a = models
                    .get(model)
                    .with_context(|| format!("model {model} of {} missing", manifest.name))?;
                out.draws += a.draws;
                if seen_models.insert(model) {
                    out.bytes += a.bytes;
                    out.textures += a.textures;
                }
            }
            CutItem::Aggregate(n) => {
                let (hash, a) = aggregates
                    .get(&n.0)
                    .with_context(|| format!("node {} has no aggregate (rebuild)", n.0))?;
                out.draws += a.draws;
                if seen_aggregates.insert(hash.clone()) {
                    out.bytes += a.bytes;
                    out.textures += a.textures;
                }
            }
        }
    }
    Ok(out)
}

/// `horizon bench-aggregates`: what issue 6's build targets are measured with.
#[derive(Debug, Serialize)]
pub struct AggregateBench {
    /// The world's name.
    pub world: String,
    /// Objects and nodes.
    pub objects: usize,
    /// Nodes of the tree (one aggregate each).
    pub nodes: usize,
    /// The full build.
    pub full: BuildReport,
    /// Objects inserted before the incremental rebuild.
    pub inserted: usize,
    /// Ancestors of the inserted objects after insertion.
    pub ancestors: usize,
    /// Ancestors of inserted objects that were not rebuilt (must be 0).
    pub ancestors_missed: usize,
    /// The most aggregates k inserts can change: per insert, at each level the ancestor and
    /// the other half of a split, 2 k (height + 1).
    pub rebuild_bound: usize,
    /// The incremental rebuild.
    pub incremental: BuildReport,
    /// `incremental.seconds / full.seconds`.
    pub incremental_ratio: f64,
    /// Peak resident memory of the process, bytes.
    pub peak_memory_bytes: u64,
}

/// Full build of `DIR/aggregates` from scratch, then `insert` seeded objects into the tree
/// and an incremental rebuild; the world's manifest is restored to the full build's.
pub fn bench(dir: &Path, insert: usize, seed: u64, out: Option<&Path>) -> anyhow::Result<()> {
    let world = WorldDir::new(dir);
    let (manifest, _objects) = world.load()?;
    let mut bvh: Bvh = WorldDir::read_json(&world.bvh())
        .with_context(|| format!("no built world in {} (run horizon build)", dir.display()))?;
    let cache: DescriptorCache = WorldDir::read_json(&world.descriptors())?;
    let models = load_models(&world, &manifest, &cache)?;
    let store = aggregate_store(dir);
    if store.root().exists() {
        std::fs::remove_dir_all(store.root())
            .with_context(|| format!("cannot clear {}", store.root().display()))?;
    }
    let options = AggregateOptions::default();
    let full = build_into(&bvh, &models, &store, options, "full build")?;
    let full_manifest = store.manifest()?.context("full build wrote no manifest")?;

    // Insert seeded copies of existing models at random places.
    let bounds = bvh
        .node(bvh.root())
        .map(|n| n.aabb())
        .context("the world is empty")?;
    let mut rng = horizon_worldgen::rng::Rng::new(seed);
    let mut inserted = Vec::new();
    for _ in 0..insert {
        let m = rng.below(manifest.models.len());
        let hash = &manifest.models[m].hash;
        let d = cache
            .models
            .get(hash)
            .context("model without descriptors")?;
        let t = glam::Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)),
            Vec3::new(
                rng.range(bounds.min.x, bounds.max.x),
                0.0,
                rng.range(bounds.min.z, bounds.max.z),
            ),
        );
        let id = bvh.insert(&horizon_bvh::NewObject {
            model: m as u64,
            transform: t,
            sphere: horizon_bvh::Sphere::new(
                t.transform_point3(Vec3::from_array(d.centre)),
                d.radius,
            ),
            shape: &d.zernike,
            texture: &d.csd,
        })?;
        inserted.push(id);
    }
    let mut ancestors = BTreeSet::new();
    for &id in &inserted {
        let mut at = bvh.object(id).map(|o| o.leaf());
        while let Some(n) = at {
            ancestors.insert(n.0);
            at = bvh.node(n).and_then(|r| r.parent());
        }
    }
    // Its garbage collection waits: the full build's manifest comes back below.
    let incremental = build_some_into(&bvh, &models, &store, options, None, false, "incremental")?;
    let after = store
        .manifest()?
        .context("incremental build wrote no manifest")?;
    let before_keys: BTreeSet<&String> = full_manifest.nodes.values().map(|e| &e.key).collect();
    let rebuilt: BTreeSet<u32> = after
        .nodes
        .iter()
        .filter(|(_, e)| !before_keys.contains(&e.key))
        .map(|(&n, _)| n)
        .collect();
    let ancestors_missed = ancestors.difference(&rebuilt).count();
    let rebuild_bound = 2 * insert * (bvh.height() as usize + 1);
    // The world on disk is still the one without the inserted objects.
    store.write_manifest(&full_manifest)?;
    store.collect_garbage(&full_manifest)?;
    let result = AggregateBench {
        world: manifest.name.clone(),
        objects: bvh.len() - insert,
        nodes: full.nodes,
        incremental_ratio: incremental.seconds / full.seconds.max(1e-9),
        full,
        inserted: insert,
        ancestors: ancestors.len(),
        ancestors_missed,
        rebuild_bound,
        incremental,
        peak_memory_bytes: peak_memory_bytes(),
    };
    let md = bench_markdown(&result);
    let path = out.map(Path::to_path_buf).unwrap_or_else(|| {
        Path::new("bench/results").join(format!("aggregates_{}.md", manifest.name))
    });
    crate::mesh_cmd::write_atomically(&path, md.as_bytes())?;
    println!("{md}");
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// Peak resident set size of this process (Linux `VmHWM`), 0 where unknown.
pub fn peak_memory_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

fn bench_markdown(r: &AggregateBench) -> String {
    let limit = match r.world.as_str() {
        "village" => Some(60.0),
        "city" => Some(600.0),
        _ => None,
    };
    let verdict = |ok: bool| if ok { "PASS" } else { "FAIL" };
    let mut s = format!(
        "# Aggregate build: {}\n\n`horizon bench-aggregates DIR --insert {}` on this machine (2 cores), one run.\n\n",
        r.world, r.inserted
    );
    s += "| measure | value | target | verdict |\n|---|---|---|---|\n";
    s += &format!(
        "| full build ({} objects, {} aggregates) | {:.1} s | {} | {} |\n",
        r.objects,
        r.nodes,
        r.full.seconds,
        limit.map_or("report".into(), |l| format!("<= {l} s")),
        limit.map_or("-", |l| verdict(r.full.seconds <= l))
    );
    s += &format!(
        "| peak memory | {:.2} GB | <= 8 GB | {} |\n",
        r.peak_memory_bytes as f64 / 1e9,
        verdict(r.peak_memory_bytes <= 8 << 30)
    );
    s += &format!(
        "| incremental after {} inserts: aggregates rebuilt | {} of {} ({} ancestors, {} of them missed) | every ancestor, at most 2 k (h + 1) = {} | {} |\n",
        r.inserted,
        r.incremental.built,
        r.nodes,
        r.ancestors,
        r.ancestors_missed,
        r.rebuild_bound,
        verdict(r.ancestors_missed == 0 && r.incremental.built <= r.rebuild_bound)
    );
    s += &format!(
        "| incremental time | {:.2} s = {:.2}% of full | <= 5% | {} |\n",
        r.incremental.seconds,
        100.0 * r.incremental_ratio,
        verdict(r.incremental_ratio <= 0.05)
    );
    s += &format!(
        "| aggregate bytes | {:.1} MB | - | - |\n| failed aggregates | {} | 0 | {} |\n",
        r.full.bytes_total as f64 / 1e6,
        r.full.failed.len(),
        verdict(r.full.failed.is_empty())
    );
    s += "\n## Time per tree level\n\nRoot first. Built: aggregates built on the level (the \
          incremental rebuild reuses the rest).\n\n| depth | nodes | full: built | full: seconds \
          | incremental: built | incremental: seconds |\n|---|---|---|---|---|---|\n";
    // Splits can give the incremental tree a level the full one lacks.
    let depths = r
        .full
        .level_times
        .len()
        .max(r.incremental.level_times.len());
    for depth in 0..depths {
        let (f, i) = (
            r.full.level_times.get(depth),
            r.incremental.level_times.get(depth),
        );
        let cell =
            |l: Option<&LevelTime>, text: fn(&LevelTime) -> String| l.map_or("-".into(), text);
        s += &format!(
            "| {depth} | {} | {} | {} | {} | {} |\n",
            cell(f.or(i), |l| l.nodes.to_string()),
            cell(f, |l| l.built.to_string()),
            cell(f, |l| format!("{:.2}", l.seconds)),
            cell(i, |l| l.built.to_string()),
            cell(i, |l| format!("{:.2}", l.seconds)),
        );
    }
    s += &stage_tables(r);
    s
}

/// Where the builds' time went: each stage's core-seconds summed over the aggregates built,
/// for both builds, then the incremental one by depth.
fn stage_tables(r: &AggregateBench) -> String {
    let (full, inc) = (r.full.stages.named(), r.incremental.stages.named());
    let mut s = String::from(
        "\n## Time per stage\n\nCore-seconds summed over the aggregates built (the nodes of a \
         level run in parallel, so these add up to more than the wall time).\n\n| stage | full \
         | incremental | incremental / full |\n|---|---|---|---|\n",
    );
    for ((name, f), (_, i)) in full.iter().zip(&inc) {
        s += &format!(
            "| {name} | {f:.2} | {i:.2} | {:.1}% |\n",
            100.0 * i / f.max(1e-9)
        );
    }
    let (f, i): (f64, f64) = (
        full.iter().map(|x| x.1).sum(),
        inc.iter().map(|x| x.1).sum(),
    );
    s += &format!(
        "| all | {f:.2} | {i:.2} | {:.1}% |\n",
        100.0 * i / f.max(1e-9)
    );
    s += "\nThe incremental rebuild by depth, core-seconds:\n\n| depth | built |";
    for (name, _) in &inc {
        s += &format!(" {name} |");
    }
    s += "\n|---|---|";
    s += &"---|".repeat(inc.len());
    s += "\n";
    for level in &r.incremental.level_times {
        s += &format!("| {} | {} |", level.depth, level.built);
        for (_, t) in level.stages.named() {
            s += &format!(" {t:.2} |");
        }
        s += "\n";
    }
    s
}
