//! One node's aggregate (core paper sections 5 to 7): gather the children's representations,
//! cull what cannot show, bound what enters the merge ([`MERGE_TRIANGLES`]), dedup
//! near-duplicates (Table 1), merge into one instanced mesh, simplify with IAS to the node's budget, draw the objects whose simplified parts lost their
//! shape (and, over the budget, the smallest others) as box proxies (`proxy.rs`), atlas, merge the parts placed alike and bake the
//! placements that cost less written out than instanced into one submesh
//! (`InstancedMesh::merge_coplaced_submeshes`, `bake_cheap_instances`: fewer draw calls and
//! less JSON), encode (`ExportOptions::aggregate`: vertices shared in runs, 8-bit normals,
//! 16-bit UVs and instance rotations, 16-bit positions within [`POSITION_PIXELS`]).
//!
//! What a node hands its parent ([`Handoff`]) is not its final GLB but the simplified
//! version of every model submesh it drew, in model space. The parent then instances one
//! version per model submesh across all its children (the coarsest, which is the closest to
//! what the parent needs), so instancing survives all the way up the tree instead of every
//! child aggregate becoming one more unique mesh. Textures always come from the source
//! models, never from a child's atlas, so they are resampled once.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Vec3};
use horizon_atlas::{build_atlas_with, AtlasOptions, TextureCache};
use horizon_descriptors::calibrate::Table1;
use horizon_mesh::{export_glb, ExportOptions, Instance, InstancedMesh, Material, Submesh};
use horizon_simplify::{simplify, SimplifyOptions, Target};
use serde::{Deserialize, Serialize};

use crate::budget::{dedup_distance, Display};
use crate::dedup::{plan, ModelUse};
use crate::error::AggregateError;
use crate::options::AggregateOptions;
use crate::proxy::{ObjectPlacement, ProxyInput};
use crate::source::{ModelSource, SourceModel};

/// A model submesh: (model number, submesh index in the model).
pub type PartKey = (u64, u32);

/// One object placed under the node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// The BVH's model number.
    pub model: u64,
    /// Model-to-world transform.
    pub transform: Affine3A,
    /// Centre of its world bounding sphere.
    pub centre: Vec3,
    /// Radius of its world bounding sphere.
    pub radius: f32,
}

/// What a built node hands its parent.
#[derive(Clone, Debug)]
pub enum Handoff {
    /// The optimised pipeline: the simplified version of every model submesh drawn.
    Versions(BTreeMap<PartKey, Arc<Submesh>>),
    /// The unoptimised baseline: the whole simplified mesh, world space, single instances.
    Expanded(Arc<ExpandedPart>),
}

/// The unoptimised baseline's handoff: a world-space mesh and where its materials came from.
#[derive(Clone, Debug)]
pub struct ExpandedPart {
    /// Single-instance submeshes in world space, without materials or textures: a submesh's
    /// material index points into `material_keys`.
    pub mesh: InstancedMesh,
    /// For each material, its source (model, material index).
    pub material_keys: Vec<(u64, usize)>,
}

/// Everything one node's aggregate is made from.
#[derive(Debug)]
pub struct NodeInput {
    /// The node's number (for messages).
    pub node: u32,
    /// Where it can be shown (budgets).
    pub display: Display,
    /// Radius of a sphere holding the whole aggregate (for the dedup distance).
    pub outer_radius: f32,
    /// Every object under the node.
    pub placements: Vec<Placement>,
    /// The handoffs of the node's child nodes that have one (none for a leaf).
    pub children: Vec<Arc<Handoff>>,
    /// Whether to atlas (resolved from the policy by the caller).
    pub atlas: bool,
}

/// What building one aggregate did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NodeStats {
    /// Objects under the node.
    pub placements: usize,
    /// Objects left out as smaller than `cull_pixels`.
    pub culled: usize,
    /// Model-internal instances (parts) of kept objects left out as smaller than
    /// `cull_pixels`.
    #[serde(default)]
    pub culled_parts: usize,
    /// Distinct models drawn before dedup.
    pub models: usize,
    /// Models replaced by a near-duplicate.
    pub replaced: usize,
    /// The triangle budget.
    pub budget: u64,
    /// Expanded triangles of the merge.
    pub triangles_in: u64,
    /// Expanded triangles of the aggregate.
    pub triangles_out: u64,
    /// Triangles stored (unique) in the aggregate.
    pub unique_triangles: u64,
    /// Submeshes and instances in the aggregate.
    pub submeshes: usize,
    /// Instances in the aggregate.
    pub instances: usize,
    /// Materials and textures in the aggregate.
    pub materials: usize,
    /// Textures in the aggregate.
    pub textures: usize,
    /// Encoded texture bytes in the aggregate.
    pub texture_bytes: usize,
    /// GLB bytes.
    pub bytes: usize,
    /// Wall time of building it, seconds.
    #[serde(default)]
    pub seconds: f64,
    /// The simplifier's error (RMS quadric distance, world units), 0 when not simplified.
    #[serde(default)]
    pub error: f64,
    /// That error in pixels at the nearest display distance.
    #[serde(default)]
    pub error_pixels: f64,
    /// Objects drawn as box proxies because their simplified parts lost their shape
    /// (`proxy.rs`).
    #[serde(default)]
    pub proxied_shape: usize,
    /// Objects drawn as box proxies to fit the budget.
    #[serde(default)]
    pub proxied_budget: usize,
    /// Of `proxied_budget`, the objects drawn as box proxies without entering the merge,
    /// because the node's larger objects already fill [`MERGE_TRIANGLES`].
    #[serde(default)]
    pub proxied_merge: usize,
    /// The largest footprint among the latter, pixels at the nearest display distance.
    #[serde(default)]
    pub proxied_pixels: f64,
    /// Where the wall time went, stage by stage.
    #[serde(default)]
    pub stages: StageSeconds,
}

/// Wall time of one aggregate's stages, seconds: the pipeline of [`generate_with`] and the
/// build's reading and writing around it (`build.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageSeconds {
    /// Reading the handoffs of children reused from the store (their parts files).
    #[serde(default)]
    pub read_children: f64,
    /// Gathering versions, culling and loading the source models.
    #[serde(default)]
    pub gather: f64,
    /// The dedup plan (Table 1).
    #[serde(default)]
    pub dedup: f64,
    /// Merging into one instanced mesh.
    #[serde(default)]
    pub merge: f64,
    /// IAS (or the baseline's QEM) and the handoff's versions.
    #[serde(default)]
    pub simplify: f64,
    /// Box proxies.
    #[serde(default)]
    pub proxy: f64,
    /// The texture atlas.
    #[serde(default)]
    pub atlas: f64,
    /// Merging co-placed submeshes, baking cheap instances and encoding the GLB.
    #[serde(default)]
    pub encode: f64,
    /// Encoding the parts file.
    #[serde(default)]
    pub parts: f64,
    /// Writing both files as the store's temporaries.
    #[serde(default)]
    pub write: f64,
}

impl StageSeconds {
    /// The stages' names and times, in pipeline order.
    pub fn named(&self) -> [(&'static str, f64); 10] {
        [
            ("read children", self.read_children),
            ("gather", self.gather),
            ("dedup", self.dedup),
            ("merge", self.merge),
            ("simplify", self.simplify),
            ("proxy", self.proxy),
            ("atlas", self.atlas),
            ("encode", self.encode),
            ("parts", self.parts),
            ("write", self.write),
        ]
    }

    /// Adds `other`'s times to these.
    pub fn add(&mut self, other: &StageSeconds) {
        self.read_children += other.read_children;
        self.gather += other.gather;
        self.dedup += other.dedup;
        self.merge += other.merge;
        self.simplify += other.simplify;
        self.proxy += other.proxy;
        self.atlas += other.atlas;
        self.encode += other.encode;
        self.parts += other.parts;
        self.write += other.write;
    }
}

/// Times consecutive stages: each [`Lap::lap`] returns the seconds since the previous one.
struct Lap(Instant);

impl Lap {
    fn new() -> Self {
        Self(Instant::now())
    }

    fn lap(&mut self) -> f64 {
        let now = Instant::now();
        let seconds = now.duration_since(self.0).as_secs_f64();
        self.0 = now;
        seconds
    }
}

/// A built aggregate.
#[derive(Debug)]
pub struct NodeOutput {
    /// The aggregate as a GLB.
    pub glb: Vec<u8>,
    /// What the parent gets.
    pub handoff: Handoff,
    /// What it took.
    pub stats: NodeStats,
}

/// Builds one node's aggregate by the optimised pipeline (the rebuild runs the unoptimised
/// baseline instead where `options.method` asks for it).
pub fn generate(
    input: &mut NodeInput,
    models: &dyn ModelSource,
    table: &Table1,
    options: &AggregateOptions,
) -> Result<NodeOutput, AggregateError> {
    generate_with(input, models, table, options, &TextureCache::new(0))
}

/// [`generate`], decoding the textures it atlases through `textures`, which the aggregates
/// of one build share (the same bytes come out either way). Takes the children's handoffs
/// out of `input`, so that what the merge does not use is freed as soon as it is known.
pub fn generate_with(
    input: &mut NodeInput,
    models: &dyn ModelSource,
    table: &Table1,
    options: &AggregateOptions,
    textures: &TextureCache,
) -> Result<NodeOutput, AggregateError> {
    let start = Instant::now();
    let mut lap = Lap::new();
    let mut stats = NodeStats {
        placements: input.placements.len(),
        budget: input.display.triangle_budget(options),
        ..NodeStats::default()
    };
    // Stage 1, gather: the coarsest version of every model submesh among the children.
    let mut versions = coarsest_versions(&std::mem::take(&mut input.children));
    // Stage 2, cull: objects under `cull_pixels` at the nearest display distance cannot show.
    let kept = cull(input, options);
    stats.culled = input.placements.len() - kept.len();
    // Stage 2b, bound the merge: past MERGE_TRIANGLES, the smallest go straight to proxies.
    let (kept, forced) = bound_merge(input, kept, &versions, models)?;
    stats.proxied_merge = forced.len();
    if !forced.is_empty() {
        let merged: std::collections::BTreeSet<u64> = kept.iter().map(|p| p.model).collect();
        versions.retain(|(model, _), _| merged.contains(model));
    }
    // Stage 3, dedup (section 5.1).
    let sources = load_models(kept.iter().map(|p| p.model), models)?;
    stats.stages.gather = lap.lap();
    let replacements = if options.dedup {
        dedup_plan(input, &kept, &sources, table, options)
    } else {
        BTreeMap::new()
    };
    stats.models = sources.len();
    stats.replaced = replacements.len();
    let mut sources = sources;
    for r in replacements.values() {
        if let std::collections::btree_map::Entry::Vacant(e) = sources.entry(r.by) {
            e.insert(models.model(r.by)?);
        }
    }
    stats.stages.dedup = lap.lap();
    // Stage 4, merge: one submesh per drawn model submesh, one instance per placement and
    // model-internal instance.
    let mut merge = Merger::default();
    let mut part_of_submesh: Vec<PartKey> = Vec::new();
    let mut slot: HashMap<PartKey, usize> = HashMap::new();
    let mut objects: Vec<ObjectPlacement> = Vec::with_capacity(kept.len());
    let mut instance_objects: Vec<usize> = Vec::new();
    for p in &kept {
        let (model, align) = match replacements.get(&p.model) {
            Some(r) => (r.by, r.align),
            None => (p.model, Affine3A::IDENTITY),
        };
        let object = objects.len();
        objects.push(ObjectPlacement {
            model,
            transform: p.transform * align,
            centre: p.centre,
            radius: p.radius,
        });
        let source = &sources[&model];
        for (s, inner) in source.placements.iter().enumerate() {
            let key = (model, s as u32);
            let (centre, radius) = source.part_spheres[s];
            for m in inner {
                let transform = p.transform * align * *m;
                // Beyond whole objects, parts under `cull_pixels` are left out too.
                let scale = horizon_mesh::transform::max_axis_scale(&transform);
                let part_pixels = input
                    .display
                    .object_pixels(transform.transform_point3(centre), radius * scale);
                if part_pixels < options.cull_pixels && kept.len() > 1 {
                    stats.culled_parts += 1;
                    continue;
                }
                // The children's coarsest version, else the source part: a part can have no
                // version although its model has some, when every child that drew the model
                // culled the part, drew the model as a look-alike, or failed, while here it
                // is big enough to show.
                let index = *slot.entry(key).or_insert_with(|| {
                    let sub = versions
                        .get(&key)
                        .map_or_else(|| source.mesh.submeshes[s].clone(), |v| (**v).clone());
                    part_of_submesh.push(key);
                    merge.submesh(model, source, sub)
                });
                merge.mesh.instances.push(Instance {
                    submesh: index,
                    transform,
                });
                instance_objects.push(object);
            }
        }
    }
    let material_keys = std::mem::take(&mut merge.material_keys);
    let merged = merge.mesh;
    let merged_instance_submeshes: Vec<usize> =
        merged.instances.iter().map(|i| i.submesh).collect();
    stats.triangles_in = merged.expanded_triangle_count();
    stats.stages.merge = lap.lap();
    // Stage 5, simplify with IAS to the budget.
    let (simplified, kept_parts) = if stats.triangles_in > stats.budget {
        let s = simplify(
            &merged,
            Target::Triangles(stats.budget),
            &SimplifyOptions::default(),
        )
        .map_err(|source| AggregateError::Simplify {
            node: input.node,
            source,
        })?;
        stats.error = s.report.error;
        stats.error_pixels = input.display.pixels_of_length(s.report.error);
        (s.mesh, s.kept)
    } else {
        let n = merged.submeshes.len();
        (merged, (0..n).map(Some).collect())
    };
    // A version names its material as its source model does, the way a parent reads it back
    // from the parts file: the merged index means nothing outside this aggregate.
    let handoff = Handoff::Versions(
        part_of_submesh
            .iter()
            .zip(&kept_parts)
            .filter_map(|(key, k)| {
                let sub = &simplified.submeshes[(*k)?];
                let material = sub
                    .material
                    .and_then(|m| material_keys.get(m))
                    .map(|&(_, m)| m);
                Some((
                    *key,
                    Arc::new(Submesh {
                        material,
                        ..sub.clone()
                    }),
                ))
            })
            .collect(),
    );
    stats.stages.simplify = lap.lap();
    // Stage 6, box proxies for the objects whose simplified parts lost their shape, and
    // over the budget for the smallest others (this aggregate only: the handoff above keeps
    // every version). IAS kept the instances of the submeshes it kept, in order.
    let instance_objects: Vec<usize> = merged_instance_submeshes
        .iter()
        .zip(&instance_objects)
        .filter(|(s, _)| kept_parts[**s].is_some())
        .map(|(_, &o)| o)
        .collect();
    let parts: Vec<(PartKey, Option<usize>)> = part_of_submesh
        .iter()
        .copied()
        .zip(kept_parts.iter().copied())
        .collect();
    let (simplified, proxies) = crate::proxy::apply(
        simplified,
        &ProxyInput {
            instance_objects: &instance_objects,
            objects: &objects,
            parts: &parts,
            sources: &sources,
            forced: &forced,
            models,
            budget: stats.budget,
            display: &input.display,
        },
    );
    stats.proxied_shape = proxies.shape;
    stats.proxied_budget = proxies.budget;
    stats.proxied_pixels = proxies.largest_pixels;
    stats.stages.proxy = lap.lap();
    // Stage 7, atlas (section 7) and encode.
    let out = if input.atlas {
        let mut atlas_options = AtlasOptions {
            max_bytes: options.atlas_bytes,
            max_side: input.display.atlas_side(options),
            ..AtlasOptions::default()
        };
        // Charts that do not fit the display's side even at a texel each (thousands of box
        // proxies at an upper node) get a larger atlas, up to MAX_ATLAS_SIDE, its byte
        // budget grown with its area.
        loop {
            match build_atlas_with(&simplified, &atlas_options, textures) {
                Ok((atlased, _)) => break atlased,
                Err(horizon_atlas::AtlasError::DoesNotFit { .. })
                    if atlas_options.max_side < MAX_ATLAS_SIDE =>
                {
                    atlas_options.max_side *= 2;
                    atlas_options.max_bytes = atlas_options.max_bytes.saturating_mul(4);
                }
                Err(source) => {
                    return Err(AggregateError::Atlas {
                        node: input.node,
                        source,
                    })
                }
            }
        }
    } else {
        simplified
    };
    stats.stages.atlas = lap.lap();
    // Stage 8, one draw per set of placements: parts placed alike (a model's submeshes,
    // one material after the atlas) merge, and cheap placements (single ones, tiny parts)
    // are baked into shared geometry.
    let out = out.merge_coplaced_submeshes().bake_cheap_instances();
    let mut out = finish(input, out, handoff, stats)?;
    out.stats.stages.encode = lap.lap();
    out.stats.seconds = start.elapsed().as_secs_f64();
    Ok(out)
}

/// How far, in pixels as near as the aggregate's geometry can be shown
/// (`Display::nearest_length_of_pixels`), storing its positions as 16-bit integers may move a
/// vertex (`ExportOptions::position_tolerance`). An eighth of a pixel is under the 8-bit
/// normals' shading change and far under IAS's own error at the default budget (`budget.rs`,
/// `lab/results/budget_village.md`); a run it refuses keeps float positions.
pub const POSITION_PIXELS: f64 = 0.125;

/// Encodes the aggregate and fills in its counts.
pub(crate) fn finish(
    input: &NodeInput,
    mesh: InstancedMesh,
    handoff: Handoff,
    mut stats: NodeStats,
) -> Result<NodeOutput, AggregateError> {
    let node = input.node;
    let tolerance = input.display.nearest_length_of_pixels(POSITION_PIXELS) as f32;
    let glb = export_glb(&mesh, &ExportOptions::aggregate(tolerance)).map_err(|e| {
        AggregateError::Glb {
            node,
            reason: e.to_string(),
        }
    })?;
    stats.triangles_out = mesh.expanded_triangle_count();
    stats.unique_triangles = mesh.unique_triangle_count();
    stats.submeshes = mesh.submeshes.len();
    stats.instances = mesh.instances.len();
    stats.materials = mesh.materials.len();
    stats.textures = mesh.textures.len();
    stats.texture_bytes = mesh.textures.iter().map(|t| t.bytes.len()).sum();
    stats.bytes = glb.len();
    Ok(NodeOutput {
        glb,
        handoff,
        stats,
    })
}

/// For every model submesh any child drew, its version with the fewest triangles (ties:
/// the first child's).
fn coarsest_versions(children: &[Arc<Handoff>]) -> BTreeMap<PartKey, Arc<Submesh>> {
    let mut out: BTreeMap<PartKey, Arc<Submesh>> = BTreeMap::new();
    for child in children {
        let Handoff::Versions(v) = child.as_ref() else {
            continue;
        };
        for (key, sub) in v {
            match out.get(key) {
                Some(have) if have.indices.len() <= sub.indices.len() => {}
                _ => {
                    out.insert(*key, sub.clone());
                }
            }
        }
    }
    out
}

/// The largest atlas side an aggregate grows to when its charts do not fit the side its
/// display asks for (`Display::atlas_side`).
pub const MAX_ATLAS_SIDE: u32 = 4096;

/// Unique triangles a node's merge may hold (what IAS loads: its memory grows with them, about
/// a kilobyte each). On a world of distinct models whose parts IAS cannot simplify (seams,
/// materials), every level would otherwise hand its parent nearly the full detail of all it
/// covers, and a node over 10,000 buildings would load 14 million triangles. Past it, objects
/// are taken largest on screen first and the rest are drawn as box proxies (`proxy.rs`),
/// without their models entering the merge.
pub const MERGE_TRIANGLES: u64 = 1_000_000;

/// Splits the kept placements into those merged and those drawn as proxies straight away
/// ([`MERGE_TRIANGLES`]). A model's triangles are its versions' where children drew it, its
/// own otherwise, and count once however many objects place it. Reads no model.
fn bound_merge(
    input: &NodeInput,
    kept: Vec<Placement>,
    versions: &BTreeMap<PartKey, Arc<Submesh>>,
    models: &dyn ModelSource,
) -> Result<(Vec<Placement>, Vec<ObjectPlacement>), AggregateError> {
    let mut version_triangles: BTreeMap<u64, u64> = BTreeMap::new();
    for (&(model, _), sub) in versions {
        *version_triangles.entry(model).or_default() += sub.triangle_count();
    }
    let mut triangles: BTreeMap<u64, u64> = BTreeMap::new();
    for p in &kept {
        if let std::collections::btree_map::Entry::Vacant(e) = triangles.entry(p.model) {
            e.insert(match version_triangles.get(&p.model) {
                Some(&t) => t,
                None => models.triangles(p.model)?,
            });
        }
    }
    if triangles.values().sum::<u64>() <= MERGE_TRIANGLES {
        return Ok((kept, Vec::new()));
    }
    let mut order: Vec<(f64, usize)> = kept
        .iter()
        .enumerate()
        .map(|(i, p)| (input.display.object_pixels(p.centre, p.radius), i))
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut merged_models: std::collections::BTreeSet<u64> = Default::default();
    let mut total = 0;
    let mut take = vec![false; kept.len()];
    for (_, i) in order {
        let model = kept[i].model;
        let added = if merged_models.contains(&model) {
            0
        } else {
            triangles[&model]
        };
        // The largest object always enters, so that an aggregate is never all proxies.
        if total + added <= MERGE_TRIANGLES || total == 0 {
            total += added;
            merged_models.insert(model);
            take[i] = true;
        }
    }
    let (mut merged, mut forced) = (Vec::new(), Vec::new());
    for (p, t) in kept.into_iter().zip(take) {
        if t {
            merged.push(p);
        } else {
            forced.push(ObjectPlacement {
                model: p.model,
                transform: p.transform,
                centre: p.centre,
                radius: p.radius,
            });
        }
    }
    Ok((merged, forced))
}

/// The placements big enough to show, or the largest one if none is.
fn cull(input: &NodeInput, options: &AggregateOptions) -> Vec<Placement> {
    let kept: Vec<Placement> = input
        .placements
        .iter()
        .filter(|p| input.display.object_pixels(p.centre, p.radius) >= options.cull_pixels)
        .copied()
        .collect();
    if !kept.is_empty() || input.placements.is_empty() {
        return kept;
    }
    let largest = input
        .placements
        .iter()
        .max_by(|a, b| a.radius.total_cmp(&b.radius))
        .copied();
    largest.into_iter().collect()
}

/// Every distinct model of `ids`, loaded once.
pub(crate) fn load_models(
    ids: impl Iterator<Item = u64>,
    models: &dyn ModelSource,
) -> Result<BTreeMap<u64, Arc<SourceModel>>, AggregateError> {
    let mut out = BTreeMap::new();
    for id in ids {
        if let std::collections::btree_map::Entry::Vacant(e) = out.entry(id) {
            e.insert(models.model(id)?);
        }
    }
    Ok(out)
}

/// The dedup plan for the kept placements (section 5.1).
fn dedup_plan(
    input: &NodeInput,
    kept: &[Placement],
    sources: &BTreeMap<u64, Arc<SourceModel>>,
    table: &Table1,
    options: &AggregateOptions,
) -> BTreeMap<u64, crate::dedup::Replacement> {
    let mut usage: BTreeMap<u64, (usize, f32)> = BTreeMap::new();
    for p in kept {
        let u = usage.entry(p.model).or_insert((0, 0.0));
        u.0 += 1;
        u.1 = u.1.max(p.radius);
    }
    let uses: Vec<ModelUse> = usage
        .iter()
        .map(|(&model, &(placements, radius))| {
            let s = &sources[&model];
            ModelUse {
                model,
                shape: &s.shape,
                texture: &s.texture,
                radius,
                placements,
                frame: s.frame.as_ref(),
            }
        })
        .collect();
    plan(&uses, dedup_distance(input.outer_radius, options), table)
}

/// Accumulates submeshes, materials and textures from several sources, sharing each source
/// material and texture once.
#[derive(Debug, Default)]
pub(crate) struct Merger {
    pub(crate) mesh: InstancedMesh,
    materials: HashMap<(u64, usize), usize>,
    textures: HashMap<(u64, usize), usize>,
    pub(crate) material_keys: Vec<(u64, usize)>,
}

impl Merger {
    /// Adds `sub` (a submesh of `source`, or a version of one) with its material; returns
    /// its index.
    pub(crate) fn submesh(&mut self, model: u64, source: &SourceModel, mut sub: Submesh) -> usize {
        sub.material = sub
            .material
            .and_then(|m| self.material(model, m, &source.mesh));
        self.mesh.submeshes.push(sub);
        self.mesh.submeshes.len() - 1
    }

    /// The merged index of material `m` of `model` (found at that index of `from`, the
    /// model's mesh), adding it and its texture, each shared by (model, index), if new.
    pub(crate) fn material(&mut self, model: u64, m: usize, from: &InstancedMesh) -> Option<usize> {
        let key = (model, m);
        if let Some(&i) = self.materials.get(&key) {
            return Some(i);
        }
        let mut material: Material = from.materials.get(m)?.clone();
        if let Some(t) = material.base_color_texture.as_mut() {
            let tkey = (model, t.texture);
            let index = match self.textures.get(&tkey) {
                Some(&i) => i,
                None => {
                    let texture = from.textures.get(t.texture)?.clone();
                    self.mesh.textures.push(texture);
                    self.textures.insert(tkey, self.mesh.textures.len() - 1);
                    self.mesh.textures.len() - 1
                }
            };
            t.texture = index;
        }
        self.mesh.materials.push(material);
        self.material_keys.push(key);
        let i = self.mesh.materials.len() - 1;
        self.materials.insert(key, i);
        Some(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::InMemoryModels;

    /// A model of one submesh with `triangles` triangles (all on one degenerate corner: only
    /// the count matters here).
    fn model(hash: &str, triangles: usize) -> SourceModel {
        let mesh = InstancedMesh {
            submeshes: vec![Submesh {
                positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
                indices: [0, 1, 2].repeat(triangles),
                ..Submesh::default()
            }],
            instances: vec![Instance {
                submesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            ..InstancedMesh::default()
        };
        SourceModel::new(hash.into(), mesh, Vec::new(), Vec::new())
    }

    fn input(placements: Vec<Placement>) -> NodeInput {
        NodeInput {
            node: 0,
            display: Display::of(Vec3::ZERO, 50.0, 10.0, &AggregateOptions::default()),
            outer_radius: 60.0,
            placements,
            children: Vec::new(),
            atlas: false,
        }
    }

    fn at(model: u64, x: f32, radius: f32) -> Placement {
        Placement {
            model,
            transform: Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)),
            centre: Vec3::new(x, 0.0, 0.0),
            radius,
        }
    }

    #[test]
    fn the_merge_takes_the_largest_objects_up_to_its_bound_and_proxies_the_rest() {
        let half = MERGE_TRIANGLES as usize / 2 + 1;
        let models = InMemoryModels::new(vec![model("a", half), model("b", half), model("c", 10)]);
        // Under the bound: everything merges.
        let small = input(vec![at(0, 0.0, 5.0), at(2, 10.0, 1.0)]);
        let (merged, forced) =
            bound_merge(&small, small.placements.clone(), &BTreeMap::new(), &models)
                .expect("bound");
        assert_eq!((merged.len(), forced.len()), (2, 0));
        // Two distinct halves do not fit: the larger on screen merges, the smaller is a proxy;
        // a second placement of a merged model costs nothing more and merges too.
        let big = input(vec![
            at(0, 0.0, 2.0),
            at(1, 10.0, 8.0),
            at(1, -10.0, 1.0),
            at(2, 20.0, 1.0),
        ]);
        let (merged, forced) =
            bound_merge(&big, big.placements.clone(), &BTreeMap::new(), &models).expect("bound");
        let merged_models: Vec<u64> = merged.iter().map(|p| p.model).collect();
        assert_eq!(merged_models, vec![1, 1, 2], "{merged:?}");
        assert_eq!(forced.len(), 1);
        assert_eq!(forced[0].model, 0);
        // Children's versions count instead of the model's own triangles.
        let mut versions = BTreeMap::new();
        versions.insert((0, 0), Arc::new(model("a'", 100).mesh.submeshes[0].clone()));
        let (merged, forced) =
            bound_merge(&big, big.placements.clone(), &versions, &models).expect("bound");
        assert_eq!((merged.len(), forced.len()), (4, 0));
    }

    #[test]
    fn an_object_over_the_bound_alone_still_merges() {
        let models = InMemoryModels::new(vec![model("a", MERGE_TRIANGLES as usize + 1)]);
        let one = input(vec![at(0, 0.0, 2.0)]);
        let (merged, forced) =
            bound_merge(&one, one.placements.clone(), &BTreeMap::new(), &models).expect("bound");
        assert_eq!((merged.len(), forced.len()), (1, 0));
    }
}
