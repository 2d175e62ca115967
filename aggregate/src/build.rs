//! The offline aggregate rebuild (core paper section 5): every node of the BVH gets an
//! aggregate, built bottom-up and in parallel by tree level (rayon).
//!
//! A node whose key (`keys.rs`) the store already knows is reused, not rebuilt. A dirty node
//! whose children were reused reads their handoffs back from the store's parts files.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use horizon_bvh::{Bvh, NodeId, ObjectId};
use horizon_descriptors::calibrate::Table1;
use horizon_mesh::{export_glb, import_bytes, ExportOptions, Format, ImportOptions, Instance};
use horizon_mesh::{InstancedMesh, Submesh};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use horizon_atlas::TextureCache;

use crate::budget::Display;
use crate::error::AggregateError;
use crate::generate::{generate_with, Handoff, NodeInput, PartKey, Placement, StageSeconds};
use crate::impostors::{build_impostors, ImpostorPolicy, ImpostorReport};
use crate::keys::{node_keys, KeyHasher};
use crate::options::{AggregateOptions, AtlasPolicy, Method};
use crate::source::{submesh_bytes, ModelSource};
use crate::store::{AggregateEntry, AggregateManifest, AggregateStore, PartList};

/// Decoded bytes of source textures a build keeps for its atlases (see [`TextureCache`]):
/// decoding a texture once per build instead of once per aggregate that samples it.
const TEXTURE_CACHE_BYTES: usize = 512 << 20;

/// Estimated bytes of one level's handoffs a build keeps in memory for the level above. Past
/// it a handoff is left in its parts file, which the parent reads back: on a world of many
/// distinct models the leaves' handoffs are nearly the whole world's geometry.
const HANDOFF_BYTES: usize = 1 << 30;

/// One node's outcome in a level: its entry (if any), its handoff (if built), whether built,
/// and the time its stages took (zero if reused).
type LevelResult = (
    NodeId,
    Option<AggregateEntry>,
    Option<Arc<Handoff>>,
    bool,
    StageSeconds,
);

/// Textures above which [`AtlasPolicy::Auto`] atlases (the paper's rule, section 7).
pub const AUTO_ATLAS_TEXTURES: usize = 100;
/// Texture bytes above which [`AtlasPolicy::Auto`] atlases.
pub const AUTO_ATLAS_BYTES: u64 = 64 * 1024 * 1024;

/// What the rebuild is asked for.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildOptions {
    /// Options of every aggregate.
    pub aggregate: AggregateOptions,
    /// The world's texture count and encoded bytes (for [`AtlasPolicy::Auto`]).
    pub world_textures: (usize, u64),
    /// Which nodes get orthoview impostors after the aggregates (`impostors.rs`).
    pub impostors: ImpostorPolicy,
}

/// Progress of a rebuild, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    /// Aggregates built or reused so far.
    pub done: usize,
    /// Aggregates in the tree.
    pub total: usize,
}

/// What a rebuild did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BuildReport {
    /// Nodes in the tree (each gets an aggregate).
    pub nodes: usize,
    /// Aggregates built by this run.
    pub built: usize,
    /// Aggregates found in the store under their key.
    pub reused: usize,
    /// Aggregates that failed, with the reason (their parents were built without them).
    pub failed: Vec<(u32, String)>,
    /// Bytes of the aggregates built by this run.
    pub bytes_built: u64,
    /// Bytes of every aggregate of the tree.
    pub bytes_total: u64,
    /// Whether aggregates were atlased.
    pub atlas: bool,
    /// Wall time.
    pub seconds: f64,
    /// Levels of the tree.
    pub levels: usize,
    /// Per level, root first: aggregates built and the wall time spent on the level.
    pub level_times: Vec<LevelTime>,
    /// The stages' times summed over the aggregates built (core-seconds: the nodes of a level
    /// run in parallel).
    #[serde(default)]
    pub stages: StageSeconds,
    /// The impostors' stage, if the build made them (its time is in `seconds` too).
    #[serde(default)]
    pub impostors: Option<ImpostorReport>,
}

/// One tree level of a rebuild.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LevelTime {
    /// Depth (0 for the root).
    pub depth: usize,
    /// Nodes on the level.
    pub nodes: usize,
    /// Aggregates built on it (the rest were reused).
    pub built: usize,
    /// Wall time of the level.
    pub seconds: f64,
    /// The stages' times summed over the level's aggregates built.
    #[serde(default)]
    pub stages: StageSeconds,
}

/// What a rebuild did, and the manifest it wrote.
#[derive(Clone, Debug)]
pub struct BuildOutcome {
    /// What the rebuild did.
    pub report: BuildReport,
    /// The manifest it wrote last, naming every node's aggregate.
    pub manifest: AggregateManifest,
}

/// Builds (or reuses) the aggregate of every node of `bvh` into `store`.
pub fn build_aggregates(
    bvh: &Bvh,
    models: &dyn ModelSource,
    store: &dyn AggregateStore,
    options: &BuildOptions,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildOutcome, AggregateError> {
    build(bvh, models, store, options, None, progress, &|| false)
}

/// [`build_aggregates`], stopping with [`AggregateError::Stopped`] before any tree level
/// once `stop` says so. Every level finished before is committed, so the next build reuses
/// it; the manifest is not written.
pub fn build_aggregates_until(
    bvh: &Bvh,
    models: &dyn ModelSource,
    store: &dyn AggregateStore,
    options: &BuildOptions,
    progress: &(dyn Fn(Progress) + Sync),
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<BuildOutcome, AggregateError> {
    build(bvh, models, store, options, None, progress, stop)
}

/// Builds only `roots` and every node below them (which their handoffs need), and writes a
/// manifest of them alone, under a root key of its own so that it is never taken for a whole
/// build. The report's baseline uses it: its upper aggregates (world-space merges of
/// everything below) do not fit in memory on a large world and are in no measured cut.
#[cfg(feature = "baseline")]
pub fn build_subtrees(
    bvh: &Bvh,
    models: &dyn ModelSource,
    store: &dyn AggregateStore,
    options: &BuildOptions,
    roots: &BTreeSet<u32>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildOutcome, AggregateError> {
    build(bvh, models, store, options, Some(roots), progress, &|| {
        false
    })
}

/// The rebuild of every node, or of the subtrees under `only`.
fn build(
    bvh: &Bvh,
    models: &dyn ModelSource,
    store: &dyn AggregateStore,
    options: &BuildOptions,
    only: Option<&BTreeSet<u32>>,
    progress: &(dyn Fn(Progress) + Sync),
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<BuildOutcome, AggregateError> {
    let start = Instant::now();
    options
        .aggregate
        .validate()
        .map_err(|e| AggregateError::Tree(format!("bad options: {e}")))?;
    // Stage 1: levels and keys (Table 1 is in every key and decides every dedup).
    let atlas = resolve_atlas(options);
    let table = Table1::calibrated();
    let levels = levels(bvh);
    let keys = node_keys(bvh, models, &levels, &options.aggregate, atlas, &table)?;
    let only = only.map(|roots| closed_below(bvh, roots));
    let root_key = match &only {
        None => keys.get(&bvh.root()).cloned().unwrap_or_default(),
        // A partial build's key names the nodes it holds.
        Some(set) => {
            let mut h = KeyHasher::new();
            h.write(b"partial");
            for n in set {
                if let Some(k) = keys.get(&NodeId(*n)) {
                    h.write(k.as_bytes());
                }
            }
            h.finish_hex()
        }
    };
    let levels: Vec<Vec<NodeId>> = match &only {
        None => levels,
        Some(set) => levels
            .into_iter()
            .map(|level| level.into_iter().filter(|n| set.contains(&n.0)).collect())
            .collect(),
    };
    let total: usize = levels.iter().map(Vec::len).sum();
    // Stage 2: what the store already has.
    #[cfg_attr(not(feature = "baseline"), allow(unused_mut))]
    let mut known = store.known()?;
    #[cfg(feature = "baseline")]
    if options.aggregate.method == Method::Unoptimized {
        // Baseline handoffs are not persisted: reuse all of a matching build or nothing.
        // A build with failed nodes lacks them in its manifest, and their parents lack their
        // geometry: nothing of it is reused.
        let complete = store
            .manifest()
            .ok()
            .flatten()
            .is_some_and(|m| m.root_key == root_key && m.nodes.len() == total);
        if !complete {
            known.clear();
        }
    }
    // Stage 3: bottom-up, one level at a time, nodes of a level in parallel.
    let done = AtomicUsize::new(0);
    let mut entries: BTreeMap<u32, AggregateEntry> = BTreeMap::new();
    let mut report = BuildReport {
        nodes: total,
        atlas,
        levels: levels.len(),
        ..BuildReport::default()
    };
    let failed: Mutex<Vec<(u32, String)>> = Mutex::new(Vec::new());
    // Decoded source textures, shared by every aggregate of the build.
    let textures = TextureCache::new(TEXTURE_CACHE_BYTES);
    // The level just built or reused: its handoffs in memory (the optimised versions built
    // this run, up to `HANDOFF_BYTES`), and its entries, through which every other handoff
    // (reused ones, those past the budget, and the baseline's whole world-space meshes, too
    // large to hold a level of) is read back from its parts file.
    let mut below: HashMap<NodeId, Arc<Handoff>> = HashMap::new();
    let mut below_entries: HashMap<NodeId, AggregateEntry> = HashMap::new();
    for (depth, level) in levels.iter().enumerate().rev() {
        if stop() {
            return Err(AggregateError::Stopped);
        }
        let level_start = Instant::now();
        let kept_bytes = AtomicUsize::new(0);
        let results: Result<Vec<LevelResult>, AggregateError> = level
            .par_iter()
            .map(|&node| {
                let key = &keys[&node];
                if let Some(e) = known.get(key) {
                    done.fetch_add(1, Ordering::Relaxed);
                    progress(Progress {
                        done: done.load(Ordering::Relaxed),
                        total,
                    });
                    return Ok((node, Some(e.clone()), None, false, StageSeconds::default()));
                }
                let read = Instant::now();
                let children = child_handoffs(
                    bvh,
                    node,
                    &below,
                    &below_entries,
                    &keys,
                    store,
                    models,
                    options.aggregate.method,
                );
                let read_children = read.elapsed().as_secs_f64();
                let mut input = node_input(bvh, node, children, &options.aggregate, atlas)?;
                let generated = match options.aggregate.method {
                    Method::Optimized => {
                        generate_with(&mut input, models, &table, &options.aggregate, &textures)
                    }
                    #[cfg(feature = "baseline")]
                    Method::Unoptimized => {
                        crate::baseline::generate_unoptimized(&input, models, &options.aggregate)
                    }
                };
                let outcome = generated.and_then(|mut out| {
                    let encoding = Instant::now();
                    let parts = encode_parts(node.0, &out.handoff, models)?;
                    out.stats.stages.read_children = read_children;
                    out.stats.stages.parts = encoding.elapsed().as_secs_f64();
                    let mut stages = out.stats.stages;
                    let writing = Instant::now();
                    let entry = store.stage(
                        key.clone(),
                        &out.glb,
                        parts.as_ref().map(|(b, k)| (b.as_slice(), k.clone())),
                        out.stats,
                    )?;
                    stages.write = writing.elapsed().as_secs_f64();
                    Ok((entry, out.handoff, stages))
                });
                done.fetch_add(1, Ordering::Relaxed);
                progress(Progress {
                    done: done.load(Ordering::Relaxed),
                    total,
                });
                match outcome {
                    // The baseline's handoffs are read back from their parts files, so a
                    // level never holds all of them at once.
                    Ok((entry, handoff, stages)) => {
                        let keep = match &handoff {
                            Handoff::Versions(v) => {
                                let bytes = v.values().map(|s| submesh_bytes(s)).sum::<usize>();
                                kept_bytes.fetch_add(bytes, Ordering::Relaxed) + bytes
                                    <= HANDOFF_BYTES
                            }
                            Handoff::Expanded(_) => false,
                        };
                        Ok((
                            node,
                            Some(entry),
                            keep.then(|| Arc::new(handoff)),
                            true,
                            stages,
                        ))
                    }
                    Err(e @ AggregateError::Io { .. }) => Err(e),
                    Err(e) => {
                        if let Ok(mut f) = failed.lock() {
                            f.push((node.0, e.to_string()));
                        }
                        Ok((node, None, None, true, StageSeconds::default()))
                    }
                }
            })
            .collect();
        // The level's files become durable and its entries journalled together, also when
        // it stopped early: what it finished is there for the next build to reuse.
        let committed = store.commit();
        let results = results?;
        committed?;
        let mut next = HashMap::new();
        let mut next_entries = HashMap::new();
        let mut level_time = LevelTime {
            depth,
            nodes: level.len(),
            ..LevelTime::default()
        };
        for (node, entry, handoff, built, stages) in results {
            level_time.built += usize::from(built);
            level_time.stages.add(&stages);
            report.stages.add(&stages);
            if let Some(e) = entry {
                if built {
                    report.built += 1;
                    report.bytes_built += e.stats.bytes as u64;
                } else {
                    report.reused += 1;
                }
                report.bytes_total += e.stats.bytes as u64;
                next_entries.insert(node, e.clone());
                entries.insert(node.0, e);
            }
            if let Some(h) = handoff {
                next.insert(node, h);
            }
        }
        below = next;
        below_entries = next_entries;
        level_time.seconds = level_start.elapsed().as_secs_f64();
        report.level_times.push(level_time);
    }
    report.level_times.reverse();
    report.failed = failed.into_inner().unwrap_or_default();
    report.failed.sort();
    // Stage 4: the impostors, from the aggregates just built or reused.
    let impostors = if options.impostors != ImpostorPolicy::Off && only.is_none() {
        let (impostors, impostor_report) = build_impostors(
            bvh,
            models,
            store,
            &entries,
            options.impostors,
            options.aggregate.min_solid_angle as f32,
            stop,
        )?;
        report.impostors = Some(impostor_report);
        impostors
    } else {
        BTreeMap::new()
    };
    // Stage 5: the manifest, last; then what it no longer names goes.
    let manifest = AggregateManifest {
        format: crate::FORMAT,
        options: options.aggregate,
        atlas,
        root_key,
        nodes: entries,
        impostors,
    };
    store.write_manifest(&manifest)?;
    report.seconds = start.elapsed().as_secs_f64();
    Ok(BuildOutcome { report, manifest })
}

/// `roots` and every node below them.
fn closed_below(bvh: &Bvh, roots: &BTreeSet<u32>) -> BTreeSet<u32> {
    let mut out = BTreeSet::new();
    let mut stack: Vec<NodeId> = roots.iter().map(|&n| NodeId(n)).collect();
    while let Some(n) = stack.pop() {
        if !out.insert(n.0) {
            continue;
        }
        if let Some(node) = bvh.node(n) {
            stack.extend(node.child_nodes());
        }
    }
    out
}

/// Whether aggregates are atlased under `options`.
pub fn resolve_atlas(options: &BuildOptions) -> bool {
    match options.aggregate.atlas {
        AtlasPolicy::Always => true,
        AtlasPolicy::Never => false,
        AtlasPolicy::Auto => {
            options.world_textures.0 > AUTO_ATLAS_TEXTURES
                || options.world_textures.1 > AUTO_ATLAS_BYTES
        }
    }
}

/// The tree's nodes by depth, root first.
pub fn levels(bvh: &Bvh) -> Vec<Vec<NodeId>> {
    let mut out: Vec<Vec<NodeId>> = Vec::new();
    if bvh.is_empty() {
        return out;
    }
    let mut current = vec![bvh.root()];
    while !current.is_empty() {
        let mut next = Vec::new();
        for &n in &current {
            if let Some(node) = bvh.node(n) {
                next.extend(node.child_nodes());
            }
        }
        out.push(current);
        current = next;
    }
    out
}

/// The input of one node's aggregate.
fn node_input(
    bvh: &Bvh,
    node: NodeId,
    children: Vec<Arc<Handoff>>,
    options: &AggregateOptions,
    atlas: bool,
) -> Result<NodeInput, AggregateError> {
    let n = bvh
        .node(node)
        .ok_or_else(|| AggregateError::Tree(format!("no node {}", node.0)))?;
    let bound = n.bound();
    let mut ids: Vec<ObjectId> = Vec::new();
    bvh.objects_under(node, &mut ids);
    let mut placements: Vec<Placement> = ids
        .iter()
        .filter_map(|&o| bvh.object(o))
        .map(|o| Placement {
            model: o.model(),
            transform: o.transform(),
            centre: o.sphere().centre,
            radius: o.sphere().radius,
        })
        .collect();
    placements.sort_by(|a, b| {
        a.model.cmp(&b.model).then_with(|| {
            let (x, y) = (a.transform.to_cols_array(), b.transform.to_cols_array());
            x.iter()
                .zip(&y)
                .map(|(p, q)| p.total_cmp(q))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        })
    });
    Ok(NodeInput {
        node: node.0,
        display: Display::of(bound.centre, bound.radius, n.r_max(), options),
        outer_radius: n.outer_sphere().radius,
        placements,
        children,
        atlas,
    })
}

/// The handoffs of `node`'s child nodes: built this run, or read back from the store through
/// their entries (`below_entries`: every child that has an aggregate, built or reused).
#[allow(clippy::too_many_arguments)]
fn child_handoffs(
    bvh: &Bvh,
    node: NodeId,
    below: &HashMap<NodeId, Arc<Handoff>>,
    below_entries: &HashMap<NodeId, AggregateEntry>,
    keys: &HashMap<NodeId, String>,
    store: &dyn AggregateStore,
    models: &dyn ModelSource,
    method: Method,
) -> Vec<Arc<Handoff>> {
    let Some(n) = bvh.node(node) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut children: Vec<NodeId> = n.child_nodes().collect();
    children.sort_by(|a, b| keys.get(a).cmp(&keys.get(b)));
    for c in children {
        if let Some(h) = below.get(&c) {
            out.push(h.clone());
        } else if let Some(h) = below_entries
            .get(&c)
            .and_then(|e| decode_parts(store, e, models, method))
        {
            out.push(Arc::new(h));
        }
    }
    out
}

/// zstd level of parts files: float geometry written losslessly compresses about 5x at
/// level 3 (a 6.6 MB parts file of the 60,000-building city: 1.3 MB), at a small fraction of
/// a node's build time. On a world of distinct models every tree level's parts hold about the
/// world's geometry once, so this is most of the build's disk.
const PARTS_ZSTD_LEVEL: i32 = 3;

/// The parts file of a handoff (a zstd-compressed GLB; a plain GLB, as older builds wrote,
/// reads back too), with no materials (the parent takes materials from the source
/// models), and its [`PartList`]. Versions: every version as one submesh with one identity
/// instance, keyed by (model hash, submesh). The baseline's expanded part: its world-space
/// submeshes and instances as they are, each submesh keyed by its material's (model hash,
/// material index).
fn encode_parts(
    node: u32,
    handoff: &Handoff,
    models: &dyn ModelSource,
) -> Result<Option<(Vec<u8>, PartList)>, AggregateError> {
    let (mesh, keys) = match handoff {
        Handoff::Versions(versions) => {
            let mut mesh = InstancedMesh::default();
            let mut keys = Vec::new();
            for (&(model, s), sub) in versions {
                let hash = models.hash(model)?;
                mesh.instances.push(Instance {
                    submesh: mesh.submeshes.len(),
                    transform: glam::Affine3A::IDENTITY,
                });
                mesh.submeshes.push(Submesh {
                    material: None,
                    ..(**sub).clone()
                });
                keys.push((hash, s));
            }
            (mesh, keys)
        }
        Handoff::Expanded(part) => {
            let mut keys = Vec::new();
            for sub in &part.mesh.submeshes {
                keys.push(match sub.material.and_then(|m| part.material_keys.get(m)) {
                    Some(&(model, m)) => {
                        let index = u32::try_from(m).map_err(|_| AggregateError::Glb {
                            node,
                            reason: format!("material index {m} out of range"),
                        })?;
                        (models.hash(model)?, index)
                    }
                    None => (String::new(), u32::MAX),
                });
            }
            let mesh = InstancedMesh {
                submeshes: part
                    .mesh
                    .submeshes
                    .iter()
                    .map(|sub| Submesh {
                        material: None,
                        ..sub.clone()
                    })
                    .collect(),
                instances: part.mesh.instances.clone(),
                materials: Vec::new(),
                textures: Vec::new(),
            };
            (mesh, keys)
        }
    };
    let glb = export_glb(&mesh, &ExportOptions::parts()).map_err(|e| AggregateError::Glb {
        node,
        reason: e.to_string(),
    })?;
    let bytes = zstd::bulk::compress(&glb, PARTS_ZSTD_LEVEL).map_err(|e| AggregateError::Glb {
        node,
        reason: format!("the parts file does not compress: {e}"),
    })?;
    Ok(Some((bytes, keys)))
}

/// Reads a handoff back from its parts file; `None` if it is missing or does not match its
/// entry (the parent then falls back to the source models, or, for the baseline, goes
/// without the child).
fn decode_parts(
    store: &dyn AggregateStore,
    entry: &AggregateEntry,
    models: &dyn ModelSource,
    method: Method,
) -> Option<Handoff> {
    let hash = entry.parts.as_ref()?;
    let stored = store.parts(hash).ok()?;
    let bytes = if stored.starts_with(b"glTF") {
        stored
    } else {
        zstd::stream::decode_all(stored.as_slice()).ok()?
    };
    let mesh = import_bytes(&bytes, Format::Glb, None, &ImportOptions::trusted())
        .ok()?
        .mesh;
    if mesh.submeshes.len() != entry.part_keys.len() {
        return None;
    }
    #[cfg(feature = "baseline")]
    if method == Method::Unoptimized {
        return crate::baseline::decode_expanded(mesh, entry, models);
    }
    #[cfg(not(feature = "baseline"))]
    let _ = method;
    let mut versions: BTreeMap<PartKey, Arc<Submesh>> = BTreeMap::new();
    for (sub, (hash, s)) in mesh.submeshes.into_iter().zip(&entry.part_keys) {
        let model = models.by_hash(hash)?;
        let material = models
            .model(model)
            .ok()?
            .mesh
            .submeshes
            .get(*s as usize)?
            .material;
        versions.insert((model, *s), Arc::new(Submesh { material, ..sub }));
    }
    Some(Handoff::Versions(versions))
}
