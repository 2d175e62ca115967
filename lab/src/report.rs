//! `horizon-lab report`: the join download a built world gives a client. For seeded
//! viewpoints, the unique bytes of every asset in the cut (models of objects, aggregate GLBs),
//! with draw calls and textures, against the naive client (every model of the world) and
//! against unoptimised aggregates (no dedup, QEM on the expanded merge, no atlas), built into
//! `DIR/baseline` on first use by a [`MeasuringStore`].

use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use horizon_aggregate::{
    build_subtrees, AggregateManifest, BuildOptions, ImpostorPolicy, Progress,
};
use horizon_bvh::{Bvh, CutItem, CutQuery};
use horizon_server::outln;
use horizon_server::terminal::ProgressBar;
use horizon_world::World;
use serde::Serialize;

use crate::measuring::MeasuringStore;
use crate::views::viewpoints;

/// `horizon-lab report --json`.
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

/// `horizon-lab report DIR --views V --seed S [--min-solid-angle A] [--json]`.
pub fn run(
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
    let world = World::open(dir)?;
    let tree = world.with_tree(|t| t.clone())?;
    let bvh = &tree.bvh;
    let ours = world
        .published_manifest()?
        .with_context(|| format!("no aggregates in {} (run horizon build)", dir.display()))?;
    // The cuts of the seeded viewpoints.
    let bounds = bvh
        .node(bvh.root())
        .map(|n| n.aabb())
        .context("the world is empty")?;
    let positions: Vec<Vec3> = viewpoints(&bounds, seed, views);
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
    let base_store = MeasuringStore::new(&dir.join("baseline"));
    let models = world.models();
    let baseline_options = BuildOptions {
        aggregate: ours.options.unoptimized(),
        world_textures: models.texture_totals()?,
        impostors: ImpostorPolicy::Off,
    };
    let shown: BTreeSet<u32> = cuts
        .iter()
        .flatten()
        .filter_map(|e| match e.item {
            CutItem::Aggregate(n) => Some(n.0),
            CutItem::Object(_) => None,
        })
        .collect();
    let bar = ProgressBar::new("baseline");
    let outcome = build_subtrees(
        bvh,
        models,
        &base_store,
        &baseline_options,
        &shown,
        &|p: Progress| bar.show(p.done, p.total),
    )?;
    bar.finish();
    base_store.collect_garbage(&outcome.manifest)?;
    let baseline_seconds = if outcome.report.built > 0 {
        t.elapsed().as_secs_f64()
    } else {
        0.0
    };
    let base = outcome.manifest;
    // Assets: models by BVH number (counted from the models already loaded for the
    // baseline, not read again), aggregates by node.
    let rows = models.rows()?;
    let model_assets: Vec<(String, Asset)> = rows
        .iter()
        .map(|m| -> anyhow::Result<(String, Asset)> {
            let mesh = &models.source(m.number)?.mesh;
            Ok((
                m.asset.clone(),
                Asset {
                    bytes: m.bytes,
                    draws: mesh.submeshes.len() as u64,
                    textures: mesh.textures.len() as u64,
                },
            ))
        })
        .collect::<anyhow::Result<_>>()?;
    let naive_bytes: u64 = rows
        .iter()
        .map(|m| (m.asset.as_str(), m.bytes))
        .collect::<HashMap<_, _>>()
        .values()
        .sum();
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
        let a = join(bvh, entries, &model_assets, &ours_assets)?;
        let b = join(bvh, entries, &model_assets, &base_assets)?;
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
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        print_report(dir, &report)?;
    }
    Ok(())
}

fn print_report(dir: &Path, r: &Report) -> std::io::Result<()> {
    let mb = |b: f64| b / 1e6;
    outln!(
        "join download of {} over {} views at Omega_min {}:",
        dir.display(),
        r.views,
        r.min_solid_angle
    )?;
    outln!(
        "  ours:        {:>10.3} MB, {:>8.1} draw calls, {:>7.1} textures",
        mb(r.join_bytes_mean),
        r.draw_calls_mean,
        r.textures_mean
    )?;
    outln!(
        "  unoptimised: {:>10.3} MB, {:>8.1} draw calls, {:>7.1} textures",
        mb(r.unoptimized_join_bytes_mean),
        r.unoptimized_draw_calls_mean,
        r.unoptimized_textures_mean
    )?;
    outln!("  naive:       {:>10.3} MB", mb(r.naive_bytes as f64))?;
    outln!(
        "  reduction: {:.1}% vs naive, {:.1}% vs unoptimised; {:.0} entries per cut, {:.0} aggregates",
        100.0 * r.reduction_vs_naive,
        100.0 * r.reduction_vs_unoptimized,
        r.entries_mean,
        r.aggregates_mean
    )?;
    Ok(())
}

/// The join download of one cut: unique assets' bytes and textures; draw calls per entry.
fn join(
    bvh: &Bvh,
    entries: &[horizon_bvh::CutEntry],
    models: &[(String, Asset)],
    aggregates: &HashMap<u32, (String, Asset)>,
) -> anyhow::Result<Asset> {
    let mut seen_models = BTreeSet::new();
    let mut seen_aggregates = BTreeSet::new();
    let mut out = Asset::default();
    for e in entries {
        match e.item {
            CutItem::Object(o) => {
                let model = bvh.object(o).context("cut names a missing object")?.model() as usize;
                let (asset, a) = models
                    .get(model)
                    .with_context(|| format!("model {model} missing"))?;
                out.draws += a.draws;
                if seen_models.insert(asset.clone()) {
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
