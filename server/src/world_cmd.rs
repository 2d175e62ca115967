//! `horizon gen world`, `horizon build`, `horizon cut` and `horizon sweep` (issue 5): a generated world written
//! as a world directory (`world_store.rs`), its similarity-aware BVH bulk-built from the
//! models' descriptors, and the solid-angle cut query on the stored snapshot.

use std::collections::HashMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glam::{Affine3A, Vec3};
use horizon_bvh::{
    Bvh, BvhOptions, CutItem, CutQuery, EntryKind, NewObject, ObjectId, SpatialBaseline, Sphere,
};
use horizon_descriptors::{csd_distance, describe, zernike_distance, DescriptorOptions};
use horizon_mesh::{export_glb, import_file, ExportOptions, ImportOptions, InstancedMesh};
use rayon::prelude::*;
use serde::Serialize;

use crate::world_store::{
    content_hash, DescriptorCache, ModelDescriptors, ModelRecord, ObjectList, ObjectRecord,
    WorldDir, WorldManifest, FORMAT,
};

/// Writes the world `name` generated from `seed` into `dir`. City and city9 replace 3% of
/// their objects by the models found in `assets` (the repository's `assets/models`).
pub fn gen_world(name: &str, dir: &Path, seed: u64, assets: Option<&Path>) -> anyhow::Result<()> {
    let started = Instant::now();
    let extra = if name.starts_with("city") {
        let folder = match assets {
            Some(a) => a.to_path_buf(),
            None => default_assets()?,
        };
        load_user_models(&folder)?
    } else {
        Vec::new()
    };
    let world = horizon_worldgen::generate_world_with(name, seed, &extra)?;
    let generated = started.elapsed().as_secs_f64();

    let store = WorldDir::new(dir);
    std::fs::create_dir_all(store.models())
        .with_context(|| format!("cannot create {}", store.models().display()))?;
    // Export, hash and store every model in parallel; identical GLBs share one file.
    let stored: Vec<(String, u64)> = world
        .models
        .par_iter()
        .map(|(model_name, mesh)| -> anyhow::Result<(String, u64)> {
            let glb = export_glb(mesh, &ExportOptions::plain())
                .with_context(|| format!("cannot export model {model_name}"))?;
            let hash = content_hash(&glb);
            let path = store.model(&hash);
            if !path.exists() {
                crate::mesh_cmd::write_atomically(&path, &glb)?;
            }
            Ok((hash, glb.len() as u64))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut models: Vec<ModelRecord> = Vec::new();
    let mut seen = HashMap::new();
    for ((model_name, _), (hash, bytes)) in world.models.iter().zip(&stored) {
        seen.entry(hash.clone()).or_insert_with(|| {
            models.push(ModelRecord {
                hash: hash.clone(),
                name: model_name.clone(),
                bytes: *bytes,
            });
        });
    }
    let objects = ObjectList {
        objects: world
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| ObjectRecord {
                id: i as u32,
                model: stored[o.model].0.clone(),
                transform: o.transform.to_cols_array(),
            })
            .collect(),
    };
    let manifest = WorldManifest {
        format: FORMAT,
        name: name.to_owned(),
        seed,
        object_count: objects.objects.len(),
        model_count: models.len(),
        models,
    };
    WorldDir::write_json(&store.objects(), &objects)?;
    WorldDir::write_json(&store.manifest(), &manifest)?;
    let bytes: u64 = manifest.models.iter().map(|m| m.bytes).sum();
    println!(
        "{name} (seed {seed}) -> {}: {} objects, {} unique models ({} user), {bytes} model bytes; generated in {generated:.2} s, written in {:.2} s",
        dir.display(),
        manifest.object_count,
        manifest.model_count,
        extra.len(),
        started.elapsed().as_secs_f64() - generated
    );
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
        match import_file(f, &ImportOptions::default()) {
            Ok(imported)
                if imported.mesh.validate().is_ok() && !imported.mesh.bounds().is_empty() =>
            {
                models.push(imported.mesh)
            }
            Ok(_) => eprintln!("horizon: note: skipping empty or invalid {}", f.display()),
            Err(e) => eprintln!("horizon: note: skipping {}: {e}", f.display()),
        }
    }
    if models.is_empty() {
        anyhow::bail!("no importable models in {}", folder.display());
    }
    Ok(models)
}

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
    bvh_seconds: f64,
    write_seconds: f64,
    /// The aggregate stage, unless `--bvh-only`.
    aggregates: Option<horizon_aggregate::BuildReport>,
}

/// Builds the BVH of the world in `dir` with eq. 1's `mu` and `w` and stores its snapshot.
pub fn build(
    dir: &Path,
    mu: f32,
    w: f32,
    aggregates: Option<crate::aggregate_cmd::AggregateArgs>,
    json: bool,
) -> anyhow::Result<()> {
    let progress = std::io::stderr().is_terminal();
    let note = |msg: &str| {
        if progress {
            eprintln!("horizon: {msg}");
        }
    };
    let t0 = Instant::now();
    let store = WorldDir::new(dir);
    let (manifest, objects) = store.load()?;
    let mut cache: DescriptorCache = if store.descriptors().exists() {
        WorldDir::read_json(&store.descriptors())?
    } else {
        DescriptorCache::default()
    };
    let load_seconds = t0.elapsed().as_secs_f64();

    // Descriptors of the models not in the cache, in parallel.
    let t1 = Instant::now();
    let missing: Vec<&ModelRecord> = manifest
        .models
        .iter()
        .filter(|m| !cache.models.contains_key(&m.hash))
        .collect();
    note(&format!(
        "describing {} of {} models",
        missing.len(),
        manifest.models.len()
    ));
    let done = std::sync::atomic::AtomicUsize::new(0);
    let options = DescriptorOptions::default();
    let computed: Vec<(String, ModelDescriptors)> = missing
        .par_iter()
        .map(|m| -> anyhow::Result<(String, ModelDescriptors)> {
            let path = store.model(&m.hash);
            let mesh = import_file(&path, &ImportOptions::default())
                .with_context(|| format!("cannot load {}", path.display()))?
                .mesh;
            let d = describe(&mesh, &options)
                .with_context(|| format!("cannot describe {}", path.display()))?
                .descriptors;
            let b = mesh.bounds();
            let centre = (b.min + b.max) * 0.5;
            let radius = (b.max - b.min).length() * 0.5;
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if progress && (n.is_multiple_of(50) || n == missing.len()) {
                eprint!("\rhorizon: described {n}/{}", missing.len());
                if n == missing.len() {
                    eprintln!();
                }
            }
            Ok((
                m.hash.clone(),
                ModelDescriptors {
                    zernike: d.zernike,
                    csd: d.csd,
                    centre: centre.to_array(),
                    radius,
                },
            ))
        })
        .collect::<anyhow::Result<_>>()?;
    let descriptors_computed = computed.len();
    if !computed.is_empty() {
        cache.models.extend(computed);
        WorldDir::write_json(&store.descriptors(), &cache)?;
    }
    let descriptor_seconds = t1.elapsed().as_secs_f64();

    // Objects: world bounding spheres from the model spheres, then the bulk build.
    let t2 = Instant::now();
    note("building the BVH");
    let new_objects = new_objects(&manifest, &objects, &cache)?;
    let bvh = Bvh::bulk_build(world_options(mu, w, &manifest, &cache), &new_objects)?;
    bvh.validate()?;
    let bvh_seconds = t2.elapsed().as_secs_f64();

    let t3 = Instant::now();
    note("writing the snapshot");
    WorldDir::write_json(&store.bvh(), &bvh)?;
    let write_seconds = t3.elapsed().as_secs_f64();

    // Every node's aggregate (issue 6).
    let aggregates = match aggregates {
        Some(args) => {
            note("loading models");
            let models = crate::aggregate_cmd::load_models(&store, &manifest, &cache)?;
            let report = crate::aggregate_cmd::build_into(
                &bvh,
                &models,
                &crate::aggregate_cmd::aggregate_store(dir),
                args.options(),
                "aggregates",
            )?;
            Some(report)
        }
        None => None,
    };

    let summary = BuildSummary {
        objects: bvh.len(),
        models: manifest.models.len(),
        descriptors_computed,
        descriptors_reused: manifest.models.len() - descriptors_computed,
        nodes: bvh.node_count(),
        height: bvh.height(),
        load_seconds,
        descriptor_seconds,
        bvh_seconds,
        write_seconds,
        aggregates,
    };
    if json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!(
            "built {}: {} objects, {} models ({} described, {} reused), {} nodes, height {}; load {:.2} s, descriptors {:.2} s, bvh {:.2} s, write {:.2} s",
            dir.display(),
            summary.objects,
            summary.models,
            summary.descriptors_computed,
            summary.descriptors_reused,
            summary.nodes,
            summary.height,
            load_seconds,
            descriptor_seconds,
            bvh_seconds,
            write_seconds
        );
        if let Some(a) = &summary.aggregates {
            println!(
                "aggregates: {} nodes, {} built, {} reused, {} failed; {:.1} MB written, {:.1} MB in all; {:.1} s{}{}",
                a.nodes,
                a.built,
                a.reused,
                a.failed.len(),
                a.bytes_built as f64 / 1e6,
                a.bytes_total as f64 / 1e6,
                a.seconds,
                if a.atlas { ", atlased" } else { "" },
                if a.removed.files > 0 {
                    format!(
                        "; {} files of earlier builds removed ({:.1} MB)",
                        a.removed.files,
                        a.removed.bytes as f64 / 1e6
                    )
                } else {
                    String::new()
                }
            );
        }
    }
    if let Some(a) = &summary.aggregates {
        if let Some((node, reason)) = a.failed.first() {
            anyhow::bail!(
                "{} aggregates failed (first: node {node}: {reason})",
                a.failed.len()
            );
        }
    }
    Ok(())
}

/// The BVH's input objects: each object's world bounding sphere (the model's sphere through
/// its transform) and its model's descriptors. Every model must be in `cache`.
/// BVH options for a world: eq. 1's mu and w, and the two descriptor distances normalised by
/// this world's own scales, the median z_diff and the median t_diff between its distinct
/// models (every pair up to 400 models, else a seeded sample of 40,000 pairs). One unit of
/// either term then means "as different as two typical models of this world", which keeps
/// shape, texture and volume on comparable footings whatever the world. Worlds with fewer than
/// two models, or whose medians are 0, keep the defaults.
pub(crate) fn world_options(
    mu: f32,
    w: f32,
    manifest: &WorldManifest,
    cache: &DescriptorCache,
) -> BvhOptions {
    let mut options = BvhOptions::default().with_weights(mu, w);
    let models: Vec<&crate::world_store::ModelDescriptors> = manifest
        .models
        .iter()
        .filter_map(|m| cache.models.get(&m.hash))
        .collect();
    let n = models.len();
    if n < 2 {
        return options;
    }
    let pairs: Vec<(usize, usize)> = if n <= 400 {
        (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .collect()
    } else {
        let mut rng = horizon_worldgen::rng::Rng::new(0x5CA1E);
        (0..40_000)
            .map(|_| {
                let a = ((rng.unit() * n as f32) as usize).min(n - 1);
                let b = ((rng.unit() * (n - 1) as f32) as usize).min(n - 2);
                (a, if b >= a { b + 1 } else { b })
            })
            .collect()
    };
    let median = |mut v: Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let z = median(
        pairs
            .iter()
            .map(|&(a, b)| zernike_distance(&models[a].zernike, &models[b].zernike))
            .collect(),
    );
    let t = median(
        pairs
            .iter()
            .map(|&(a, b)| csd_distance(&models[a].csd, &models[b].csd))
            .collect(),
    );
    if z.is_finite() && z > 0.0 {
        options.shape_scale = z;
    }
    if t.is_finite() && t > 0.0 {
        options.texture_scale = t;
    }
    options
}

/// Eye height of the benchmark viewers, metres (the worlds are Y-up, ground at 0).
pub(crate) const EYE_HEIGHT: f32 = 2.0;

/// `count` seeded viewpoints at eye height, uniform over the horizontal extent of `bounds`:
/// the viewers of `horizon sweep` and `horizon bench-bvh`.
pub(crate) fn viewpoints(bounds: &horizon_bvh::Aabb, seed: u64, count: usize) -> Vec<Vec3> {
    let mut rng = horizon_worldgen::rng::Rng::new(seed);
    (0..count)
        .map(|_| {
            Vec3::new(
                bounds.min.x + rng.unit() * (bounds.max.x - bounds.min.x),
                EYE_HEIGHT,
                bounds.min.z + rng.unit() * (bounds.max.z - bounds.min.z),
            )
        })
        .collect()
}

pub(crate) fn new_objects<'a>(
    manifest: &WorldManifest,
    objects: &ObjectList,
    cache: &'a DescriptorCache,
) -> anyhow::Result<Vec<NewObject<'a>>> {
    let index: HashMap<&str, usize> = manifest
        .models
        .iter()
        .enumerate()
        .map(|(i, m)| (m.hash.as_str(), i))
        .collect();
    let mut out = Vec::with_capacity(objects.objects.len());
    for o in &objects.objects {
        let d = cache
            .models
            .get(&o.model)
            .with_context(|| format!("model {} has no descriptors (run horizon build)", o.model))?;
        let t = Affine3A::from_cols_array(&o.transform);
        let scale = horizon_mesh::transform::max_axis_scale(&t);
        out.push(NewObject {
            model: index[o.model.as_str()] as u64,
            transform: t,
            sphere: Sphere::new(
                t.transform_point3(Vec3::from_array(d.centre)),
                d.radius * scale,
            ),
            shape: &d.zernike,
            texture: &d.csd,
        });
    }
    Ok(out)
}

/// One row of `horizon sweep`: the average query cost of one world's tree built with one
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
pub fn sweep(
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
        let store = WorldDir::new(dir);
        let (manifest, objects) = store.load()?;
        let cache: DescriptorCache = WorldDir::read_json(&store.descriptors())
            .with_context(|| format!("{} is not built (run horizon build)", dir.display()))?;
        let input = new_objects(&manifest, &objects, &cache)?;
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
                let bvh = Bvh::bulk_build(world_options(mu, w, &manifest, &cache), &input)?;
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
                    world: manifest.name.clone(),
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
                world: manifest.name.clone(),
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
        println!("{}", serde_json::to_string(&rows)?);
    } else {
        println!(
            "| world | tree | mu | w | nodes | height | build s | nodes visited | cut size | query ms |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|");
        let show = |v: Option<f32>| v.map_or("-".to_string(), |v| v.to_string());
        for r in &rows {
            println!(
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
            );
        }
    }
    Ok(())
}

/// One entry of `horizon cut --json`.
#[derive(Debug, Serialize)]
struct EntryReport {
    id: u32,
    kind: &'static str,
    parent: Option<u32>,
    covers: u32,
    solid_angle: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    objects: Option<Vec<u32>>,
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

/// Runs the cut query on the stored snapshot of `dir` and prints the entries.
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
    let store = WorldDir::new(dir);
    if !dir.is_dir() {
        anyhow::bail!("{} is not a world directory", dir.display());
    }
    let bvh: Bvh = WorldDir::read_json(&store.bvh())
        .with_context(|| format!("no built world in {} (run horizon build)", dir.display()))?;
    let query = CutQuery {
        position,
        min_solid_angle,
        max_results,
    };
    let started = Instant::now();
    let result = bvh.cut(&query);
    let seconds = started.elapsed().as_secs_f64();
    let mut under = Vec::new();
    let entries: Vec<EntryReport> = result
        .entries
        .iter()
        .map(|e| {
            let (id, objects) = match e.item {
                CutItem::Object(ObjectId(o)) => (o, explain.then(|| vec![o])),
                CutItem::Aggregate(node) => {
                    let objects = explain.then(|| {
                        under.clear();
                        bvh.objects_under(node, &mut under);
                        under.iter().map(|o| o.0).collect()
                    });
                    (node.0, objects)
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
        .collect();
    let aggregates = entries.iter().filter(|e| e.kind == "aggregate").count();
    let report = CutReport {
        objects: entries.len() - aggregates,
        aggregates,
        entries,
        nodes_visited: result.nodes_visited,
        seconds,
    };
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        use std::io::Write;
        let mut out = std::io::BufWriter::new(std::io::stdout().lock());
        writeln!(
            out,
            "cut at {position}: {} entries ({} objects, {} aggregates), {} nodes visited, {:.3} ms",
            report.entries.len(),
            report.objects,
            report.aggregates,
            report.nodes_visited,
            seconds * 1e3
        )?;
        for e in &report.entries {
            let parent = e.parent.map_or("-".to_owned(), |p| p.to_string());
            write!(
                out,
                "{} {} parent {parent} covers {} solid angle {:.3e}",
                e.kind, e.id, e.covers, e.solid_angle
            )?;
            if let Some(objects) = &e.objects {
                write!(out, " objects {objects:?}")?;
            }
            writeln!(out)?;
        }
        out.flush()?;
    }
    Ok(())
}
