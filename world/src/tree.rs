//! [`Tree`]: the world's similarity-aware BVH with the map between the world's object ids and
//! the tree's, the generation it holds every change up to, and its snapshot.
//!
//! The tree is derived state. A snapshot (zstd-compressed JSON, a blob) holds it at some
//! generation, and the metadata store's log holds every committed change after that; the
//! tree at any generation is the snapshot with the log replayed in order. Insertion (eq. 1),
//! moves and removals are deterministic, so the replayed tree is the very tree the live world
//! held: the same nodes, hence the same aggregate keys, so nothing built is rebuilt after a
//! restart.

use std::collections::{BTreeMap, BTreeSet};

use glam::{Affine3A, Vec3};
use horizon_bvh::{Bvh, NewObject, NodeId, ObjectId, Sphere};
use serde::{Deserialize, Serialize};

use crate::error::WorldError;
use crate::store::{Applied, ModelDescriptors};

/// zstd level of snapshots: fast, and JSON of descriptors compresses well at any level.
const SNAPSHOT_LEVEL: i32 = 3;

/// The BVH and its id maps (see the module docs).
#[derive(Clone, Debug)]
pub struct Tree {
    /// The hierarchy.
    pub bvh: Bvh,
    /// The generation the tree holds every change up to.
    pub generation: u64,
    /// World object id -> tree object id.
    ids: BTreeMap<u64, ObjectId>,
    /// Tree object id -> world object id.
    back: Vec<u64>,
    /// Tree object id -> the generation that last placed or moved it.
    placed: Vec<u64>,
    /// The same, ordered by generation: the objects placed after a generation (the pending
    /// objects of a cut) are a range of it.
    by_generation: BTreeSet<(u64, u64)>,
    /// Model number -> how many objects the tree places with it (model numbers are the
    /// store's dense row numbers; the cut reads this once per placement it weighs).
    uses: Vec<u32>,
}

/// What a snapshot stores.
#[derive(Serialize, Deserialize)]
struct Stored {
    bvh: Bvh,
    generation: u64,
    ids: Vec<(u64, ObjectId)>,
}

/// A model's sphere and descriptors, as the tree takes them.
pub trait Describe {
    /// The descriptors of the model numbered `model`.
    fn descriptors_of(&self, model: u64) -> Result<std::sync::Arc<ModelDescriptors>, WorldError>;
}

impl Tree {
    /// A tree over `objects` (world id, model number, transform), bulk-built (core paper
    /// section 4.3) with `options` at `generation`.
    pub fn bulk(
        options: horizon_bvh::BvhOptions,
        objects: &[(u64, u64, Affine3A)],
        descriptors: &dyn Describe,
        generation: u64,
    ) -> Result<Self, WorldError> {
        let described: Vec<std::sync::Arc<ModelDescriptors>> = objects
            .iter()
            .map(|&(_, model, _)| descriptors.descriptors_of(model))
            .collect::<Result<_, _>>()?;
        let input: Vec<NewObject<'_>> = objects
            .iter()
            .zip(&described)
            .map(|(&(_, model, transform), d)| new_object(model, transform, d))
            .collect();
        let bvh = Bvh::bulk_build(options, &input)?;
        bvh.validate()?;
        // bulk_build numbers objects 0.. in input order.
        let ids = objects
            .iter()
            .enumerate()
            .map(|(i, &(id, _, _))| (id, ObjectId(i as u32)))
            .collect();
        Ok(Self::with_ids(bvh, generation, ids))
    }

    /// An empty tree with `options`.
    pub fn empty(options: horizon_bvh::BvhOptions) -> Result<Self, WorldError> {
        Ok(Self::with_ids(Bvh::new(options)?, 0, BTreeMap::new()))
    }

    fn with_ids(bvh: Bvh, generation: u64, ids: BTreeMap<u64, ObjectId>) -> Self {
        let mut back = Vec::new();
        let mut uses = Vec::new();
        for (&w, &t) in &ids {
            set_slot(&mut back, t, w);
            if let Some(o) = bvh.object(t) {
                count_use(&mut uses, o.model(), 1);
            }
        }
        Self {
            bvh,
            generation,
            ids,
            back,
            placed: Vec::new(),
            by_generation: BTreeSet::new(),
            uses,
        }
    }

    /// Records, for each `(world id, generation)`, the generation that last placed or moved
    /// the object: the metadata store knows it, the snapshot does not. [`Tree::apply`] keeps
    /// it from then on.
    pub fn set_placed(&mut self, placed: impl IntoIterator<Item = (u64, u64)>) {
        self.placed.clear();
        self.by_generation.clear();
        for (object, generation) in placed {
            self.place(object, generation);
        }
    }

    fn place(&mut self, object: u64, generation: u64) {
        self.unplace(object);
        if let Some(&id) = self.ids.get(&object) {
            set_slot(&mut self.placed, id, generation);
            self.by_generation.insert((generation, object));
        }
    }

    fn unplace(&mut self, object: u64) {
        if let Some(&id) = self.ids.get(&object) {
            if let Some(old) = self.placed.get_mut(id.0 as usize) {
                if *old != NO_SLOT {
                    self.by_generation.remove(&(*old, object));
                    *old = NO_SLOT;
                }
            }
        }
    }

    /// The generation that last placed or moved a world object (0 if unknown).
    pub fn placed(&self, object: u64) -> u64 {
        self.ids.get(&object).map_or(0, |&id| self.placed_at(id))
    }

    /// The generation that last placed or moved a tree object (0 if unknown).
    pub fn placed_at(&self, object: ObjectId) -> u64 {
        match self.placed.get(object.0 as usize) {
            Some(&g) if g != NO_SLOT => g,
            _ => 0,
        }
    }

    /// The world ids of the objects placed or moved after `generation`.
    pub fn placed_after(&self, generation: u64) -> impl Iterator<Item = u64> + '_ {
        self.by_generation
            .range((generation.saturating_add(1), 0)..)
            .map(|&(_, object)| object)
    }

    /// Applies one committed change; returns the nodes whose contents it changed (the
    /// ancestors of where the object was and where it is now).
    pub fn apply(
        &mut self,
        change: &Applied,
        descriptors: &dyn Describe,
    ) -> Result<Vec<NodeId>, WorldError> {
        if change.generation <= self.generation {
            return Ok(Vec::new());
        }
        let mut touched = Vec::new();
        if let Some(&old) = self.ids.get(&change.object) {
            touched.extend(self.ancestors(old));
        }
        match (change.state, self.ids.get(&change.object).copied()) {
            (Some((model, transform)), None) => {
                let d = descriptors.descriptors_of(model)?;
                let id = self.bvh.insert(&new_object(model, transform, &d))?;
                count_use(&mut self.uses, model, 1);
                self.ids.insert(change.object, id);
                set_slot(&mut self.back, id, change.object);
                self.place(change.object, change.generation);
                touched.extend(self.ancestors(id));
            }
            (Some((model, transform)), Some(id)) => {
                let d = descriptors.descriptors_of(model)?;
                let sphere = sphere_of(transform, &d);
                self.bvh.move_object(id, transform, sphere)?;
                self.place(change.object, change.generation);
                touched.extend(self.ancestors(id));
            }
            (None, Some(id)) => {
                let model = self.bvh.object(id).map(|o| o.model());
                self.bvh.remove(id)?;
                if let Some(model) = model {
                    count_use(&mut self.uses, model, -1);
                }
                self.unplace(change.object);
                self.ids.remove(&change.object);
                set_slot(&mut self.back, id, NO_SLOT);
            }
            (None, None) => {
                return Err(WorldError::Inconsistent(format!(
                    "the log deletes object {}, which the tree does not hold",
                    change.object
                )))
            }
        }
        self.generation = change.generation;
        touched.sort_unstable();
        touched.dedup();
        Ok(touched)
    }

    /// How many objects the tree places with model `model`.
    pub fn uses(&self, model: u64) -> u32 {
        usize::try_from(model)
            .ok()
            .and_then(|m| self.uses.get(m))
            .copied()
            .unwrap_or(0)
    }

    /// The tree id of a world object.
    pub fn tree_id(&self, object: u64) -> Option<ObjectId> {
        self.ids.get(&object).copied()
    }

    /// The world id of a tree object.
    pub fn world_id(&self, object: ObjectId) -> Option<u64> {
        self.back
            .get(object.0 as usize)
            .copied()
            .filter(|&w| w != NO_SLOT)
    }

    /// The nodes from `object`'s leaf up to the root.
    fn ancestors(&self, object: ObjectId) -> Vec<NodeId> {
        let mut out = Vec::new();
        let mut at = self.bvh.object(object).map(|o| o.leaf());
        while let Some(n) = at {
            out.push(n);
            at = self.bvh.node(n).and_then(|r| r.parent());
        }
        out
    }

    /// The snapshot's bytes.
    pub fn to_snapshot(&self) -> Result<Vec<u8>, WorldError> {
        let stored = Stored {
            bvh: self.bvh.clone(),
            generation: self.generation,
            ids: self.ids.iter().map(|(&w, &t)| (w, t)).collect(),
        };
        let json = serde_json::to_vec(&stored)
            .map_err(|e| WorldError::Inconsistent(format!("the tree does not serialise: {e}")))?;
        zstd::bulk::compress(&json, SNAPSHOT_LEVEL)
            .map_err(|e| WorldError::Inconsistent(format!("the tree does not compress: {e}")))
    }

    /// A tree from a snapshot's bytes (checked with `Bvh::validate` as it is read).
    pub fn from_snapshot(bytes: &[u8]) -> Result<Self, WorldError> {
        let corrupt = |reason: String| WorldError::Inconsistent(format!("tree snapshot: {reason}"));
        let json = zstd::stream::decode_all(bytes).map_err(|e| corrupt(e.to_string()))?;
        let stored: Stored = serde_json::from_slice(&json).map_err(|e| corrupt(e.to_string()))?;
        let ids = stored.ids.into_iter().collect();
        Ok(Self::with_ids(stored.bvh, stored.generation, ids))
    }
}

/// An empty slot of the tree-id-indexed tables.
const NO_SLOT: u64 = u64::MAX;

/// Sets `table[id]`, growing it with empty slots.
fn set_slot(table: &mut Vec<u64>, id: ObjectId, value: u64) {
    let i = id.0 as usize;
    if table.len() <= i {
        table.resize(i + 1, NO_SLOT);
    }
    table[i] = value;
}

/// Adds `delta` (1 or -1) to `model`'s count of uses, growing the table.
fn count_use(uses: &mut Vec<u32>, model: u64, delta: i32) {
    let Ok(m) = usize::try_from(model) else {
        return;
    };
    if uses.len() <= m {
        uses.resize(m + 1, 0);
    }
    uses[m] = uses[m].saturating_add_signed(delta);
}

/// A placed model's world bounding sphere: its model sphere through its transform.
pub fn sphere_of(transform: Affine3A, d: &ModelDescriptors) -> Sphere {
    let scale = horizon_mesh::transform::max_axis_scale(&transform);
    Sphere::new(
        transform.transform_point3(Vec3::from_array(d.centre)),
        d.radius * scale,
    )
}

/// A placed model as the BVH takes it: its number, transform, world sphere and descriptors.
pub fn new_object<'a>(model: u64, transform: Affine3A, d: &'a ModelDescriptors) -> NewObject<'a> {
    NewObject {
        model,
        transform,
        sphere: sphere_of(transform, d),
        shape: &d.zernike,
        texture: &d.csd,
    }
}
