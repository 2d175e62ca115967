//! `horizon-lab sweep`: the core paper's Figure 5. For each built world and each eq. 1
//! weighting (mu, w), the tree is bulk-built from the cached descriptors and the cut's cost
//! (nodes visited, cut size) averaged over seeded viewpoints; then the same viewpoints on the
//! spatial obvhs baseline.

use std::path::PathBuf;
use std::time::Instant;

use horizon_bvh::{Bvh, CutQuery, SpatialBaseline};
use horizon_server::outln;
use horizon_world::World;
use serde::Serialize;

use crate::input::BvhInput;
use crate::views::viewpoints;

/// One row of `horizon-lab sweep`: the average query cost of one world's tree built with one
/// (mu, w).
#[derive(Debug, Serialize)]
struct SweepRow {
    world: String,
    /// "similarity" (ours, bulk-built with mu and w) or "obvhs" (the spatial SAH baseline).
    tree: &'static str,
    mu: Option<f32>,
    w: Option<f32>,
    nodes: usize,
    height: u32,
    build_seconds: f64,
    mean_nodes_visited: f64,
    mean_cut_size: f64,
    mean_query_seconds: f64,
}

/// The mu values of the sweep (core paper Figure 5).
const SWEEP_MU: [f32; 6] = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0];
/// The w values of the sweep.
const SWEEP_W: [f32; 4] = [0.0, 0.2, 0.5, 1.0];

/// Figure 5 reproduced: for each built world in `dirs` and each (mu, w), bulk-builds the tree
/// from the cached descriptors and averages the cut cost (nodes visited, cut size) over
/// `views` seeded viewpoints at eye height (2 m) inside the world's bounds.
pub fn run(
    dirs: &[PathBuf],
    views: usize,
    seed: u64,
    min_solid_angle: f32,
    max_results: usize,
    json: bool,
) -> anyhow::Result<()> {
    if views == 0 || max_results == 0 {
        anyhow::bail!("--views and --max-results must be at least 1");
    }
    if !(min_solid_angle.is_finite() && min_solid_angle > 0.0) {
        anyhow::bail!("--min-solid-angle {min_solid_angle} must be a positive number");
    }
    let mut rows = Vec::new();
    for dir in dirs {
        let world = World::open(dir)?;
        let (name, _) = world.identity()?;
        let held = BvhInput::of(&world)?;
        let input = held.objects();
        // Mean nodes visited, cut size and seconds over the same seeded viewpoints.
        let measure = |bounds: &horizon_bvh::Aabb, cut: &dyn Fn(&CutQuery) -> (usize, usize)| {
            let (mut visited, mut size, mut seconds) = (0usize, 0usize, 0.0f64);
            for position in viewpoints(bounds, seed, views) {
                let query = CutQuery {
                    position,
                    min_solid_angle,
                    max_results,
                };
                let t = Instant::now();
                let (v, n) = cut(&query);
                seconds += t.elapsed().as_secs_f64();
                visited += v;
                size += n;
            }
            let n = views as f64;
            (visited as f64 / n, size as f64 / n, seconds / n)
        };
        let mut last = None;
        for mu in SWEEP_MU {
            for w in SWEEP_W {
                let started = Instant::now();
                let bvh = Bvh::bulk_build(world.bvh_options(mu, w)?, &input)?;
                let build_seconds = started.elapsed().as_secs_f64();
                let Some(root) = bvh.node(bvh.root()) else {
                    anyhow::bail!("{} has no objects", dir.display());
                };
                let bounds = root.aabb();
                let (visited, size, seconds) = measure(&bounds, &|q| {
                    let cut = bvh.cut(q);
                    (cut.nodes_visited, cut.entries.len())
                });
                rows.push(SweepRow {
                    world: name.clone(),
                    tree: "similarity",
                    mu: Some(mu),
                    w: Some(w),
                    nodes: bvh.node_count(),
                    height: bvh.height(),
                    build_seconds,
                    mean_nodes_visited: visited,
                    mean_cut_size: size,
                    mean_query_seconds: seconds,
                });
                last = Some((bvh, bounds));
            }
        }
        // The spatial baseline over the same objects and viewpoints.
        if let Some((bvh, bounds)) = last {
            let started = Instant::now();
            let baseline = SpatialBaseline::build(&bvh);
            let build_seconds = started.elapsed().as_secs_f64();
            let (visited, size, seconds) = measure(&bounds, &|q| {
                let cut = baseline.cut(q);
                (cut.nodes_visited, cut.entries.len())
            });
            rows.push(SweepRow {
                world: name.clone(),
                tree: "obvhs",
                mu: None,
                w: None,
                nodes: baseline.node_count(),
                height: 0,
                build_seconds,
                mean_nodes_visited: visited,
                mean_cut_size: size,
                mean_query_seconds: seconds,
            });
        }
    }
    if json {
        outln!("{}", serde_json::to_string(&rows)?)?;
    } else {
        outln!(
            "| world | tree | mu | w | nodes | height | build s | nodes visited | cut size | query ms |"
        )?;
        outln!("|---|---|---|---|---|---|---|---|---|---|")?;
        let show = |v: Option<f32>| v.map_or("-".to_string(), |v| v.to_string());
        for r in &rows {
            outln!(
                "| {} | {} | {} | {} | {} | {} | {:.2} | {:.1} | {:.1} | {:.3} |",
                r.world,
                r.tree,
                show(r.mu),
                show(r.w),
                r.nodes,
                r.height,
                r.build_seconds,
                r.mean_nodes_visited,
                r.mean_cut_size,
                r.mean_query_seconds * 1e3
            )?;
        }
    }
    Ok(())
}
