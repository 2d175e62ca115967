//! Orthoview impostors in the rebuild (Chaudhuri et al. 2009, section 4.1): the far field's
//! depth images, built with the aggregates and published in the same manifest.
//!
//! [`build_impostors`] runs after the aggregates of a build, as four stages:
//! 1. **choose**: a node gets an impostor where serving one ([`VIEWS_SERVED`] orthoviews at the
//!    world's q, about [`BYTES_PER_PIXEL`] each) costs less than its aggregate. On a world of
//!    reused models that is the upper tree; on distinct models, nearly every node.
//! 2. **key**: an impostor's key is its node's aggregate key (everything below it) with the
//!    impostor format, q and directions; a key the published manifest knows is reused.
//! 3. **make**, bottom-up by tree level, the nodes of a level in parallel: a node whose
//!    children all have impostors is composited from their orthoviews (minimum depth,
//!    averaged within a depth threshold: [`Orthoview::composite`]); any other (the leaves of
//!    the impostor hierarchy) is ray-cast from its objects at full detail
//!    ([`Orthoview::render`]), a ray per pixel; coverage below full comes from compositing. A child's orthoviews come from this build or, reused, from
//!    their stored images; a node one of whose children's images cannot be read is ray-cast
//!    instead, and named in the report.
//! 4. **encode**: three lossless PNGs per direction (colour, 16-bit depth, octahedral
//!    normals), content-addressed through the store, committed level by level; a level's
//!    orthoviews past [`KEPT_VIEW_BYTES`] are read back from them by the level above.
//!
//! A node's q and the directions: `horizon_impostor::node_resolution` (pixel-exact from where
//! the cut would first draw the node's aggregate) and `WORLD_DIRECTIONS`, at the options'
//! `min_solid_angle` and the clients' default [`PIXEL_SOLID_ANGLE`].

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glam::Vec3;
use horizon_bvh::{Bvh, NodeId, ObjectId};
use horizon_impostor::{
    node_resolution, Orthoview, PreparedMesh, SceneBuilder, VIEWS_SERVED, WORLD_DIRECTIONS,
};
use horizon_mesh::Aabb;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::AggregateError;
use crate::keys::KeyHasher;
use crate::source::ModelSource;
use crate::store::{AggregateEntry, AggregateStore};

/// Version of the impostor format; part of every impostor key.
pub const IMPOSTOR_FORMAT: u32 = 6;

/// The solid angle of a client's pixel the orthoviews are made for: 1920 pixels across a
/// 60-degree field of view, the wire's default `pixel_solid_angle`.
pub const PIXEL_SOLID_ANGLE: f32 = 3.0e-7;

/// Encoded bytes an orthoview pixel is taken to cost when choosing which nodes get an
/// impostor (colour, depth and normals together, PNG-compressed, empty pixels included):
/// 0.28 to 0.42 measured on the city worlds (`lab/results/impostors.md`), rounded up.
pub const BYTES_PER_PIXEL: f64 = 0.5;

/// Decoded meshes kept for ray casting, as an estimate of their bytes.
const PREPARED_CACHE_BYTES: usize = 2 << 30;

/// Decoded orthoviews of one tree level kept in memory for the level above (8 bytes a
/// pixel); the rest are read back from their images.
const KEPT_VIEW_BYTES: usize = 512 << 20;

/// Which nodes of a build get impostors.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImpostorPolicy {
    /// None.
    #[default]
    Off,
    /// Those whose impostor costs less to serve than their aggregate (the world's rebuild).
    WherePaying,
    /// Every node with an aggregate (tests, and measuring what the choice leaves out).
    Everywhere,
}

/// One node's impostor: an orthoview per world direction, as stored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImpostorEntry {
    /// Hash of what it was made from (the node's aggregate key, format, q, directions).
    pub key: String,
    /// The box its orthoviews show: inside the node's box.
    pub min: [f32; 3],
    /// Its largest corner.
    pub max: [f32; 3],
    /// One per direction, in the order of `WORLD_DIRECTIONS`.
    pub views: Vec<ImpostorView>,
}

/// One stored orthoview.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImpostorView {
    /// The canonical direction it looks along.
    pub direction: [i8; 3],
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// World size of a pixel.
    pub pixel: f32,
    /// Content hash of the colour PNG (sRGB, alpha = coverage).
    pub color: String,
    /// Of the depth PNG (16-bit grey: 0 empty, 1..=65535 across the box along the direction).
    pub depth: String,
    /// Of the normal PNG (grey and alpha: the two octahedral coordinates).
    pub normal: String,
    /// Bytes of the three PNGs: colour, depth, normals.
    pub bytes: [u64; 3],
}

impl ImpostorEntry {
    /// The box its orthoviews show.
    pub fn bounds(&self) -> Aabb {
        Aabb {
            min: Vec3::from(self.min),
            max: Vec3::from(self.max),
        }
    }

    /// Bytes of every stored image.
    pub fn bytes(&self) -> u64 {
        self.views.iter().flat_map(|v| v.bytes).sum()
    }

    /// The largest pixel of any of its orthoviews, world units: the impostor is within one
    /// screen pixel of its content from `pixel / pixel_angle` away.
    pub fn pixel(&self) -> f32 {
        self.views.iter().map(|v| v.pixel).fold(0.0, f32::max)
    }

    /// Every blob it names.
    pub fn blobs(&self) -> impl Iterator<Item = &String> {
        self.views
            .iter()
            .flat_map(|v| [&v.color, &v.depth, &v.normal])
    }

    /// Reads its orthoviews back from `store`, validated.
    pub fn load(&self, store: &dyn AggregateStore) -> Result<Vec<Orthoview>, AggregateError> {
        let bounds = self.bounds();
        self.views
            .iter()
            .map(|v| {
                let images = [
                    store.blob(&v.color)?,
                    store.blob(&v.depth)?,
                    store.blob(&v.normal)?,
                ];
                Orthoview::decode(&bounds, v.direction, &images).map_err(|reason| {
                    AggregateError::Corrupt {
                        path: v.color.clone().into(),
                        reason,
                    }
                })
            })
            .collect()
    }
}

/// What the impostor stage of a build did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ImpostorReport {
    /// Nodes with an impostor.
    pub nodes: usize,
    /// Impostors made by this build.
    pub built: usize,
    /// Found under their key.
    pub reused: usize,
    /// Of those built, ray-cast from objects (the rest were composited).
    pub rendered: usize,
    /// The largest q of a node's orthoviews.
    pub resolution: u32,
    /// Bytes of every impostor of the tree.
    pub bytes_total: u64,
    /// Wall time.
    pub seconds: f64,
    /// Nodes ray-cast because a child's stored orthoviews could not be read, with why.
    #[serde(default)]
    pub unreadable: Vec<(u32, String)>,
    /// The children whose stored orthoviews could not be read. They are left out of this
    /// build's impostors, so their nodes are drawn by their aggregates and the next build
    /// makes them again.
    #[serde(default)]
    pub unreadable_children: Vec<u32>,
}

/// Builds (or reuses) the impostor of every node that gets one (see the module docs), for
/// the build's `aggregates`; the store's manifest (the build's predecessor) has the impostors
/// that may be reused.
pub fn build_impostors(
    bvh: &Bvh,
    models: &dyn ModelSource,
    store: &dyn AggregateStore,
    aggregates: &BTreeMap<u32, AggregateEntry>,
    policy: ImpostorPolicy,
    min_solid_angle: f32,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<(BTreeMap<u32, ImpostorEntry>, ImpostorReport), AggregateError> {
    let start = Instant::now();
    let q_of = |node: u32| -> u32 {
        bvh.node(NodeId(node)).map_or(horizon_impostor::MIN_Q, |n| {
            let b = n.aabb();
            let extent = (b.max - b.min).length();
            node_resolution(extent, n.r_max(), min_solid_angle, PIXEL_SOLID_ANGLE)
        })
    };
    let mut report = ImpostorReport::default();
    // Stage 1: choose.
    let chosen = choose(aggregates, policy, &q_of);
    // Stage 2: keys, and what the previous manifest already has.
    let key_of = |node: u32| -> String {
        let mut h = KeyHasher::new();
        h.write(b"impostor");
        h.write(&IMPOSTOR_FORMAT.to_le_bytes());
        h.write(&q_of(node).to_le_bytes());
        for d in WORLD_DIRECTIONS {
            h.write(&d.map(|c| c as u8));
        }
        h.write(aggregates[&node].key.as_bytes());
        h.finish_hex()
    };
    let previous = store.manifest()?;
    let known: HashMap<&str, &ImpostorEntry> = previous
        .iter()
        .flat_map(|m| m.impostors.values())
        .map(|e| (e.key.as_str(), e))
        .collect();
    let mut out: BTreeMap<u32, ImpostorEntry> = BTreeMap::new();
    let mut dirty: HashSet<u32> = HashSet::new();
    for &node in &chosen {
        let key = key_of(node);
        match known.get(key.as_str()) {
            Some(&e) => {
                out.insert(node, e.clone());
                report.reused += 1;
            }
            None => {
                dirty.insert(node);
            }
        }
    }
    // Stage 3: make, bottom-up.
    let prepared = PreparedCache::default();
    // (node ray-cast instead, its child that could not be read, why).
    let unreadable: Mutex<Vec<(u32, u32, String)>> = Mutex::new(Vec::new());
    let mut below: HashMap<u32, Arc<Vec<Orthoview>>> = HashMap::new();
    for level in crate::build::levels(bvh).iter().rev() {
        if stop() {
            return Err(AggregateError::Stopped);
        }
        let todo: Vec<NodeId> = level
            .iter()
            .copied()
            .filter(|n| dirty.contains(&n.0))
            .collect();
        if todo.is_empty() {
            below.clear();
            continue;
        }
        let made: Vec<(u32, Arc<Vec<Orthoview>>, bool)> = todo
            .par_iter()
            .map(|&node| {
                let children: Vec<NodeId> = bvh
                    .node(node)
                    .map(|n| n.child_nodes().collect())
                    .unwrap_or_default();
                let composite =
                    !children.is_empty() && children.iter().all(|c| chosen.contains(&c.0));
                let kids = composite.then(|| {
                    children
                        .iter()
                        .map(|c| match below.get(&c.0) {
                            Some(v) => Ok(v.clone()),
                            None => out
                                .get(&c.0)
                                .ok_or_else(|| {
                                    AggregateError::Tree(format!("node {} has no impostor", c.0))
                                })
                                .and_then(|e| e.load(store))
                                .map(Arc::new)
                                .map_err(|e| (c.0, e)),
                        })
                        .collect::<Result<Vec<_>, _>>()
                });
                // A child whose stored orthoviews cannot be read (damaged, or made by an
                // older composite) does not stop the build: this node is ray-cast instead,
                // and the child is left out so that it is made again.
                let (views, rendered) = match kids {
                    Some(Ok(kids)) => (composite_views(&kids, q_of(node.0)), false),
                    Some(Err((child, e))) => {
                        if let Ok(mut u) = unreadable.lock() {
                            u.push((node.0, child, e.to_string()));
                        }
                        let views = render_views(bvh, node, models, &prepared, q_of(node.0))?;
                        (views, true)
                    }
                    None => (
                        render_views(bvh, node, models, &prepared, q_of(node.0))?,
                        true,
                    ),
                };
                Ok((node.0, Arc::new(views), rendered))
            })
            .collect::<Result<_, AggregateError>>()?;
        // Stage 4: encode.
        let encoded: Vec<(u32, ImpostorEntry)> = made
            .par_iter()
            .map(|(node, views, _)| Ok((*node, encode(store, key_of(*node), views)?)))
            .collect::<Result<_, AggregateError>>()?;
        report.built += made.len();
        report.rendered += made.iter().filter(|m| m.2).count();
        out.extend(encoded);
        if let Ok(u) = unreadable.lock() {
            for (_, child, _) in u.iter() {
                out.remove(child);
            }
        }
        // The level's images become readable, so that the parents read back what is not
        // kept in memory: past `KEPT_VIEW_BYTES` (on 60,000 distinct buildings, the leaves'
        // orthoviews alone are 4 GB).
        store.commit()?;
        let mut kept = 0usize;
        below = made
            .into_iter()
            .filter(|(_, views, _)| {
                kept += views
                    .iter()
                    .map(|v| (v.width * v.height) as usize * 8)
                    .sum::<usize>();
                kept <= KEPT_VIEW_BYTES
            })
            .map(|(n, v, _)| (n, v))
            .collect();
    }
    store.commit()?;
    report.nodes = out.len();
    report.resolution = out
        .values()
        .flat_map(|e| &e.views)
        .map(|v| v.width.max(v.height))
        .max()
        .unwrap_or(0);
    report.bytes_total = out.values().map(ImpostorEntry::bytes).sum();
    let unreadable = unreadable.into_inner().unwrap_or_default();
    report.unreadable = unreadable
        .iter()
        .map(|(node, child, why)| (*node, format!("child {child}: {why}")))
        .collect();
    report.unreadable.sort();
    report.unreadable_children = unreadable.iter().map(|(_, child, _)| *child).collect();
    report.unreadable_children.sort_unstable();
    report.unreadable_children.dedup();
    report.seconds = start.elapsed().as_secs_f64();
    Ok((out, report))
}

/// The nodes that get an impostor under `policy`.
fn choose(
    aggregates: &BTreeMap<u32, AggregateEntry>,
    policy: ImpostorPolicy,
    q_of: &dyn Fn(u32) -> u32,
) -> HashSet<u32> {
    let served = |n: u32| {
        let q = f64::from(q_of(n));
        VIEWS_SERVED as f64 * q * q * BYTES_PER_PIXEL
    };
    aggregates
        .iter()
        .filter(|(&n, e)| match policy {
            ImpostorPolicy::Off => false,
            ImpostorPolicy::WherePaying => e.stats.bytes as f64 >= served(n),
            ImpostorPolicy::Everywhere => true,
        })
        .map(|(&n, _)| n)
        .collect()
}

/// A node's orthoviews composited from its children's.
fn composite_views(children: &[Arc<Vec<Orthoview>>], q: u32) -> Vec<Orthoview> {
    // Children that show nothing add nothing (a stored empty box reads back as a point).
    let bounds = children
        .iter()
        .filter(|c| c.iter().any(|v| v.covered() > 0))
        .filter_map(|c| c.first())
        .fold(Aabb::EMPTY, |b, v| b.union(&v.bounds));
    WORLD_DIRECTIONS
        .par_iter()
        .enumerate()
        .map(|(i, &d)| {
            let views: Vec<&Orthoview> = children.iter().filter_map(|c| c.get(i)).collect();
            Orthoview::composite(&views, &bounds, d, q)
        })
        .collect()
}

/// A node's orthoviews ray-cast from its objects, at full detail, a ray per pixel (four, to
/// measure coverage, cost the build 3.6 times as much on the city for no measured gain:
/// `lab/results/impostors.md`).
fn render_views(
    bvh: &Bvh,
    node: NodeId,
    models: &dyn ModelSource,
    prepared: &PreparedCache,
    q: u32,
) -> Result<Vec<Orthoview>, AggregateError> {
    let mut ids: Vec<ObjectId> = Vec::new();
    bvh.objects_under(node, &mut ids);
    let mut scene = SceneBuilder::default();
    let mut bounds = Aabb::EMPTY;
    for o in ids.iter().filter_map(|&o| bvh.object(o)) {
        let (mesh, model_bounds) = prepared.get(models, o.model())?;
        let t = o.transform();
        if !model_bounds.is_empty() {
            for c in model_bounds.corners() {
                bounds.grow(t.transform_point3(c));
            }
        }
        scene.add(&mesh, &t);
    }
    // Inside the node's box (the box of its object spheres) whatever rounding did.
    if let Some(n) = bvh.node(node) {
        let b = n.aabb();
        bounds = Aabb {
            min: bounds.min.max(b.min),
            max: bounds.max.min(b.max),
        };
    }
    let scene = scene.build();
    Ok(WORLD_DIRECTIONS
        .iter()
        .map(|&d| Orthoview::render(&scene, &bounds, d, q))
        .collect())
}

/// Encodes a node's orthoviews into the store and makes its entry.
fn encode(
    store: &dyn AggregateStore,
    key: String,
    views: &[Orthoview],
) -> Result<ImpostorEntry, AggregateError> {
    let bounds = views.first().map_or(Aabb::EMPTY, |v| v.bounds);
    let (min, max) = if bounds.is_empty() {
        ([0.0; 3], [0.0; 3])
    } else {
        (bounds.min.to_array(), bounds.max.to_array())
    };
    let views = views
        .iter()
        .map(|v| {
            let [color, depth, normal] = v
                .encode()
                .map_err(|e| AggregateError::Tree(format!("an orthoview does not encode: {e}")))?;
            Ok(ImpostorView {
                direction: v.direction,
                width: v.width,
                height: v.height,
                pixel: v.pixel_size(),
                bytes: [color.len(), depth.len(), normal.len()].map(|n| n as u64),
                color: store.stage_blob(&color)?,
                depth: store.stage_blob(&depth)?,
                normal: store.stage_blob(&normal)?,
            })
        })
        .collect::<Result<Vec<_>, AggregateError>>()?;
    Ok(ImpostorEntry {
        key,
        min,
        max,
        views,
    })
}

/// Prepared meshes by model number, kept while their estimated bytes fit
/// [`PREPARED_CACHE_BYTES`] (over it, the cache starts again).
#[derive(Default)]
struct PreparedCache {
    inner: Mutex<(HashMap<u64, Prepared>, usize)>,
}

/// A model ready to ray-cast, and its bounds.
type Prepared = (Arc<PreparedMesh>, Aabb);

impl PreparedCache {
    fn get(&self, models: &dyn ModelSource, model: u64) -> Result<Prepared, AggregateError> {
        if let Ok(m) = self.inner.lock() {
            if let Some(hit) = m.0.get(&model) {
                return Ok(hit.clone());
            }
        }
        let source = models.model(model)?;
        let mesh = Arc::new(PreparedMesh::new(&source.mesh));
        let bounds = source.mesh.bounds();
        let cost = mesh.triangles() as usize * 64
            + source
                .mesh
                .textures
                .iter()
                .map(|t| t.size.0 as usize * t.size.1 as usize * 6)
                .sum::<usize>();
        if let Ok(mut m) = self.inner.lock() {
            if m.1 + cost > PREPARED_CACHE_BYTES {
                m.0.clear();
                m.1 = 0;
            }
            m.1 += cost;
            m.0.insert(model, (mesh.clone(), bounds));
        }
        Ok((mesh, bounds))
    }
}
