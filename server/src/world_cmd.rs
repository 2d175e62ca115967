//! `horizon build` and `horizon cut`: the offline path over a world directory. Build describes
//! the models, gives them their levels of detail, bulk-builds the similarity-aware BVH and rebuilds every aggregate; cut answers
//! one solid-angle query on what was built.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use horizon_aggregate::{AggregateOptions, ImpostorPolicy, Progress};
use horizon_bvh::{CutItem, CutQuery, EntryKind, ObjectId};
use horizon_server::outln;
use horizon_server::terminal::{note, ProgressBar};
use horizon_world::{RebuildReport, World};
use serde::Serialize;

/// What `horizon build` prints (also as its last stdout line).
#[derive(Debug, Serialize)]
struct BuildSummary {
    objects: usize,
    models: usize,
    descriptors_computed: usize,
    descriptors_reused: usize,
    nodes: usize,
    height: u32,
    load_seconds: f64,
    descriptor_seconds: f64,
    /// Models given their levels of detail by this build.
    levels_computed: usize,
    level_seconds: f64,
    bvh_seconds: f64,
    /// The aggregate stage, unless `--bvh-only`.
    aggregates: Option<RebuildReport>,
}

/// Builds the world in `dir`: descriptors of the models not described yet, the BVH with
/// eq. 1's `mu` and `w` (its snapshot stored), and, unless `aggregates` is `None`, every
/// node's aggregate, published.
pub fn build(
    dir: &Path,
    mu: f32,
    w: f32,
    aggregates: Option<AggregateOptions>,
    impostors: ImpostorPolicy,
    json: bool,
) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let world = World::open(dir)?;
    world.set_impostors(impostors);
    anyhow::ensure!(
        world.is_exclusive(),
        "another process serves or builds {} (stop it first)",
        dir.display()
    );
    let load_seconds = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let bar = ProgressBar::new("describing models");
    let descriptors_computed = world.describe_models(&|done, total| bar.show(done, total))?;
    bar.finish();
    let descriptor_seconds = t1.elapsed().as_secs_f64();

    let t_levels = Instant::now();
    let bar = ProgressBar::new("levels of detail");
    let (levels_computed, failures) = world.level_models(&|done, total| bar.show(done, total))?;
    bar.finish();
    for (name, why) in &failures {
        eprintln!("horizon: {name}: levels of detail stopped early: {why}");
    }
    let level_seconds = t_levels.elapsed().as_secs_f64();

    let t2 = Instant::now();
    note("building the BVH");
    let (objects, nodes, height) = world.build_tree(mu, w)?;
    let bvh_seconds = t2.elapsed().as_secs_f64();

    let aggregates = match aggregates {
        Some(options) => {
            let bar = ProgressBar::new("aggregates");
            let report =
                world.rebuild_aggregates(options, &|p: Progress| bar.show(p.done, p.total))?;
            bar.finish();
            Some(report)
        }
        None => None,
    };

    let models = world.models().len();
    let summary = BuildSummary {
        objects,
        models,
        descriptors_computed,
        descriptors_reused: models - descriptors_computed,
        nodes,
        height,
        load_seconds,
        descriptor_seconds,
        levels_computed,
        level_seconds,
        bvh_seconds,
        aggregates,
    };
    if json {
        outln!("{}", serde_json::to_string(&summary)?)?;
    } else {
        print_summary(dir, &summary)?;
    }
    if let Some(a) = &summary.aggregates {
        if let Some((node, reason)) = a.build.failed.first() {
            anyhow::bail!(
                "{} aggregates failed (first: node {node}: {reason})",
                a.build.failed.len()
            );
        }
    }
    Ok(())
}

fn print_summary(dir: &Path, s: &BuildSummary) -> std::io::Result<()> {
    outln!(
        "built {}: {} objects, {} models ({} described, {} reused, {} levelled), {} nodes, height {}; load {:.2} s, descriptors {:.2} s, levels {:.2} s, bvh {:.2} s",
        dir.display(),
        s.objects,
        s.models,
        s.descriptors_computed,
        s.descriptors_reused,
        s.levels_computed,
        s.nodes,
        s.height,
        s.load_seconds,
        s.descriptor_seconds,
        s.level_seconds,
        s.bvh_seconds,
    )?;
    if let Some(r) = &s.aggregates {
        let a = &r.build;
        let removed = if r.removed_blobs > 0 {
            format!("; {} blobs of earlier builds removed", r.removed_blobs)
        } else {
            String::new()
        };
        outln!(
            "aggregates: {} nodes, {} built, {} reused, {} failed; {:.1} MB written, {:.1} MB in all; {:.1} s{}; generation {} published{removed}",
            a.nodes,
            a.built,
            a.reused,
            a.failed.len(),
            a.bytes_built as f64 / 1e6,
            a.bytes_total as f64 / 1e6,
            a.seconds,
            if a.atlas { ", atlased" } else { "" },
            r.generation,
        )?;
        if let Some(i) = &a.impostors {
            outln!(
                "impostors: {} nodes ({} built, {} ray-cast, {} reused), {} px, {:.1} MB in all ({:.0}% of the aggregates); {:.1} s",
                i.nodes,
                i.built,
                i.rendered,
                i.reused,
                i.resolution,
                i.bytes_total as f64 / 1e6,
                100.0 * i.bytes_total as f64 / a.bytes_total.max(1) as f64,
                i.seconds,
            )?;
            for (node, why) in &i.unreadable {
                outln!(
                    "impostor of node {node} ray-cast: a child's images could not be read: {why}"
                )?;
            }
        }
    }
    Ok(())
}

/// One entry of `horizon cut --json`: an object by its world id, an aggregate by its node.
#[derive(Debug, Serialize)]
struct EntryReport {
    id: u64,
    kind: &'static str,
    parent: Option<u32>,
    covers: u32,
    solid_angle: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    objects: Option<Vec<u64>>,
}

/// What `horizon cut --json` prints.
#[derive(Debug, Serialize)]
struct CutReport {
    entries: Vec<EntryReport>,
    objects: usize,
    aggregates: usize,
    nodes_visited: usize,
    seconds: f64,
}

/// Parses `X,Y,Z`.
pub fn parse_position(text: &str) -> anyhow::Result<Vec3> {
    let parts: Vec<&str> = text.split(',').collect();
    let bad = || anyhow::anyhow!("--pos {text:?} is not X,Y,Z (three finite numbers)");
    if parts.len() != 3 {
        return Err(bad());
    }
    let mut v = [0.0f32; 3];
    for (slot, p) in v.iter_mut().zip(&parts) {
        *slot = p.trim().parse().map_err(|_| bad())?;
        if !slot.is_finite() {
            return Err(bad());
        }
    }
    Ok(Vec3::from_array(v))
}

/// Runs the cut query on the stored snapshot of `dir` and prints the entries (with
/// `explain`, the objects each one covers).
pub fn cut(
    dir: &Path,
    pos: &str,
    min_solid_angle: f32,
    max_results: usize,
    json: bool,
    explain: bool,
) -> anyhow::Result<()> {
    let position = parse_position(pos)?;
    if !(min_solid_angle.is_finite() && min_solid_angle > 0.0) {
        anyhow::bail!("--min-solid-angle {min_solid_angle} must be a positive number");
    }
    if max_results == 0 {
        anyhow::bail!("--max-results must be at least 1");
    }
    let world = World::open(dir)?;
    let query = CutQuery {
        position,
        min_solid_angle,
        max_results,
    };
    let started = Instant::now();
    let result = world.cut(&query)?;
    let seconds = started.elapsed().as_secs_f64();
    let entries: Vec<EntryReport> = world.with_tree(|tree| {
        let mut under = Vec::new();
        let world_id = |o: ObjectId| tree.world_id(o).unwrap_or(u64::from(o.0));
        result
            .entries
            .iter()
            .map(|e| {
                let (id, objects) = match e.item {
                    CutItem::Object(o) => (world_id(o), explain.then(|| vec![world_id(o)])),
                    CutItem::Aggregate(node) => {
                        let objects = explain.then(|| {
                            under.clear();
                            tree.bvh.objects_under(node, &mut under);
                            under.iter().map(|&o| world_id(o)).collect()
                        });
                        (u64::from(node.0), objects)
                    }
                };
                EntryReport {
                    id,
                    kind: match e.kind() {
                        EntryKind::Object => "object",
                        EntryKind::Aggregate => "aggregate",
                    },
                    parent: e.parent.map(|p| p.0),
                    covers: e.covers,
                    solid_angle: e.solid_angle,
                    objects,
                }
            })
            .collect()
    })?;
    let aggregates = entries.iter().filter(|e| e.kind == "aggregate").count();
    let report = CutReport {
        objects: entries.len() - aggregates,
        aggregates,
        entries,
        nodes_visited: result.nodes_visited,
        seconds,
    };
    if json {
        outln!("{}", serde_json::to_string(&report)?)?;
        return Ok(());
    }
    outln!(
        "cut at {position}: {} entries ({} objects, {} aggregates), {} nodes visited, {:.3} ms",
        report.entries.len(),
        report.objects,
        report.aggregates,
        report.nodes_visited,
        seconds * 1e3
    )?;
    for e in &report.entries {
        let parent = e.parent.map_or("-".to_owned(), |p| p.to_string());
        let objects = e
            .objects
            .as_ref()
            .map_or(String::new(), |o| format!(" objects {o:?}"));
        outln!(
            "{} {} parent {parent} covers {} solid angle {:.3e}{objects}",
            e.kind,
            e.id,
            e.covers,
            e.solid_angle
        )?;
    }
    Ok(())
}
