//! `horizon-lab fidelity`: what a cut's image loses against the full world, and what it
//! costs. For seeded views (street level, overhead, outside looking in) it ray-casts the world
//! twice with the same renderer (`horizon_impostor`): every object as its model, and the
//! cut's entries. It reports PSNR, SSIM, the share of pixels off by more than 16 levels and
//! holes, and for both the bytes to download, the draw calls (placements batched by asset,
//! as a viewer draws them) and the triangles; and for every aggregate in the cut, the
//! intersection over union of its bounds with those of the objects it covers.

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use glam::{Affine3A, Vec3};
use horizon_bvh::{Aabb, NodeId, DEFAULT_MIN_SOLID_ANGLE};
use horizon_impostor::{compare, Camera, Comparison, PreparedMesh, SceneBuilder};
use horizon_mesh::rng::Rng;
use horizon_mesh::{import_bytes, Format, ImportOptions};
use horizon_protocol::{Budgets, Entry, EntryKind, View};
use horizon_server::outln;
use horizon_server::service::cut::{plan, plan_stopping, plan_with, AssetTable, Coarsening};
use horizon_world::World;
use serde::Serialize;

use crate::views::{viewpoints, EYE_HEIGHT};

/// `horizon-lab fidelity`'s arguments.
#[derive(Clone, Debug, clap::Args)]
pub struct Args {
    /// The built world directory.
    pub dir: PathBuf,
    /// Street-level views (one overhead and one outside view are always added).
    #[arg(long, default_value_t = 2)]
    pub street: usize,
    /// Seed of the views.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Image width, pixels.
    #[arg(long, default_value_t = 960)]
    pub width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 540)]
    pub height: u32,
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub fov: f32,
    /// Rays per pixel along each axis (2: four rays per pixel).
    #[arg(long, default_value_t = 2)]
    pub samples: u32,
    /// The cut's smallest solid angle shown as itself.
    #[arg(long, default_value_t = DEFAULT_MIN_SOLID_ANGLE)]
    pub min_solid_angle: f64,
    /// The cut's most entries.
    #[arg(long, default_value_t = horizon_bvh::DEFAULT_MAX_RESULTS as u64)]
    pub max_entries: u64,
    /// The cut's draw-call budget.
    #[arg(long)]
    pub max_draw_calls: Option<u64>,
    /// The cut's triangle budget. Under one, every object keeps its own level of detail
    /// instead of the finest its model needs anywhere in the cut.
    #[arg(long)]
    pub max_triangles: Option<u64>,
    /// The cut's byte budget (each asset counted once).
    #[arg(long)]
    pub max_bytes: Option<u64>,
    /// Also plan, render and measure each view's cut with levels coarsened where a byte,
    /// draw-call or triangle budget binds (`Coarsening::Search`, which the service does not
    /// do), against the service's cut in the same run.
    #[arg(long)]
    pub coarsen_peer: bool,
    /// Also plan, render and measure each view's cut with refinement stopped at the first
    /// refinement a byte, draw-call or triangle budget refuses (`plan_stopping`; the service
    /// goes on past it), against the service's cut in the same run.
    #[arg(long)]
    pub stop_peer: bool,
    /// The geometric error, in pixels, an object's level of detail may show (0: every
    /// object at full detail).
    #[arg(long, default_value_t = horizon_protocol::DEFAULT_MAX_PIXEL_ERROR)]
    pub max_pixel_error: f64,
    /// Also plan, render and measure each view's cut without levels of detail (every object
    /// at level 0), the peer the levels are compared with in the same run.
    #[arg(long)]
    pub levels_peer: bool,
    /// Plan cuts with orthoview impostors (drawn as splats, `Orthoview::splats`), and also
    /// plan, render and measure each view's cut without them, the peer they are compared
    /// with in the same run. With `--node`: the node's impostor against its aggregate, each
    /// alone, at the impostor's handover distance for this image's pixel.
    #[arg(long)]
    pub impostors: bool,
    /// Also plan, render and measure each view's cut without instances entries (every node
    /// as its aggregate or impostor), the peer the reuse-aware cut is compared with in the
    /// same run.
    #[arg(long)]
    pub instances_peer: bool,
    /// Instead of seeded views: render node N's aggregate alone against the objects it covers
    /// alone, from above at 45 degrees and at the node's nearest display distance (times
    /// `--node-distance`).
    #[arg(long)]
    pub node: Option<u32>,
    /// With `--node`: the camera's distance as a multiple of the nearest display distance
    /// (below 1: nearer than the aggregate was built to be seen, as when a budget binds).
    #[arg(long, default_value_t = 1.0)]
    pub node_distance: f32,
    /// Also write the report as JSON to this file (one run for the table and the JSON).
    #[arg(long)]
    pub json_out: Option<PathBuf>,
    /// Folder to write each view's renders (full, cut, difference) into as PNG.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Plan and cost every view and check every aggregate's bounds, but render nothing
    /// (PSNR, SSIM and holes are left out): for worlds whose full detail does not fit the
    /// renderer's memory, such as 60,000 distinct buildings.
    #[arg(long, conflicts_with_all = ["node", "images", "levels_peer"])]
    pub no_render: bool,
}

/// One view's figures.
#[derive(Clone, Debug, Serialize)]
pub struct ViewReport {
    /// `street-1`, `overhead`, `outside`.
    pub name: String,
    /// The eye.
    pub eye: [f32; 3],
    /// The cut against the full world.
    pub psnr: f64,
    /// Mean SSIM of luma.
    pub ssim: f64,
    /// Share of pixels off by more than 16 levels.
    pub off16: f64,
    /// Share of the image the full world covers and the cut leaves to the sky.
    pub holes: f64,
    /// The full world: every model once.
    pub full: Cost,
    /// The cut.
    pub cut: Cost,
    /// Entries of the cut, and how many are aggregates.
    pub entries: usize,
    /// Aggregate entries.
    pub aggregates: usize,
    /// Bounds IoU of the cut's aggregates with what they cover: median, lowest, and how many
    /// fall under 0.9.
    pub iou_median: f64,
    /// Lowest IoU.
    pub iou_min: f64,
    /// Aggregates with IoU under 0.9.
    pub iou_under_0_9: usize,
    /// The five aggregates covering the most objects: entry id and objects covered.
    pub largest: Vec<(String, u64)>,
    /// The five aggregates of lowest IoU: entry id and IoU.
    pub iou_worst: Vec<(String, f64)>,
    /// Seconds to render both.
    pub render_seconds: f64,
    /// The same cut without levels of detail, with `--levels-peer`.
    pub flat: Option<FlatReport>,
    /// The same cut without impostors, with `--impostors`.
    pub meshes_only: Option<FlatReport>,
    /// The same cut without instances entries, with `--instances-peer`.
    pub aggregates_only: Option<FlatReport>,
    /// The same cut with levels coarsened where a budget binds, with `--coarsen-peer`.
    pub coarsened_cut: Option<FlatReport>,
    /// The same cut stopped at the first refusal, with `--stop-peer`.
    pub stopped_cut: Option<FlatReport>,
    /// Refusals the service's cut went on past.
    pub skipped: usize,
    /// How many times wider than the image's pixel its levels were chosen for, where a
    /// budget bound (`Plan::coarsened`).
    pub coarsened: Option<f32>,
    /// Object entries of the cut (each an object drawn as itself).
    pub object_entries: usize,
    /// Milliseconds to plan the coarsened cut (the median of five), with `--coarsen-peer`.
    pub plan_ms_coarsened: Option<f64>,
    /// The same for the cut stopped at the first refusal, with `--stop-peer`.
    pub plan_ms_stopping: Option<f64>,
    /// Instances entries of the cut.
    pub instance_entries: usize,
    /// Milliseconds to plan the cut and make its entries (the median of five).
    pub plan_ms: f64,
    /// The same for the cut without instances, with `--instances-peer`.
    pub plan_ms_without_instances: Option<f64>,
    /// Impostor entries of the cut.
    pub impostors: usize,
    /// With `--node` and `--impostors`: PSNR of the node's impostor against its aggregate.
    pub against_aggregate: Option<f64>,
    /// What the cut's object entries alone cost: the floor of any change to how nodes are
    /// drawn (objects that subtend `min_solid_angle` are always sent as themselves).
    pub objects_alone: Cost,
    /// Object entries drawn at a level above 0.
    pub levelled: usize,
}

/// The cut without levels of detail at the same view, against the full world.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FlatReport {
    /// PSNR against the full world.
    pub psnr: f64,
    /// SSIM against the full world.
    pub ssim: f64,
    /// Holes.
    pub holes: f64,
    /// What it costs.
    pub cost: Cost,
    /// Its object entries.
    pub object_entries: usize,
    /// Its entries.
    pub entries: usize,
}

/// What drawing a set of entries costs a client.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Cost {
    /// Unique asset bytes.
    pub bytes: u64,
    /// Draw calls, every asset's placements batched into one instanced draw per submesh.
    pub draw_calls: u64,
    /// Triangles drawn.
    pub triangles: u64,
    /// The entries as JSON (what `GET /v1/cut` sends), bytes: for the full world, the
    /// placements a naive client needs besides the models.
    pub entries_json: u64,
    /// The same, zstd-compressed at level 3 (the server compresses answers by
    /// `Accept-Encoding`).
    pub entries_zstd: u64,
}

/// The whole run.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The world directory.
    pub world: String,
    /// Objects in the world.
    pub objects: usize,
    /// Image size and rays per pixel.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Rays per pixel along each axis.
    pub samples: u32,
    /// The cut's parameters.
    pub min_solid_angle: f64,
    /// Most entries.
    pub max_entries: u64,
    /// Draw-call budget.
    pub max_draw_calls: Option<u64>,
    /// Triangle budget.
    pub max_triangles: Option<u64>,
    /// Byte budget.
    pub max_bytes: Option<u64>,
    /// Pixels of error a level of detail may show.
    pub max_pixel_error: f64,
    /// Per view.
    pub views: Vec<ViewReport>,
}

/// Runs the measure and prints its table (or JSON).
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    let report = measure(args)?;
    if let Some(path) = &args.json_out {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        print_table(&report)?;
    }
    Ok(())
}

/// The stages: open the world, plan the full world once, then per view plan the cut, render
/// both and compare.
pub fn measure(args: &Args) -> anyhow::Result<Report> {
    anyhow::ensure!(args.samples >= 1, "--samples must be at least 1");
    let world = World::open(&args.dir).with_context(|| format!("open {}", args.dir.display()))?;
    if let Some(node) = args.node {
        let manifest = world.published_manifest()?;
        anyhow::ensure!(
            manifest.is_some_and(|m| m.nodes.contains_key(&node)),
            "node {node} has no published aggregate"
        );
    }
    let table = AssetTable::default();
    table.refresh(&world)?;
    let bounds = world.with_tree(|t| {
        let bvh = &t.bvh;
        bvh.node(bvh.root()).map(|n| n.aabb())
    })?;
    let bounds = bounds.context("the world has no objects")?;
    let mut assets = Assets::new(&world, &table);

    // The full world: a cut that refines everything.
    let mut everything = View::at([0.0; 3]);
    everything.min_solid_angle = 1e-12;
    everything.max_pixel_error = 0.0;
    everything.instances = false;
    everything.budgets = Budgets {
        max_entries: Some(horizon_protocol::MAX_ENTRIES_LIMIT),
        ..Budgets::default()
    };
    let full_entries = world.with_served(|s| plan(s, &table, &everything).entries())?;
    let full_scene = if args.no_render {
        None
    } else {
        Some(assets.scene(&full_entries)?)
    };
    let full_cost = assets.cost(&full_entries);
    let object_boxes = assets.object_boxes(&full_entries)?;
    eprintln!(
        "full world: {} objects, {} placed submeshes",
        full_entries.len(),
        full_scene.as_ref().map_or(0, |s| s.items())
    );

    if let Some(node) = args.node {
        return focus(
            args,
            &world,
            &mut assets,
            &full_entries,
            &object_boxes,
            node,
        );
    }
    let mut views = Vec::new();
    for (name, camera) in cameras(&bounds, args) {
        let mut view = View::at(camera.eye.to_array().map(f64::from));
        view.min_solid_angle = args.min_solid_angle;
        view.max_pixel_error = args.max_pixel_error;
        view.impostors = args.impostors;
        // The rendered image's own pixel, so that levels of detail are chosen for it.
        view.pixel_solid_angle = f64::from(args.fov.to_radians() / args.height as f32).powi(2);
        view.budgets = Budgets {
            max_entries: Some(args.max_entries),
            max_draw_calls: args.max_draw_calls,
            max_triangles: args.max_triangles,
            max_bytes: args.max_bytes,
        };
        let ((cut_entries, skipped), plan_ms) = timed(|| {
            world.with_served(|s| {
                let p = plan(s, &table, &view);
                (p.entries(), p.skipped)
            })
        })?;
        let (plain_entries, plain_plan_ms) = if args.instances_peer {
            let plain = View {
                instances: false,
                ..view
            };
            let (entries, ms) = timed_plan(&world, &table, &plain)?;
            (Some(entries), Some(ms))
        } else {
            (None, None)
        };
        let mut costs = costed(
            &world,
            &mut assets,
            &name,
            &camera,
            &cut_entries,
            full_cost,
            &object_boxes,
        )?;
        costs.plan_ms = plan_ms;
        costs.skipped = skipped;
        costs.plan_ms_without_instances = plain_plan_ms;
        let Some(full_scene) = &full_scene else {
            costs.aggregates_only = plain_entries.map(|e| FlatReport {
                psnr: f64::NAN,
                ssim: f64::NAN,
                holes: f64::NAN,
                cost: assets.cost(&e),
                object_entries: objects_in(&e),
                entries: e.len(),
            });
            eprintln!(
                "{name}: {} entries ({} aggregates, {} impostors), {:.1} MB",
                costs.entries,
                costs.aggregates,
                costs.impostors,
                costs.cut.bytes as f64 / 1e6
            );
            views.push(costs);
            continue;
        };
        let flat = if args.levels_peer {
            let flat_view = View {
                max_pixel_error: 0.0,
                ..view
            };
            let flat_entries = world.with_served(|s| plan(s, &table, &flat_view).entries())?;
            let frame = assets.scene(&flat_entries)?.render(&camera, args.samples);
            Some((flat_entries, frame))
        } else {
            None
        };
        let meshes_only = if args.impostors {
            let mesh_view = View {
                impostors: false,
                ..view
            };
            let entries = world.with_served(|s| plan(s, &table, &mesh_view).entries())?;
            let frame = assets.scene(&entries)?.render(&camera, args.samples);
            Some((entries, frame))
        } else {
            None
        };
        let coarsened_cut = if args.coarsen_peer {
            let ((entries, coarsened), ms) = timed(|| {
                world.with_served(|s| {
                    let p = plan_with(s, &table, &view, None, Coarsening::Search);
                    (p.entries(), p.coarsened)
                })
            })?;
            costs.plan_ms_coarsened = Some(ms);
            costs.coarsened = coarsened;
            let frame = assets.scene(&entries)?.render(&camera, args.samples);
            Some((entries, frame))
        } else {
            None
        };
        let stopped_cut = if args.stop_peer {
            let (entries, ms) =
                timed(|| world.with_served(|s| plan_stopping(s, &table, &view).entries()))?;
            costs.plan_ms_stopping = Some(ms);
            let frame = assets.scene(&entries)?.render(&camera, args.samples);
            Some((entries, frame))
        } else {
            None
        };
        let aggregates_only = match plain_entries {
            Some(entries) => {
                let frame = assets.scene(&entries)?.render(&camera, args.samples);
                Some((entries, frame))
            }
            None => None,
        };
        let cut_scene = assets.scene(&cut_entries)?;
        let started = Instant::now();
        let full = full_scene.render(&camera, args.samples);
        let cut = cut_scene.render(&camera, args.samples);
        let render_seconds = started.elapsed().as_secs_f64();
        let Comparison {
            psnr,
            ssim,
            off16,
            holes,
        } = compare(&full, &cut);
        let peer = |(entries, frame): (Vec<Entry>, horizon_impostor::Frame)| {
            let c = compare(&full, &frame);
            FlatReport {
                psnr: c.psnr,
                ssim: c.ssim,
                holes: c.holes,
                cost: assets.cost(&entries),
                object_entries: objects_in(&entries),
                entries: entries.len(),
            }
        };
        let flat = flat.map(peer);
        let meshes_only = meshes_only.map(peer);
        let aggregates_only = aggregates_only.map(peer);
        let coarsened_cut = coarsened_cut.map(peer);
        let stopped_cut = stopped_cut.map(peer);
        if let Some(dir) = &args.images {
            std::fs::create_dir_all(dir)?;
            full.save_png(&dir.join(format!("{name}-full.png")))?;
            cut.save_png(&dir.join(format!("{name}-cut.png")))?;
            difference(&full, &cut).save(dir.join(format!("{name}-diff.png")))?;
        }
        let report = ViewReport {
            psnr,
            ssim,
            off16,
            holes,
            render_seconds,
            flat,
            meshes_only,
            aggregates_only,
            coarsened_cut,
            stopped_cut,
            ..costs
        };
        eprintln!(
            "{name}: PSNR {psnr:.1} dB, SSIM {ssim:.4}, holes {:.3}%, {} entries ({} aggregates), {:.1} s",
            holes * 100.0,
            report.entries,
            report.aggregates,
            render_seconds
        );
        views.push(report);
    }
    Ok(Report {
        world: args.dir.display().to_string(),
        objects: full_entries.len(),
        width: args.width,
        height: args.height,
        samples: args.samples,
        min_solid_angle: args.min_solid_angle,
        max_entries: args.max_entries,
        max_draw_calls: args.max_draw_calls,
        max_triangles: args.max_triangles,
        max_bytes: args.max_bytes,
        max_pixel_error: args.max_pixel_error,
        views,
    })
}

/// How many entries are objects drawn as themselves.
fn objects_in(entries: &[Entry]) -> usize {
    entries
        .iter()
        .filter(|e| e.kind == EntryKind::Object)
        .count()
}

/// Plans `view` five times; its entries and the median milliseconds a plan took.
fn timed_plan(world: &World, table: &AssetTable, view: &View) -> anyhow::Result<(Vec<Entry>, f64)> {
    timed(|| world.with_served(|s| plan(s, table, view).entries()))
}

/// Runs `plan` five times; what it made the last time and the median milliseconds it took.
fn timed<T, E>(plan: impl Fn() -> Result<T, E>) -> anyhow::Result<(T, f64)>
where
    anyhow::Error: From<E>,
{
    let mut times = Vec::with_capacity(5);
    let mut made = None;
    for _ in 0..5 {
        let started = Instant::now();
        made = Some(plan()?);
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let made = made.ok_or_else(|| anyhow::anyhow!("nothing was planned"))?;
    Ok((made, times[2]))
}

/// A view's report without its images: its costs and its aggregates' bounds, with PSNR,
/// SSIM, pixels off and holes not measured (NaN) until the caller renders.
fn costed(
    world: &World,
    assets: &mut Assets<'_>,
    name: &str,
    camera: &Camera,
    cut_entries: &[Entry],
    full: Cost,
    object_boxes: &HashMap<u64, Aabb>,
) -> anyhow::Result<ViewReport> {
    let ious = world.with_served(|s| assets.ious(s.tree, cut_entries, object_boxes))??;
    let mut worst: Vec<(String, f64)> = ious.clone();
    worst.sort_by(|a, b| a.1.total_cmp(&b.1));
    worst.truncate(5);
    let mut sorted: Vec<f64> = ious.iter().map(|i| i.1).collect();
    sorted.sort_by(f64::total_cmp);
    let objects: Vec<Entry> = cut_entries
        .iter()
        .filter(|e| e.kind == EntryKind::Object)
        .cloned()
        .collect();
    Ok(ViewReport {
        name: name.to_string(),
        eye: camera.eye.to_array(),
        psnr: f64::NAN,
        ssim: f64::NAN,
        off16: f64::NAN,
        holes: f64::NAN,
        full,
        cut: assets.cost(cut_entries),
        entries: cut_entries.len(),
        aggregates: ious.len(),
        iou_median: sorted.get(sorted.len() / 2).copied().unwrap_or(1.0),
        iou_min: sorted.first().copied().unwrap_or(1.0),
        iou_under_0_9: sorted.iter().filter(|&&v| v < 0.9).count(),
        iou_worst: worst,
        largest: largest(cut_entries),
        render_seconds: 0.0,
        flat: None,
        meshes_only: None,
        aggregates_only: None,
        coarsened_cut: None,
        stopped_cut: None,
        skipped: 0,
        plan_ms_stopping: None,
        coarsened: None,
        object_entries: objects_in(cut_entries),
        plan_ms_coarsened: None,
        plan_ms: f64::NAN,
        plan_ms_without_instances: None,
        instance_entries: cut_entries
            .iter()
            .filter(|e| e.kind == EntryKind::Instances)
            .count(),
        impostors: cut_entries
            .iter()
            .filter(|e| e.kind == EntryKind::Impostor)
            .count(),
        against_aggregate: None,
        objects_alone: assets.cost(&objects),
        levelled: cut_entries.iter().filter(|e| e.level > 0).count(),
    })
}

/// One aggregate against what it covers, each alone, from above at 45 degrees, from as near
/// as an unbudgeted cut shows the aggregate (times `--node-distance`).
fn focus(
    args: &Args,
    world: &World,
    assets: &mut Assets<'_>,
    full: &[Entry],
    boxes: &HashMap<u64, Aabb>,
    node: u32,
) -> anyhow::Result<Report> {
    let manifest = world
        .published_manifest()?
        .context("the world has no published aggregates")?;
    let aggregate = manifest
        .nodes
        .get(&node)
        .with_context(|| format!("node {node} has no aggregate"))?
        .clone();
    let (covered, sphere, r_max) = world.with_served(|s| {
        let mut under = Vec::new();
        s.tree.bvh.objects_under(NodeId(node), &mut under);
        let covered: HashSet<u64> = under.iter().filter_map(|&o| s.tree.world_id(o)).collect();
        let n = s.tree.bvh.node(NodeId(node));
        (covered, n.map(|n| n.bound()), n.map_or(0.0, |n| n.r_max()))
    })?;
    let sphere = sphere.with_context(|| format!("node {node} is not in the tree"))?;
    let objects: Vec<Entry> = full
        .iter()
        .filter(|e| object_id(&e.id).is_some_and(|id| covered.contains(&id)))
        .cloned()
        .collect();
    let mut bounds = Aabb::EMPTY;
    for e in &objects {
        if let Some(b) = object_id(&e.id).and_then(|id| boxes.get(&id)) {
            bounds = bounds.union(*b);
        }
    }
    anyhow::ensure!(!bounds.is_empty(), "node {node} covers no object");
    let centre = (bounds.min + bounds.max) * 0.5;
    let display = horizon_aggregate::budget::Display::of(
        sphere.centre,
        sphere.radius,
        r_max,
        &manifest.options,
    );
    let mut distance = (display.radius + display.distance) as f32;
    // With `--impostors`: the node's impostor at its handover distance for this image's
    // pixel, against its aggregate there.
    let impostor = if args.impostors {
        let imp = manifest
            .impostors
            .get(&node)
            .with_context(|| format!("node {node} has no impostor"))?;
        let pixel_angle = args.fov.to_radians() / args.height as f32;
        let outer =
            world.with_served(|s| s.tree.bvh.node(NodeId(node)).map(|n| n.outer_sphere()))?;
        let outer = outer.with_context(|| format!("node {node} is not in the tree"))?;
        distance = imp.pixel() / pixel_angle + outer.radius + (outer.centre - centre).length();
        Some(imp.clone())
    } else {
        None
    };
    let distance = distance * args.node_distance;
    let eye = centre + Vec3::new(0.0, distance, distance) * std::f32::consts::FRAC_1_SQRT_2;
    let camera = Camera::look_at(eye, centre, args.width, args.height, args.fov);
    let (hash, bytes) = (aggregate.glb.clone(), aggregate.stats.bytes as u64);
    let mut drawn = vec![Entry {
        id: format!("n:{node}@{hash}"),
        kind: EntryKind::Aggregate,
        assets: vec![horizon_protocol::Asset {
            hash: hash.clone(),
            bytes,
            role: horizon_protocol::AssetRole::Mesh,
        }],
        placements: vec![horizon_protocol::Placement {
            asset: hash,
            matrix: Affine3A::IDENTITY.to_cols_array(),
        }],
        level: 0,
        pending: false,
        bytes,
        triangles: aggregate.stats.triangles_out,
        draw_calls: aggregate.stats.submeshes.max(1) as u64,
        center: centre.to_array(),
        radius: 0.0,
        impostor: None,
        covers: objects.len() as u64,
    }];
    let mut aggregate_entries = None;
    if let Some(imp) = &impostor {
        // The impostor's facing views are drawn; the aggregate is measured beside it.
        aggregate_entries = Some(std::mem::take(&mut drawn));
        let directions: Vec<[i8; 3]> = imp.views.iter().map(|v| v.direction).collect();
        let views = horizon_impostor::facing(&directions, centre - eye)
            .into_iter()
            .map(|i| horizon_server::service::cut::wire_view(&imp.views[i]))
            .collect();
        drawn = vec![Entry {
            id: format!("n:{node}@{}", imp.key),
            kind: EntryKind::Impostor,
            assets: Vec::new(),
            placements: Vec::new(),
            level: 0,
            pending: false,
            bytes: imp.bytes(),
            triangles: 0,
            draw_calls: 0,
            center: centre.to_array(),
            radius: 0.0,
            impostor: Some(horizon_protocol::Impostor {
                min: imp.min,
                max: imp.max,
                views,
            }),
            covers: objects.len() as u64,
        }];
    }
    let started = Instant::now();
    let reference = assets.scene(&objects)?.render(&camera, args.samples);
    let test = assets.scene(&drawn)?.render(&camera, args.samples);
    let mut against_aggregate = None;
    let meshes_only = match &aggregate_entries {
        Some(entries) => {
            let frame = assets.scene(entries)?.render(&camera, args.samples);
            against_aggregate = Some(compare(&frame, &test).psnr);
            if let Some(dir) = &args.images {
                std::fs::create_dir_all(dir)?;
                frame.save_png(&dir.join(format!("node-{node}-aggregate.png")))?;
            }
            let c = compare(&reference, &frame);
            Some(FlatReport {
                psnr: c.psnr,
                ssim: c.ssim,
                holes: c.holes,
                cost: assets.cost(entries),
                object_entries: objects_in(entries),
                entries: entries.len(),
            })
        }
        None => None,
    };
    let render_seconds = started.elapsed().as_secs_f64();
    let c = compare(&reference, &test);
    let name = format!("node-{node}");
    if let Some(dir) = &args.images {
        std::fs::create_dir_all(dir)?;
        reference.save_png(&dir.join(format!("{name}-full.png")))?;
        test.save_png(&dir.join(format!("{name}-cut.png")))?;
        difference(&reference, &test).save(dir.join(format!("{name}-diff.png")))?;
    }
    let ious = world.with_served(|s| assets.ious(s.tree, &drawn, boxes))??;
    let iou = ious.first().map_or(0.0, |i| i.1);
    Ok(Report {
        world: args.dir.display().to_string(),
        objects: full.len(),
        width: args.width,
        height: args.height,
        samples: args.samples,
        min_solid_angle: args.min_solid_angle,
        max_entries: args.max_entries,
        max_draw_calls: args.max_draw_calls,
        max_triangles: args.max_triangles,
        max_bytes: args.max_bytes,
        max_pixel_error: args.max_pixel_error,
        views: vec![ViewReport {
            name,
            eye: eye.to_array(),
            psnr: c.psnr,
            ssim: c.ssim,
            off16: c.off16,
            holes: c.holes,
            full: assets.cost(&objects),
            cut: assets.cost(&drawn),
            entries: 1,
            aggregates: 1,
            iou_median: iou,
            iou_min: iou,
            iou_under_0_9: usize::from(iou < 0.9),
            iou_worst: ious,
            largest: largest(&drawn),
            render_seconds,
            flat: None,
            meshes_only,
            aggregates_only: None,
            coarsened_cut: None,
            stopped_cut: None,
            skipped: 0,
            plan_ms_stopping: None,
            coarsened: None,
            object_entries: objects_in(&drawn),
            plan_ms_coarsened: None,
            instance_entries: 0,
            plan_ms: f64::NAN,
            plan_ms_without_instances: None,
            impostors: usize::from(impostor.is_some()),
            against_aggregate,
            objects_alone: Cost::default(),
            levelled: drawn.iter().filter(|e| e.level > 0).count(),
        }],
    })
}

/// The seeded views: `street` at eye height looking along a seeded heading, one overhead
/// looking down at 55 degrees, one outside the world looking at its centre.
fn cameras(bounds: &Aabb, args: &Args) -> Vec<(String, Camera)> {
    let (w, h, fov) = (args.width, args.height, args.fov);
    let mut rng = Rng::new(args.seed ^ 0x5eed_f1de);
    let centre = (bounds.min + bounds.max) * 0.5;
    let extent = (bounds.max.x - bounds.min.x).max(bounds.max.z - bounds.min.z);
    let mut out = Vec::new();
    for (k, eye) in viewpoints(bounds, args.seed, args.street)
        .into_iter()
        .enumerate()
    {
        let yaw = rng.unit() * std::f32::consts::TAU;
        let target = eye + Vec3::new(yaw.cos(), -0.05, yaw.sin());
        out.push((
            format!("street-{}", k + 1),
            Camera::look_at(eye, target, w, h, fov),
        ));
    }
    let yaw = rng.unit() * std::f32::consts::TAU;
    let ground = Vec3::new(
        centre.x + (rng.unit() - 0.5) * 0.5 * extent,
        0.0,
        centre.z + (rng.unit() - 0.5) * 0.5 * extent,
    );
    let height = 0.15 * extent + EYE_HEIGHT;
    let back = height / 55f32.to_radians().tan();
    let eye = ground + Vec3::new(-yaw.cos() * back, height, -yaw.sin() * back);
    out.push((
        "overhead".to_string(),
        Camera::look_at(eye, ground, w, h, fov),
    ));
    let angle = rng.unit() * std::f32::consts::TAU;
    let eye = Vec3::new(
        centre.x + angle.cos() * 0.9 * extent,
        0.2 * extent,
        centre.z + angle.sin() * 0.9 * extent,
    );
    let target = Vec3::new(centre.x, 0.0, centre.z);
    out.push((
        "outside".to_string(),
        Camera::look_at(eye, target, w, h, fov),
    ));
    out
}

/// The five aggregate entries that cover the most objects.
fn largest(entries: &[Entry]) -> Vec<(String, u64)> {
    let mut out: Vec<(String, u64)> = entries
        .iter()
        .filter(|e| e.kind == EntryKind::Aggregate)
        .map(|e| (e.id.clone(), e.covers))
        .collect();
    out.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    out.truncate(5);
    out
}

/// Prepared assets by hash, loaded from the world's blobs on first use.
struct Assets<'w> {
    world: &'w World,
    /// Draw calls of every model level, by hash (an instances entry's draw calls are its
    /// assets', some of which other entries may already draw).
    calls: HashMap<String, u64>,
    prepared: HashMap<String, (Arc<PreparedMesh>, horizon_mesh::Aabb)>,
    /// Bounds of assets read only for their bounds (not prepared to render).
    bounds: HashMap<String, horizon_mesh::Aabb>,
}

impl<'w> Assets<'w> {
    fn new(world: &'w World, table: &AssetTable) -> Self {
        let calls = table
            .models()
            .iter()
            .flatten()
            .flat_map(|m| m.levels.iter().map(|l| (l.hash.clone(), l.draw_calls)))
            .collect();
        Self {
            world,
            calls,
            prepared: HashMap::new(),
            bounds: HashMap::new(),
        }
    }

    /// Costs of a set of entries: unique assets' bytes and draw calls, every entry's
    /// triangles.
    fn cost(&self, entries: &[Entry]) -> Cost {
        let mut seen = HashSet::new();
        let json = serde_json::to_vec(entries).unwrap_or_default();
        let mut out = Cost {
            entries_json: json.len() as u64,
            entries_zstd: zstd::bulk::compress(&json, 3).map_or(0, |z| z.len() as u64),
            ..Cost::default()
        };
        for e in entries {
            out.triangles += e.triangles;
            // A preview (an object's coarsest level, for progressive loading) is not what the
            // entry draws once loaded: it is left out, as the entry's `bytes` leave it out.
            let fresh: Vec<_> = e
                .assets
                .iter()
                .filter(|a| a.role != horizon_protocol::AssetRole::Preview)
                .filter(|a| seen.insert(a.hash.clone()))
                .collect();
            out.bytes += fresh.iter().map(|a| a.bytes).sum::<u64>();
            // An entry's draw calls are its assets' submeshes; an asset already drawn adds
            // no call, its placements join the same instanced draw. Instances name several
            // assets, each with its own calls.
            if e.kind == EntryKind::Instances {
                out.draw_calls += fresh
                    .iter()
                    .map(|a| self.calls.get(&a.hash).copied().unwrap_or(1))
                    .sum::<u64>();
            } else if !fresh.is_empty() {
                out.draw_calls += e.draw_calls;
            }
        }
        out
    }

    /// An asset's local bounds, without preparing it to render unless it already is.
    fn bounds(&mut self, hash: &str) -> anyhow::Result<horizon_mesh::Aabb> {
        if let Some(p) = self.prepared.get(hash) {
            return Ok(p.1);
        }
        if let Some(b) = self.bounds.get(hash) {
            return Ok(*b);
        }
        let b = self.import(hash)?.bounds();
        self.bounds.insert(hash.to_string(), b);
        Ok(b)
    }

    /// An asset read from the world's blobs.
    fn import(&self, hash: &str) -> anyhow::Result<horizon_mesh::InstancedMesh> {
        let bytes = self
            .world
            .blob(hash)?
            .with_context(|| format!("asset {hash} is not in the world's blobs"))?;
        Ok(
            import_bytes(&bytes, Format::Glb, None, &ImportOptions::trusted())
                .with_context(|| format!("asset {hash}"))?
                .mesh,
        )
    }

    fn get(&mut self, hash: &str) -> anyhow::Result<(Arc<PreparedMesh>, horizon_mesh::Aabb)> {
        if let Some(p) = self.prepared.get(hash) {
            return Ok(p.clone());
        }
        let mesh = self.import(hash)?;
        let made = (Arc::new(PreparedMesh::new(&mesh)), mesh.bounds());
        self.prepared.insert(hash.to_string(), made.clone());
        Ok(made)
    }

    /// The scene of `entries`: every placement of every asset.
    fn scene(&mut self, entries: &[Entry]) -> anyhow::Result<horizon_impostor::Scene> {
        let mut builder = SceneBuilder::default();
        let mut numbers: HashMap<String, usize> = HashMap::new();
        for e in entries {
            if let Some(imp) = &e.impostor {
                for v in &imp.views {
                    builder.add(&self.splats(imp, v)?, &Affine3A::IDENTITY);
                }
            }
            for p in &e.placements {
                let number = match numbers.get(&p.asset) {
                    Some(&n) => n,
                    None => {
                        let n = builder.register(self.get(&p.asset)?.0);
                        numbers.insert(p.asset.clone(), n);
                        n
                    }
                };
                builder.add_registered(number, &affine(&p.matrix));
            }
        }
        Ok(builder.build())
    }

    /// An impostor view's splats, ready to ray-cast (kept by its colour image's hash).
    fn splats(
        &mut self,
        imp: &horizon_protocol::Impostor,
        v: &horizon_protocol::ImpostorView,
    ) -> anyhow::Result<Arc<PreparedMesh>> {
        let key = format!(
            "splats:{}:{}:{}:{:?}:{:?}:{:?}",
            v.color, v.depth, v.normal, v.direction, imp.min, imp.max
        );
        if let Some(p) = self.prepared.get(&key) {
            return Ok(p.0.clone());
        }
        let mut images = Vec::with_capacity(3);
        for hash in [&v.color, &v.depth, &v.normal] {
            images.push(
                self.world
                    .blob(hash)?
                    .with_context(|| format!("orthoview image {hash} is not stored"))?,
            );
        }
        let images: [Vec<u8>; 3] = images
            .try_into()
            .map_err(|_| anyhow::anyhow!("three images"))?;
        let bounds = horizon_mesh::Aabb {
            min: Vec3::from(imp.min),
            max: Vec3::from(imp.max),
        };
        let view = horizon_impostor::Orthoview::decode(&bounds, v.direction, &images)
            .map_err(|e| anyhow::anyhow!("orthoview {}: {e}", v.color))?;
        let mesh = view.splats();
        let made = (Arc::new(PreparedMesh::new(&mesh)), mesh.bounds());
        self.prepared.insert(key, made.clone());
        Ok(made.0)
    }

    /// Every object's exact world box, by world object id (from the full world's entries).
    fn object_boxes(&mut self, entries: &[Entry]) -> anyhow::Result<HashMap<u64, Aabb>> {
        let mut out = HashMap::new();
        for e in entries.iter().filter(|e| e.kind == EntryKind::Object) {
            let id = object_id(&e.id).with_context(|| format!("entry id {}", e.id))?;
            let mut b = Aabb::EMPTY;
            for p in &e.placements {
                let local = self.bounds(&p.asset)?;
                b = b.union(world_box(&local, &affine(&p.matrix)));
            }
            out.insert(id, b);
        }
        Ok(out)
    }

    /// Bounds IoU of every aggregate entry of a cut with the objects its node covers.
    fn ious(
        &mut self,
        tree: &horizon_world::Tree,
        entries: &[Entry],
        objects: &HashMap<u64, Aabb>,
    ) -> anyhow::Result<Vec<(String, f64)>> {
        let mut out = Vec::new();
        let mut under = Vec::new();
        for e in entries.iter().filter(|e| e.kind == EntryKind::Aggregate) {
            let node = node_id(&e.id).with_context(|| format!("entry id {}", e.id))?;
            under.clear();
            tree.bvh.objects_under(NodeId(node), &mut under);
            let mut covered = Aabb::EMPTY;
            for &o in &under {
                if let Some(b) = tree.world_id(o).and_then(|id| objects.get(&id)) {
                    covered = covered.union(*b);
                }
            }
            let mut drawn = Aabb::EMPTY;
            for p in &e.placements {
                let local = self.bounds(&p.asset)?;
                drawn = drawn.union(world_box(&local, &affine(&p.matrix)));
            }
            out.push((e.id.clone(), iou(&drawn, &covered)));
        }
        Ok(out)
    }
}

/// Intersection over union of two boxes' volumes, each padded by 1% of the larger diagonal
/// so that flat content (a ground tile) still has a volume.
fn iou(a: &Aabb, b: &Aabb) -> f64 {
    if a.is_empty() || b.is_empty() {
        return 0.0;
    }
    let pad = 0.01 * (a.max - a.min).length().max((b.max - b.min).length());
    let grow = |x: &Aabb| (x.min - Vec3::splat(pad), x.max + Vec3::splat(pad));
    let (amin, amax) = grow(a);
    let (bmin, bmax) = grow(b);
    let volume = |lo: Vec3, hi: Vec3| {
        let d = (hi - lo).max(Vec3::ZERO);
        f64::from(d.x) * f64::from(d.y) * f64::from(d.z)
    };
    let inter = volume(amin.max(bmin), amax.min(bmax));
    let union = volume(amin, amax) + volume(bmin, bmax) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

fn world_box(local: &horizon_mesh::Aabb, m: &Affine3A) -> Aabb {
    let mut out = Aabb::EMPTY;
    if local.min.x > local.max.x {
        return out;
    }
    for i in 0..8 {
        let c = Vec3::new(
            if i & 1 == 0 { local.min.x } else { local.max.x },
            if i & 2 == 0 { local.min.y } else { local.max.y },
            if i & 4 == 0 { local.min.z } else { local.max.z },
        );
        out = out.with_point(m.transform_point3(c));
    }
    out
}

fn affine(m: &[f32; 12]) -> Affine3A {
    Affine3A::from_cols_array(m)
}

/// `o:<id>@<generation>` -> id.
fn object_id(id: &str) -> Option<u64> {
    id.strip_prefix("o:")?.split('@').next()?.parse().ok()
}

/// `n:<node>@<hash>` -> node.
fn node_id(id: &str) -> Option<u32> {
    id.strip_prefix("n:")?.split('@').next()?.parse().ok()
}

/// Per-pixel absolute difference, amplified 4x so that small errors show.
fn difference(a: &horizon_impostor::Frame, b: &horizon_impostor::Frame) -> image::RgbImage {
    let mut out = image::RgbImage::new(a.width, a.height);
    for (i, px) in out.pixels_mut().enumerate() {
        let (p, q) = (a.color[i], b.color[i]);
        px.0 = std::array::from_fn(|c| (p[c].abs_diff(q[c]) as u32 * 4).min(255) as u8);
    }
    out
}

/// A figure as text, or "-" where it was not measured (`--no-render`).
fn measured(x: f64, show: impl Fn(f64) -> String) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        show(x)
    }
}

fn print_table(r: &Report) -> anyhow::Result<()> {
    outln!(
        "{}: {} objects, {}x{} at {} rays per pixel, cut at {} sr, at most {} entries{}{}",
        r.world,
        r.objects,
        r.width,
        r.height,
        r.samples * r.samples,
        r.min_solid_angle,
        r.max_entries,
        r.max_draw_calls
            .map_or(String::new(), |d| format!(", at most {d} draw calls")),
        r.max_triangles.map_or(String::new(), |t| format!(
            ", at most {t} triangles (each object at its own level)"
        )) + &r
            .max_bytes
            .map_or(String::new(), |b| format!(", at most {} bytes", mb(b)))
    )?;
    outln!()?;
    outln!("| view | PSNR dB | SSIM | off >16 | holes | download full / cut | draw calls full / cut | triangles full / cut | entries (aggregates, instances) | aggregate IoU median / min / < 0.9 |")?;
    outln!("|---|---|---|---|---|---|---|---|---|---|")?;
    for v in &r.views {
        outln!(
            "| {} | {} | {} | {} | {} | {} / {} ({:.2}x) | {} / {} ({:.2}x) | {} / {} ({:.2}x) | {} ({}, {}) | {:.3} / {:.3} / {} |",
            v.name,
            measured(v.psnr, |x| format!("{x:.1}")),
            measured(v.ssim, |x| format!("{x:.4}")),
            measured(v.off16, |x| format!("{:.2}%", x * 100.0)),
            measured(v.holes, |x| format!("{:.3}%", x * 100.0)),
            mb(v.full.bytes),
            mb(v.cut.bytes),
            ratio(v.cut.bytes, v.full.bytes),
            v.full.draw_calls,
            v.cut.draw_calls,
            ratio(v.cut.draw_calls, v.full.draw_calls),
            v.full.triangles,
            v.cut.triangles,
            ratio(v.cut.triangles, v.full.triangles),
            v.entries,
            v.aggregates,
            v.instance_entries,
            v.iou_median,
            v.iou_min,
            v.iou_under_0_9
        )?;
    }
    if r.views.iter().any(|v| v.flat.is_some()) {
        outln!()?;
        outln!(
            "Levels of detail (at most {} px of error) against the same cut without them (level 0 throughout), both against the full world:",
            r.max_pixel_error
        )?;
        outln!()?;
        outln!("| view | download without / with levels | PSNR dB without / with | SSIM without / with | holes without / with | triangles without / with | entries at a level > 0 |")?;
        outln!("|---|---|---|---|---|---|---|")?;
        for v in &r.views {
            let Some(f) = &v.flat else { continue };
            outln!(
                "| {} | {} / {} ({:.3}x) | {:.1} / {:.1} ({:+.2}) | {:.4} / {:.4} | {:.3}% / {:.3}% | {} / {} ({:.2}x) | {} of {} |",
                v.name,
                mb(f.cost.bytes),
                mb(v.cut.bytes),
                ratio(v.cut.bytes, f.cost.bytes),
                f.psnr,
                v.psnr,
                v.psnr - f.psnr,
                f.ssim,
                v.ssim,
                f.holes * 100.0,
                v.holes * 100.0,
                f.cost.triangles,
                v.cut.triangles,
                ratio(v.cut.triangles, f.cost.triangles),
                v.levelled,
                v.entries
            )?;
        }
    }
    if r.views.iter().any(|v| v.coarsened_cut.is_some()) {
        outln!()?;
        outln!("The service's cut (levels as the view asks) against the same cut with levels coarsened where a budget binds (`Coarsening::Search`), both against the full world:")?;
        outln!()?;
        outln!("| view | coarsened by | download as asked / coarsened | triangles as asked / coarsened | object entries as asked / coarsened | PSNR dB as asked / coarsened | SSIM as asked / coarsened | holes as asked / coarsened | plan ms as asked / coarsened |")?;
        outln!("|---|---|---|---|---|---|---|---|---|")?;
        for v in &r.views {
            let Some(f) = &v.coarsened_cut else { continue };
            outln!(
                "| {} | {} | {} / {} | {} / {} | {} / {} | {} / {} ({:+.2}) | {} / {} | {} / {} | {:.1} / {:.1} |",
                v.name,
                v.coarsened
                    .map_or("not bound".to_string(), |c| format!("{c:.2}x")),
                mb(v.cut.bytes),
                mb(f.cost.bytes),
                v.cut.triangles,
                f.cost.triangles,
                v.object_entries,
                f.object_entries,
                measured(v.psnr, |x| format!("{x:.1}")),
                measured(f.psnr, |x| format!("{x:.1}")),
                f.psnr - v.psnr,
                measured(v.ssim, |x| format!("{x:.4}")),
                measured(f.ssim, |x| format!("{x:.4}")),
                measured(v.holes, |x| format!("{:.3}%", x * 100.0)),
                measured(f.holes, |x| format!("{:.3}%", x * 100.0)),
                v.plan_ms,
                v.plan_ms_coarsened.unwrap_or(f64::NAN),
            )?;
        }
    }
    if r.views.iter().any(|v| v.stopped_cut.is_some()) {
        outln!()?;
        outln!("The same cut stopped at the first refinement a budget refuses (`plan_stopping`) against the service's cut, which goes on past refusals, both against the full world:")?;
        outln!()?;
        outln!("| view | refusals skipped | download stops / skips | triangles stops / skips | entries stops / skips | object entries stops / skips | PSNR dB stops / skips | SSIM stops / skips | holes stops / skips | plan ms stops / skips |")?;
        outln!("|---|---|---|---|---|---|---|---|---|---|")?;
        for v in &r.views {
            let Some(f) = &v.stopped_cut else { continue };
            outln!(
                "| {} | {} | {} / {} | {} / {} | {} / {} | {} / {} | {} / {} ({:+.2}) | {} / {} | {} / {} | {:.1} / {:.1} |",
                v.name,
                v.skipped,
                mb(f.cost.bytes),
                mb(v.cut.bytes),
                f.cost.triangles,
                v.cut.triangles,
                f.entries,
                v.entries,
                f.object_entries,
                v.object_entries,
                measured(f.psnr, |x| format!("{x:.1}")),
                measured(v.psnr, |x| format!("{x:.1}")),
                v.psnr - f.psnr,
                measured(f.ssim, |x| format!("{x:.4}")),
                measured(v.ssim, |x| format!("{x:.4}")),
                measured(f.holes, |x| format!("{:.3}%", x * 100.0)),
                measured(v.holes, |x| format!("{:.3}%", x * 100.0)),
                v.plan_ms_stopping.unwrap_or(f64::NAN),
                v.plan_ms,
            )?;
        }
    }
    if r.views.iter().any(|v| v.aggregates_only.is_some()) {
        outln!()?;
        outln!("Reuse-aware cut (instances entries) against the same cut without them (every node as its aggregate), both against the full world:")?;
        outln!()?;
        outln!("| view | download without / with instances | draw calls without / with | triangles without / with | PSNR dB without / with | SSIM without / with | holes without / with | instances entries | plan ms without / with | entries JSON zstd full / without / with |")?;
        outln!("|---|---|---|---|---|---|---|---|---|---|")?;
        for v in &r.views {
            let Some(f) = &v.aggregates_only else {
                continue;
            };
            outln!(
                "| {} | {} / {} ({:.3}x) | {} / {} ({:.2}x) | {} / {} ({:.2}x) | {} / {} | {} / {} | {} / {} | {} of {} | {:.1} / {:.1} | {} / {} / {} |",
                v.name,
                mb(f.cost.bytes),
                mb(v.cut.bytes),
                ratio(v.cut.bytes, f.cost.bytes),
                f.cost.draw_calls,
                v.cut.draw_calls,
                ratio(v.cut.draw_calls, f.cost.draw_calls),
                f.cost.triangles,
                v.cut.triangles,
                ratio(v.cut.triangles, f.cost.triangles),
                measured(f.psnr, |x| format!("{x:.1}")),
                measured(v.psnr, |x| format!("{x:.1}")),
                measured(f.ssim, |x| format!("{x:.4}")),
                measured(v.ssim, |x| format!("{x:.4}")),
                measured(f.holes, |x| format!("{:.3}%", x * 100.0)),
                measured(v.holes, |x| format!("{:.3}%", x * 100.0)),
                v.instance_entries,
                v.entries,
                v.plan_ms_without_instances.unwrap_or(f64::NAN),
                v.plan_ms,
                mb(v.full.entries_zstd),
                mb(f.cost.entries_zstd),
                mb(v.cut.entries_zstd)
            )?;
        }
    }
    if r.views.iter().any(|v| v.meshes_only.is_some()) {
        outln!()?;
        outln!("Orthoview impostors (splats) against the same cut without them, both against the full world:")?;
        outln!()?;
        outln!("| view | download without / with impostors | objects alone (the floor) | PSNR dB without / with | SSIM without / with | holes without / with | impostor entries |")?;
        outln!("|---|---|---|---|---|---|---|")?;
        for v in &r.views {
            let Some(f) = &v.meshes_only else { continue };
            outln!(
                "| {} | {} / {} ({:.3}x) | {} ({:.3}x) | {:.1} / {:.1} ({:+.2}) | {:.4} / {:.4} | {:.3}% / {:.3}% | {} of {} |",
                v.name,
                mb(f.cost.bytes),
                mb(v.cut.bytes),
                ratio(v.cut.bytes, f.cost.bytes),
                mb(v.objects_alone.bytes),
                ratio(v.objects_alone.bytes, f.cost.bytes),
                f.psnr,
                v.psnr,
                v.psnr - f.psnr,
                f.ssim,
                v.ssim,
                f.holes * 100.0,
                v.holes * 100.0,
                v.impostors,
                v.entries
            )?;
        }
        for v in &r.views {
            let (Some(a), Some(f)) = (v.against_aggregate, &v.meshes_only) else {
                continue;
            };
            outln!()?;
            outln!(
                "{}: at its handover distance, alone: impostor against aggregate PSNR {a:.1} dB; against the objects, impostor {:.1} dB, aggregate {:.1} dB",
                v.name,
                v.psnr,
                f.psnr
            )?;
        }
    }
    Ok(())
}

fn mb(bytes: u64) -> String {
    format!("{:.2} MB", bytes as f64 / 1e6)
}

fn ratio(a: u64, b: u64) -> f64 {
    a as f64 / (b as f64).max(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_is_one_for_equal_boxes_and_falls_with_overlap() {
        let a = Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        assert!((iou(&a, &a) - 1.0).abs() < 1e-9);
        let b = Aabb {
            min: Vec3::new(0.5, 0.0, 0.0),
            max: Vec3::new(1.5, 1.0, 1.0),
        };
        let v = iou(&a, &b);
        assert!(v > 0.3 && v < 0.36, "{v}");
        let far = Aabb {
            min: Vec3::splat(10.0),
            max: Vec3::splat(11.0),
        };
        assert_eq!(iou(&a, &far), 0.0);
    }

    #[test]
    fn entry_ids_parse() {
        assert_eq!(object_id("o:42@7"), Some(42));
        assert_eq!(node_id("n:3@abc"), Some(3));
        assert_eq!(object_id("n:3@abc"), None);
    }
}
