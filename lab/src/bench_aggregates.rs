//! `horizon-lab bench-aggregates`: the offline rebuild's build targets. A full build of every
//! aggregate from scratch (time, memory), then seeded inserts and the incremental rebuild
//! (what it touched, how long it took).

use std::collections::BTreeSet;
use std::path::Path;

use anyhow::Context;
use glam::Vec3;
use horizon_aggregate::{
    build_aggregates, AggregateOptions, BuildOptions, BuildReport, ImpostorPolicy, LevelTime,
    Progress,
};
use horizon_bvh::Bvh;
use horizon_mesh::rng::Rng;
use horizon_server::outln;
use horizon_server::terminal::ProgressBar;
use horizon_world::{write_atomically, AggregateSink, Describe, World};
use serde::Serialize;

/// What `horizon-lab bench-aggregates` measures.
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
pub fn run(dir: &Path, insert: usize, seed: u64, out: Option<&Path>) -> anyhow::Result<()> {
    let world = World::open(dir)?;
    world.ensure_tree()?;
    // A full build from scratch.
    world.forget_aggregates()?;
    let options = AggregateOptions::default();
    let bar = ProgressBar::new("full build");
    let full = world
        .rebuild_aggregates(options, &|p: Progress| bar.show(p.done, p.total))?
        .build;
    bar.finish();
    let full_manifest = world
        .published_manifest()?
        .context("full build published no manifest")?;

    // Seeded copies of existing models at random places, inserted into a copy of the tree:
    // the world itself is left as it was.
    let mut tree = world.with_tree(|t| t.clone())?;
    let bounds = tree
        .bvh
        .node(tree.bvh.root())
        .map(|n| n.aabb())
        .context("the world is empty")?;
    let models = world.models();
    let mut rng = Rng::new(seed);
    let mut inserted = Vec::new();
    for _ in 0..insert {
        let m = rng.below(models.len()) as u64;
        let d = models.descriptors_of(m)?;
        let t = glam::Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)),
            Vec3::new(
                rng.range(bounds.min.x, bounds.max.x),
                0.0,
                rng.range(bounds.min.z, bounds.max.z),
            ),
        );
        let id = tree.bvh.insert(&horizon_bvh::NewObject {
            model: m,
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
    let bvh: &Bvh = &tree.bvh;
    let mut ancestors = BTreeSet::new();
    for &id in &inserted {
        let mut at = bvh.object(id).map(|o| o.leaf());
        while let Some(n) = at {
            ancestors.insert(n.0);
            at = bvh.node(n).and_then(|r| r.parent());
        }
    }
    // Built into the world's stores but not published: the world keeps serving the full
    // build, and the next rebuild collects what this one wrote.
    let bar = ProgressBar::new("incremental");
    let build_options = BuildOptions {
        aggregate: options,
        world_textures: models.texture_totals()?,
        impostors: ImpostorPolicy::WherePaying,
    };
    let sink = AggregateSink::new(world.meta(), world.blobs(), Some((*full_manifest).clone()));
    let outcome = build_aggregates(bvh, models, &sink, &build_options, &|p: Progress| {
        bar.show(p.done, p.total)
    })?;
    bar.finish();
    let (incremental, after) = (outcome.report, outcome.manifest);
    let before_keys: BTreeSet<&String> = full_manifest.nodes.values().map(|e| &e.key).collect();
    let rebuilt: BTreeSet<u32> = after
        .nodes
        .iter()
        .filter(|(_, e)| !before_keys.contains(&e.key))
        .map(|(&n, _)| n)
        .collect();
    let ancestors_missed = ancestors.difference(&rebuilt).count();
    let rebuild_bound = 2 * insert * (bvh.height() as usize + 1);
    let result = AggregateBench {
        world: world.identity()?.0,
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
        Path::new(crate::RESULTS).join(format!("aggregates_{}.md", result.world))
    });
    write_atomically(&path, md.as_bytes())?;
    outln!("{md}")?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// Peak resident set size of this process (Linux `VmHWM`), 0 where unknown.
pub fn peak_memory_bytes() -> u64 {
    crate::load::status_bytes("self", "VmHWM:").unwrap_or(0)
}

fn bench_markdown(r: &AggregateBench) -> String {
    let limit = match r.world.as_str() {
        "village" => Some(60.0),
        "city" => Some(600.0),
        _ => None,
    };
    let verdict = |ok: bool| if ok { "PASS" } else { "FAIL" };
    let mut s = format!(
        "# Aggregate build: {}\n\n`horizon-lab bench-aggregates DIR --insert {}` on this machine (2 cores), one run.\n\n",
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
