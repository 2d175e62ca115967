//! `horizon-lab bench-bvh`: measures the similarity-aware BVH on a built world directory
//! (city9: 540,000 objects) against its targets and writes a markdown report.
//!
//! The trees are rebuilt from `objects.json` and the `descriptors.json` cache (parsing the
//! ~1 GB `bvh.json` snapshot of city9 would be slower than the bulk build itself):
//! 1. bulk rebuild (section 4.3) on all cores, mu 0.8, w 0.2 and the world's descriptor scales;
//! 2. incremental insertion of every object into an empty tree, one core;
//! 3. cut queries (best-first, `max_results` 4000) from seeded viewpoints at eye height 2 m
//!    inside the world's bounds, on both trees, one core;
//! 4. the same queries on the obvhs SAH baseline ([`SpatialBaseline`]);
//! 5. standing-query updates for a viewer walking 1 m per step;
//! 6. memory per object.
//!
//! Every target is printed with PASS or FAIL beside the measured figure.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use horizon_bvh::{
    Aabb, Bvh, Cut, CutQuery, CutWorkspace, SpatialBaseline, SpatialCut, SpatialWorkspace,
    StandingOptions, StandingQuery,
};
use horizon_bvh::{DEFAULT_MU, DEFAULT_W};
use horizon_mesh::rng::Rng;
use horizon_server::outln;
use horizon_world::{write_atomically, World};
use serde::Serialize;

use crate::input::BvhInput;
use crate::views::{viewpoints, EYE_HEIGHT};

/// Hysteresis of the standing query (the library's default).
const HYSTERESIS: f32 = 0.1;

/// The command's parameters.
#[derive(Debug, Clone)]
pub struct BenchArgs {
    pub dir: PathBuf,
    pub views: usize,
    pub seed: u64,
    pub steps: usize,
    pub min_solid_angle: f32,
    pub max_results: usize,
    pub out: Option<PathBuf>,
    pub json: bool,
}

/// One target with its measured figure.
#[derive(Debug, Serialize)]
struct Target {
    name: String,
    measured: f64,
    unit: &'static str,
    /// "<=" or ">=".
    comparison: &'static str,
    goal: f64,
    pass: bool,
}

impl Target {
    fn at_most(name: impl Into<String>, measured: f64, goal: f64, unit: &'static str) -> Self {
        Self {
            name: name.into(),
            measured,
            unit,
            comparison: "<=",
            goal,
            pass: measured <= goal,
        }
    }

    fn at_least(name: impl Into<String>, measured: f64, goal: f64, unit: &'static str) -> Self {
        Self {
            name: name.into(),
            measured,
            unit,
            comparison: ">=",
            goal,
            pass: measured >= goal,
        }
    }
}

/// A tree build.
#[derive(Debug, Serialize)]
struct BuildStats {
    seconds: f64,
    threads: usize,
    nodes: usize,
    height: u32,
    objects_per_second: f64,
}

/// Cut queries over every viewpoint on one tree.
#[derive(Debug, Serialize)]
struct QueryStats {
    tree: String,
    /// First run at each viewpoint.
    median_ms: f64,
    p99_ms: f64,
    /// The same viewpoint again right after (warm caches).
    warm_median_ms: f64,
    warm_p99_ms: f64,
    visited_per_entry_median: f64,
    visited_per_entry_p99: f64,
    visited_per_entry_max: f64,
    mean_nodes_visited: f64,
    mean_cut_size: f64,
    min_cut_size: f64,
    max_cut_size: f64,
    /// Cuts that reached `max_results`.
    budget_bound: usize,
}

/// A standing query following a walking viewer.
#[derive(Debug, Serialize)]
struct StandingStats {
    tree: String,
    steps: usize,
    median_ms: f64,
    p99_ms: f64,
    max_ms: f64,
    deltas_median: f64,
    deltas_mean: f64,
    deltas_max: f64,
    nodes_visited_median: f64,
    fallbacks: usize,
    /// Budget-bound updates whose best-first cut was seeded by a threshold walk.
    seeded: usize,
    /// Median nodes refined through the best-first heap per update.
    heap_refinements_median: f64,
    final_cut_size: usize,
}

/// Memory of one tree.
#[derive(Debug, Serialize)]
struct MemoryStats {
    tree: String,
    bytes: usize,
    bytes_per_object: f64,
}

/// The whole report (`--json`).
#[derive(Debug, Serialize)]
struct BenchReport {
    world: String,
    dir: String,
    objects: usize,
    models: usize,
    threads: usize,
    load_average_before: String,
    load_average_after: String,
    load_seconds: f64,
    validate_seconds: f64,
    mu: f32,
    w: f32,
    shape_scale: f32,
    texture_scale: f32,
    views: usize,
    seed: u64,
    steps: usize,
    min_solid_angle: f32,
    max_results: usize,
    bounds_min: [f32; 3],
    bounds_max: [f32; 3],
    bulk: BuildStats,
    incremental: BuildStats,
    spatial_build_seconds: f64,
    spatial_nodes: usize,
    queries: Vec<QueryStats>,
    standing: Vec<StandingStats>,
    memory: Vec<MemoryStats>,
    targets: Vec<Target>,
}

/// Runs the benchmark and writes the report.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    if args.views == 0 || args.steps == 0 || args.max_results == 0 {
        anyhow::bail!("--views, --steps and --max-results must be at least 1");
    }
    if !(args.min_solid_angle.is_finite() && args.min_solid_angle > 0.0) {
        anyhow::bail!(
            "--min-solid-angle {} must be a positive number",
            args.min_solid_angle
        );
    }
    let dir = &args.dir;
    let load_before = load_average();
    let progress = |msg: &str| eprintln!("horizon-lab: bench-bvh: {msg}");

    // Load the world and its descriptors.
    let t = Instant::now();
    let world = World::open(dir)?;
    let (name, _) = world.identity()?;
    let held = BvhInput::of(&world)?;
    let input = held.objects();
    let load_seconds = t.elapsed().as_secs_f64();
    let n = input.len();
    if n == 0 {
        anyhow::bail!("{} has no objects", dir.display());
    }
    let threads = rayon::current_num_threads();
    progress(&format!(
        "{name}: {n} objects loaded in {load_seconds:.2} s"
    ));
    let one_core = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("cannot start a one-thread pool")?;

    // 1. Bulk rebuild, all cores.
    let options = world.bvh_options(DEFAULT_MU, DEFAULT_W)?;
    let t = Instant::now();
    let bulk = Bvh::bulk_build(options.clone(), &input)?;
    let seconds = t.elapsed().as_secs_f64();
    let bulk_stats = BuildStats {
        seconds,
        threads,
        nodes: bulk.node_count(),
        height: bulk.height(),
        objects_per_second: n as f64 / seconds,
    };
    progress(&format!("bulk rebuild {seconds:.2} s"));

    // 2. Incremental insertion, one core.
    let (incremental, seconds) = one_core.install(|| -> anyhow::Result<(Bvh, f64)> {
        let t = Instant::now();
        let mut tree = Bvh::new(options.clone())?;
        for object in &input {
            tree.insert(object)?;
        }
        let seconds = t.elapsed().as_secs_f64();
        tree.shrink_to_fit();
        Ok((tree, seconds))
    })?;
    let incremental_stats = BuildStats {
        seconds,
        threads: 1,
        nodes: incremental.node_count(),
        height: incremental.height(),
        objects_per_second: n as f64 / seconds,
    };
    progress(&format!("incremental insertion {seconds:.2} s"));
    drop(input);

    let t = Instant::now();
    bulk.validate().context("the bulk tree is invalid")?;
    incremental
        .validate()
        .context("the incremental tree is invalid")?;
    let validate_seconds = t.elapsed().as_secs_f64();

    // Viewpoints: seeded, inside the world's bounds, at eye height.
    let bounds = bulk
        .node(bulk.root())
        .map(|r| r.aabb())
        .context("the tree has no root")?;
    let viewpoints = viewpoints(&bounds, args.seed, args.views);

    // 3. Cut queries on both trees, one core.
    progress("cut queries");
    let queries_of =
        |tree: &str, bvh: &Bvh| one_core.install(|| query_stats(tree, bvh, &viewpoints, args));
    let mut queries = vec![
        queries_of("bulk", &bulk),
        queries_of("incremental", &incremental),
    ];

    // 4. The spatial baseline.
    let t = Instant::now();
    let spatial = SpatialBaseline::build(&bulk);
    let spatial_build_seconds = t.elapsed().as_secs_f64();
    queries.push(one_core.install(|| spatial_stats(&spatial, &viewpoints, args)));
    let spatial_nodes = spatial.node_count();
    drop(spatial);

    // 5. Standing queries.
    progress("standing queries");
    let standing = vec![
        one_core.install(|| standing_stats("bulk", &bulk, &bounds, args)),
        one_core.install(|| standing_stats("incremental", &incremental, &bounds, args)),
    ];

    // 6. Memory.
    let memory: Vec<MemoryStats> = [("bulk", &bulk), ("incremental", &incremental)]
        .into_iter()
        .map(|(tree, bvh)| MemoryStats {
            tree: tree.to_owned(),
            bytes: bvh.memory_bytes(),
            bytes_per_object: bvh.memory_bytes() as f64 / n as f64,
        })
        .collect();

    // Targets.
    let mut targets = vec![
        Target::at_most(
            format!("bulk rebuild ({threads} threads)"),
            bulk_stats.seconds,
            10.0,
            "s",
        ),
        Target::at_least(
            "incremental insertion (1 core)",
            incremental_stats.objects_per_second,
            100_000.0,
            "objects/s",
        ),
    ];
    for q in &queries[..2] {
        targets.push(Target::at_most(
            format!("cut median ({})", q.tree),
            q.median_ms,
            2.0,
            "ms",
        ));
        targets.push(Target::at_most(
            format!("cut p99 ({})", q.tree),
            q.p99_ms,
            5.0,
            "ms",
        ));
        targets.push(Target::at_most(
            format!("nodes visited / cut size, median ({})", q.tree),
            q.visited_per_entry_median,
            3.0,
            "",
        ));
        targets.push(Target::at_most(
            format!("nodes visited / cut size, max ({})", q.tree),
            q.visited_per_entry_max,
            3.0,
            "",
        ));
    }
    for s in &standing {
        targets.push(Target::at_most(
            format!("standing update median ({})", s.tree),
            s.median_ms,
            0.2,
            "ms",
        ));
    }
    for m in &memory {
        targets.push(Target::at_most(
            format!("memory per object ({})", m.tree),
            m.bytes_per_object,
            1024.0,
            "bytes",
        ));
    }

    let report = BenchReport {
        world: name.clone(),
        dir: dir.display().to_string(),
        objects: n,
        models: world.models().len(),
        threads,
        load_average_before: load_before,
        load_average_after: load_average(),
        load_seconds,
        validate_seconds,
        mu: options.mu,
        w: options.w,
        shape_scale: options.shape_scale,
        texture_scale: options.texture_scale,
        views: args.views,
        seed: args.seed,
        steps: args.steps,
        min_solid_angle: args.min_solid_angle,
        max_results: args.max_results,
        bounds_min: bounds.min.to_array(),
        bounds_max: bounds.max.to_array(),
        bulk: bulk_stats,
        incremental: incremental_stats,
        spatial_build_seconds,
        spatial_nodes,
        queries,
        standing,
        memory,
        targets,
    };

    let markdown = markdown(&report);
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(crate::RESULTS).join(format!("bvh_{}.md", report.world)));
    write_atomically(&out, markdown.as_bytes())?;
    if args.json {
        outln!("{}", serde_json::to_string(&report)?)?;
    } else {
        outln!("{markdown}")?;
        outln!("written to {}", out.display())?;
    }
    Ok(())
}

/// `/proc/loadavg`'s three load averages, or "unknown".
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".to_owned())
}

/// The `p` quantile (nearest rank) of `values`, sorting them.
fn percentile(values: &mut [f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let i = ((values.len() - 1) as f64 * p).round() as usize;
    values[i]
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

/// Per-viewpoint figures of one query run.
#[derive(Default)]
struct Samples {
    cold: Vec<f64>,
    warm: Vec<f64>,
    ratio: Vec<f64>,
    visited: Vec<f64>,
    size: Vec<f64>,
    budget_bound: usize,
}

impl Samples {
    fn push(&mut self, cold: f64, warm: f64, visited: usize, size: usize, max_results: usize) {
        self.cold.push(cold);
        self.warm.push(warm);
        self.ratio.push(visited as f64 / size.max(1) as f64);
        self.visited.push(visited as f64);
        self.size.push(size as f64);
        self.budget_bound += usize::from(size >= max_results);
    }

    fn finish(mut self, tree: &str) -> QueryStats {
        QueryStats {
            tree: tree.to_owned(),
            median_ms: percentile(&mut self.cold, 0.5),
            p99_ms: percentile(&mut self.cold, 0.99),
            warm_median_ms: percentile(&mut self.warm, 0.5),
            warm_p99_ms: percentile(&mut self.warm, 0.99),
            visited_per_entry_median: percentile(&mut self.ratio, 0.5),
            visited_per_entry_p99: percentile(&mut self.ratio, 0.99),
            visited_per_entry_max: percentile(&mut self.ratio, 1.0),
            mean_nodes_visited: mean(&self.visited),
            mean_cut_size: mean(&self.size),
            min_cut_size: percentile(&mut self.size, 0.0),
            max_cut_size: percentile(&mut self.size, 1.0),
            budget_bound: self.budget_bound,
        }
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Every viewpoint queried on `bvh`: the first run, then the same query again.
fn query_stats(tree: &str, bvh: &Bvh, viewpoints: &[Vec3], args: &BenchArgs) -> QueryStats {
    let mut workspace = CutWorkspace::new();
    let mut cut = Cut::default();
    time_queries(tree, viewpoints, args, |query| {
        bvh.cut_into(query, &mut workspace, &mut cut);
        (cut.nodes_visited, cut.entries.len())
    })
}

/// The same viewpoints on the obvhs baseline.
fn spatial_stats(spatial: &SpatialBaseline, viewpoints: &[Vec3], args: &BenchArgs) -> QueryStats {
    let mut workspace = SpatialWorkspace::default();
    let mut cut = SpatialCut::default();
    time_queries("obvhs SAH baseline", viewpoints, args, |query| {
        spatial.cut_into(query, &mut workspace, &mut cut);
        (cut.nodes_visited, cut.entries.len())
    })
}

/// Runs `cut` twice per viewpoint (cold, then warm) and gathers its (nodes visited, entries).
fn time_queries(
    tree: &str,
    viewpoints: &[Vec3],
    args: &BenchArgs,
    mut cut: impl FnMut(&CutQuery) -> (usize, usize),
) -> QueryStats {
    let mut samples = Samples::default();
    for &position in viewpoints {
        let query = CutQuery {
            position,
            min_solid_angle: args.min_solid_angle,
            max_results: args.max_results,
        };
        let t = Instant::now();
        cut(&query);
        let cold = ms(t);
        let t = Instant::now();
        let (visited, entries) = cut(&query);
        let warm = ms(t);
        samples.push(cold, warm, visited, entries, args.max_results);
    }
    samples.finish(tree)
}

/// A viewer at eye height walking 1 m per step from the centre of the world along a gently
/// turning seeded path (bouncing off the world's bounds), with a standing query. The first
/// update (the whole cut) is not counted.
fn standing_stats(tree: &str, bvh: &Bvh, bounds: &Aabb, args: &BenchArgs) -> StandingStats {
    let mut standing = StandingQuery::new(StandingOptions {
        min_solid_angle: args.min_solid_angle,
        max_results: args.max_results,
        hysteresis: HYSTERESIS,
    });
    let mut rng = Rng::new(args.seed ^ 0x57A9_D000);
    let centre = (bounds.min + bounds.max) * 0.5;
    let mut position = Vec3::new(centre.x, EYE_HEIGHT, centre.z);
    let mut heading = rng.angle();
    let mut deltas = Vec::new();
    standing.update(bvh, position, &mut deltas);
    let (mut times, mut changes, mut visited) = (Vec::new(), Vec::new(), Vec::new());
    let mut fallbacks = 0;
    let mut seeded = 0;
    let mut heap_refinements = Vec::new();
    for _ in 0..args.steps {
        heading += rng.range(-0.05, 0.05);
        let mut step = Vec3::new(heading.cos(), 0.0, heading.sin());
        let next = position + step;
        if next.x < bounds.min.x || next.x > bounds.max.x {
            heading = std::f32::consts::PI - heading;
            step.x = -step.x;
        }
        if next.z < bounds.min.z || next.z > bounds.max.z {
            heading = -heading;
            step.z = -step.z;
        }
        position += step;
        deltas.clear();
        let t = Instant::now();
        let stats = standing.update(bvh, position, &mut deltas);
        times.push(ms(t));
        changes.push(deltas.len() as f64);
        visited.push(stats.nodes_visited as f64);
        fallbacks += usize::from(stats.fell_back);
        seeded += usize::from(stats.seeded);
        heap_refinements.push(stats.heap_refinements as f64);
    }
    StandingStats {
        tree: tree.to_owned(),
        steps: args.steps,
        median_ms: percentile(&mut times, 0.5),
        p99_ms: percentile(&mut times, 0.99),
        max_ms: percentile(&mut times, 1.0),
        deltas_median: percentile(&mut changes, 0.5),
        deltas_mean: mean(&changes),
        deltas_max: percentile(&mut changes, 1.0),
        nodes_visited_median: percentile(&mut visited, 0.5),
        fallbacks,
        seeded,
        heap_refinements_median: percentile(&mut heap_refinements, 0.5),
        final_cut_size: standing.len(),
    }
}

/// A figure with a sensible number of digits.
fn fig(v: f64) -> String {
    let a = v.abs();
    if a >= 1000.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.4}")
    }
}

/// The markdown report.
fn markdown(r: &BenchReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# BVH benchmark on `{}`\n", r.world);
    let _ = writeln!(
        s,
        "`horizon-lab bench-bvh {} --views {} --seed {} --steps {}`: {} objects, {} unique models; \
         {} rayon threads for the bulk rebuild, one core for everything else. Load average \
         before {}, after {}. Trees rebuilt from objects.json + descriptors.json (load {:.2} s); \
         options mu {}, w {}, descriptor scales (the world's median z_diff and t_diff) {} and \
         {}. Queries: Omega_min {:e} sr, max_results {}, {} seeded viewpoints \
         (seed {}) at eye height {EYE_HEIGHT} m inside the world bounds \
         ({:?} .. {:?}).\n",
        r.dir,
        r.views,
        r.seed,
        r.steps,
        r.objects,
        r.models,
        r.threads,
        r.load_average_before,
        r.load_average_after,
        r.load_seconds,
        r.mu,
        r.w,
        r.shape_scale,
        r.texture_scale,
        r.min_solid_angle,
        r.max_results,
        r.views,
        r.seed,
        r.bounds_min,
        r.bounds_max,
    );

    let _ = writeln!(s, "## Targets\n");
    let _ = writeln!(s, "| target | measured | goal | result |");
    let _ = writeln!(s, "|---|---|---|---|");
    for t in &r.targets {
        let _ = writeln!(
            s,
            "| {} | {} {} | {} {} {} | {} |",
            t.name,
            fig(t.measured),
            t.unit,
            t.comparison,
            fig(t.goal),
            t.unit,
            if t.pass { "PASS" } else { "FAIL" }
        );
    }

    let _ = writeln!(s, "\n## Builds\n");
    let _ = writeln!(
        s,
        "| tree | threads | seconds | objects/s | nodes | height |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (name, b) in [
        ("bulk rebuild", &r.bulk),
        ("incremental insertion", &r.incremental),
    ] {
        let _ = writeln!(
            s,
            "| {name} | {} | {:.3} | {:.0} | {} | {} |",
            b.threads, b.seconds, b.objects_per_second, b.nodes, b.height
        );
    }
    let _ = writeln!(
        s,
        "\nBoth trees validated in {:.2} s. obvhs SAH baseline built in {:.2} s ({} nodes).",
        r.validate_seconds, r.spatial_build_seconds, r.spatial_nodes
    );

    let _ = writeln!(
        s,
        "\n## Cut queries\n\nFirst run per viewpoint (\"cold\"), then the same query again \
         (\"warm\"). Visited/entry: nodes whose solid angle was evaluated per cut entry.\n"
    );
    let _ = writeln!(
        s,
        "| tree | median ms | p99 ms | warm median ms | warm p99 ms | visited/entry median | \
         p99 | max | mean nodes visited | mean cut size | min..max cut size | cuts at budget |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for q in &r.queries {
        let _ = writeln!(
            s,
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.2} | {:.0} | {:.0} | \
             {:.0}..{:.0} | {}/{} |",
            q.tree,
            q.median_ms,
            q.p99_ms,
            q.warm_median_ms,
            q.warm_p99_ms,
            q.visited_per_entry_median,
            q.visited_per_entry_p99,
            q.visited_per_entry_max,
            q.mean_nodes_visited,
            q.mean_cut_size,
            q.min_cut_size,
            q.max_cut_size,
            q.budget_bound,
            r.views
        );
    }

    let _ = writeln!(
        s,
        "\n## Standing queries\n\nA viewer walking {} steps of 1 m at eye height from the \
         world's centre (seeded, gently turning, bouncing off the bounds), hysteresis \
         {HYSTERESIS}; the initial full cut is not counted.\n",
        r.steps
    );
    let _ = writeln!(
        s,
        "| tree | median ms | p99 ms | max ms | deltas/step median | mean | max | nodes \
         visited median | budget-bound updates | seeded by a threshold walk | heap \
         refinements median | final cut size |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for t in &r.standing {
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {:.3} | {:.0} | {:.1} | {:.0} | {:.0} | {} | {} | {:.0} | {} |",
            t.tree,
            t.median_ms,
            t.p99_ms,
            t.max_ms,
            t.deltas_median,
            t.deltas_mean,
            t.deltas_max,
            t.nodes_visited_median,
            t.fallbacks,
            t.seeded,
            t.heap_refinements_median,
            t.final_cut_size
        );
    }

    let _ = writeln!(s, "\n## Memory\n");
    let _ = writeln!(s, "| tree | MiB | bytes/object |");
    let _ = writeln!(s, "|---|---|---|");
    for m in &r.memory {
        let _ = writeln!(
            s,
            "| {} | {:.1} | {:.0} |",
            m.tree,
            m.bytes as f64 / (1u64 << 20) as f64,
            m.bytes_per_object
        );
    }
    s
}
