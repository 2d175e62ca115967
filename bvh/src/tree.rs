//! The tree's storage: an arena of nodes with stable ids and a struct-of-arrays object store
//! (core paper section 4; Sirikata's max-sphere R-tree). The operations live beside it:
//! `insert.rs`, `split.rs`, `remove.rs`, `bulk.rs`, `cut.rs`, `validate.rs`.

use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};

use crate::bounds::{fit_sphere, Aabb, Sphere};
use crate::{BvhError, BvhOptions, InvalidTree, SHAPE_LEN, TEXTURE_LEN};

/// "No node": the parent of the root.
pub(crate) const NONE: u32 = u32::MAX;
/// `Objects::leaf` of a free object slot.
pub(crate) const FREE_SLOT: u32 = u32::MAX;
/// `Objects::leaf` of a live object that is between leaves (during a remove or a rebuild).
pub(crate) const UNPLACED: u32 = u32::MAX - 1;
/// Ids from here up are reserved for the sentinels above.
const MAX_ID: u32 = u32::MAX - 2;

/// A node of the tree. Valid while the node lives: a split keeps the id of the node it splits
/// (the new half gets a new id), a removed node's id is reused later, and [`Bvh::rebuild`]
/// renumbers every node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct NodeId(pub u32);

/// An object of the tree. Valid from [`Bvh::insert`] (or [`Bvh::bulk_build`]) until
/// [`Bvh::remove`]; moves, splits and rebuilds keep it. A removed object's id is reused later.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ObjectId(pub u32);

/// An object to add: what the aggregate pipeline and the cut need to know about it.
#[derive(Clone, Copy, Debug)]
pub struct NewObject<'a> {
    /// The content-addressed model the object instantiates.
    pub model: u64,
    /// The model-to-world transform.
    pub transform: Affine3A,
    /// The world-space bounding sphere of the placed model.
    pub sphere: Sphere,
    /// The model's shape descriptor: [`SHAPE_LEN`] 3D Zernike norms.
    pub shape: &'a [f32],
    /// The model's texture descriptor: [`TEXTURE_LEN`] CSD bins on the 0..=255 scale.
    pub texture: &'a [f32],
}

impl NewObject<'_> {
    /// Refuses wrong descriptor lengths and non-finite numbers.
    pub(crate) fn check(&self) -> Result<(), BvhError> {
        if self.shape.len() != SHAPE_LEN {
            return Err(BvhError::DescriptorLength {
                which: "shape",
                expected: SHAPE_LEN,
                got: self.shape.len(),
            });
        }
        if self.texture.len() != TEXTURE_LEN {
            return Err(BvhError::DescriptorLength {
                which: "texture",
                expected: TEXTURE_LEN,
                got: self.texture.len(),
            });
        }
        if !self.shape.iter().all(|v| v.is_finite()) {
            return Err(BvhError::NonFinite("shape descriptor"));
        }
        if !self.texture.iter().all(|v| v.is_finite()) {
            return Err(BvhError::NonFinite("texture descriptor"));
        }
        check_placement(&self.transform, &self.sphere)
    }
}

/// Refuses a non-finite transform or an invalid sphere.
pub(crate) fn check_placement(transform: &Affine3A, sphere: &Sphere) -> Result<(), BvhError> {
    if !transform.is_finite() {
        return Err(BvhError::NonFinite("transform"));
    }
    if !sphere.is_valid() {
        return Err(BvhError::NonFinite("bounding sphere"));
    }
    Ok(())
}

/// What a node holds: objects (a leaf) or nodes (an internal node). `Free` marks a slot on
/// the free list.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) enum NodeKind {
    Leaf,
    Internal,
    Free,
}

/// The hot part of a node: everything the cut query and the insert descent read, 56 bytes.
///
/// - `centre`, `radius`: the max-sphere bound (c, Rc). For a leaf it encloses its objects'
///   centres; for an internal node it encloses its children's bounds, so every object centre
///   below lies inside it.
/// - `r_max`: the largest object radius anywhere below. An object below subtends at most an
///   `r_max` sphere at the bound's nearest point (`solid_angle::worst_case_solid_angle`).
/// - `aabb`: the box of the object spheres below (the aggregate's geometric bound, and the
///   volume in eq. 1).
/// - `count`: the objects below; the descriptor centroids are `Bvh::shape_sum / count`.
/// - `len`: the children in this node's slot of `Bvh::children`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub(crate) struct Node {
    pub(crate) centre: Vec3,
    pub(crate) radius: f32,
    pub(crate) r_max: f32,
    pub(crate) parent: u32,
    pub(crate) count: u32,
    pub(crate) len: u16,
    pub(crate) kind: NodeKind,
    pub(crate) aabb: Aabb,
}

// The record the cut query walks stays at 56 bytes (see above).
const _: () = assert!(std::mem::size_of::<Node>() == 56);

impl Node {
    const FREE: Self = Self {
        centre: Vec3::ZERO,
        radius: 0.0,
        r_max: 0.0,
        parent: NONE,
        count: 0,
        len: 0,
        kind: NodeKind::Free,
        aabb: Aabb::ZERO,
    };

    /// The bound on the objects' spheres as a whole: (c, Rc + r_max).
    pub(crate) fn outer_sphere(&self) -> Sphere {
        Sphere::new(self.centre, self.radius + self.r_max)
    }
}

/// Objects as a struct of arrays, indexed by object id. A free slot has
/// `leaf == FREE_SLOT` and is on `free`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(crate) struct Objects {
    /// The model each object instantiates.
    pub(crate) model: Vec<u64>,
    /// Model-to-world transforms.
    pub(crate) transform: Vec<Affine3A>,
    /// World-space bounding spheres.
    pub(crate) sphere: Vec<Sphere>,
    /// The leaf holding each object (or `FREE_SLOT` / `UNPLACED`).
    pub(crate) leaf: Vec<u32>,
    /// Shape descriptors, `SHAPE_LEN` per slot.
    pub(crate) shape: Vec<f32>,
    /// Texture descriptors, `TEXTURE_LEN` per slot.
    pub(crate) texture: Vec<f32>,
    /// Free slots, reused last-in first-out.
    pub(crate) free: Vec<u32>,
    /// Live objects.
    pub(crate) live: usize,
}

impl Objects {
    /// Stores a checked object as unplaced and returns its slot.
    pub(crate) fn alloc(&mut self, object: &NewObject<'_>) -> Result<u32, BvhError> {
        let slot = match self.free.pop() {
            Some(slot) => {
                let i = slot as usize;
                self.model[i] = object.model;
                self.transform[i] = object.transform;
                self.sphere[i] = object.sphere;
                self.leaf[i] = UNPLACED;
                self.shape[i * SHAPE_LEN..(i + 1) * SHAPE_LEN].copy_from_slice(object.shape);
                self.texture[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN]
                    .copy_from_slice(object.texture);
                slot
            }
            None => {
                let slot = u32::try_from(self.leaf.len())
                    .ok()
                    .filter(|&s| s < MAX_ID)
                    .ok_or(BvhError::Full)?;
                self.model.push(object.model);
                self.transform.push(object.transform);
                self.sphere.push(object.sphere);
                self.leaf.push(UNPLACED);
                self.shape.extend_from_slice(object.shape);
                self.texture.extend_from_slice(object.texture);
                slot
            }
        };
        self.live += 1;
        Ok(slot)
    }

    /// Frees a slot (the object must already be out of every leaf).
    pub(crate) fn release(&mut self, slot: u32) {
        self.leaf[slot as usize] = FREE_SLOT;
        self.free.push(slot);
        self.live -= 1;
    }

    /// Room for `additional` more objects.
    pub(crate) fn reserve(&mut self, additional: usize) {
        self.model.reserve(additional);
        self.transform.reserve(additional);
        self.sphere.reserve(additional);
        self.leaf.reserve(additional);
        self.shape.reserve(additional * SHAPE_LEN);
        self.texture.reserve(additional * TEXTURE_LEN);
    }

    /// True for a live object slot.
    pub(crate) fn is_live(&self, slot: u32) -> bool {
        self.leaf
            .get(slot as usize)
            .is_some_and(|&leaf| leaf != FREE_SLOT)
    }

    pub(crate) fn shape(&self, slot: u32) -> &[f32] {
        let i = slot as usize * SHAPE_LEN;
        &self.shape[i..i + SHAPE_LEN]
    }

    pub(crate) fn texture(&self, slot: u32) -> &[f32] {
        let i = slot as usize * TEXTURE_LEN;
        &self.texture[i..i + TEXTURE_LEN]
    }
}

/// The similarity-aware BVH.
///
/// # Layout
/// Nodes live in an arena (`nodes`) indexed by [`NodeId`]; freed slots go on `free_nodes`
/// and are reused. Per node, beside the hot `Node` record:
/// - `children[id * (max_children + 1)..][..len]`: child node ids (internal node) or object
///   ids (leaf). One spare slot holds the overflowing child until the node splits, so no node
///   ever allocates.
/// - `shape_sum[id * SHAPE_LEN..]`, `texture_sum[id * TEXTURE_LEN..]`: the sums of the
///   descriptors of every object below. An insert adds one descriptor to each ancestor's
///   sums; a remove or a split recomputes the sums on its path from the children (summed in
///   f64), so the only drift is the rounding of the additions since the last recomputation,
///   at most `count * f32::EPSILON` relative. They are f32, like the descriptors: half the
///   memory and memory traffic of f64 in the insert descent, which reads the sums of every
///   child on the path and is bound by that traffic.
///
/// Objects are a struct of arrays indexed by [`ObjectId`]. All leaves are at depth `height`.
///
/// A deserialised tree is checked with [`Bvh::validate`] and refused if broken.
#[derive(Clone, Serialize, Deserialize)]
#[serde(try_from = "BvhData")]
pub struct Bvh {
    /// Branching, eq. 1's weights and scales, bulk-build parameters.
    pub(crate) options: BvhOptions,
    /// The root node: a leaf (possibly empty) or an internal node with at least 2 children.
    pub(crate) root: u32,
    /// Depth of every leaf (0 when the root is a leaf).
    pub(crate) height: u32,
    /// The node arena.
    pub(crate) nodes: Vec<Node>,
    /// Child slots, `max_children + 1` per node.
    pub(crate) children: Vec<u32>,
    /// Shape descriptor sums, `SHAPE_LEN` per node.
    pub(crate) shape_sum: Vec<f32>,
    /// Texture descriptor sums, `TEXTURE_LEN` per node.
    pub(crate) texture_sum: Vec<f32>,
    /// Free node slots, reused last-in first-out.
    pub(crate) free_nodes: Vec<u32>,
    /// The objects.
    pub(crate) objects: Objects,
    /// Which state of which tree this is: a number no other tree state in this process has
    /// had, renewed by every change (see [`Bvh::state_stamp`]).
    #[serde(skip)]
    pub(crate) stamp: u64,
}

/// The source of [`Bvh::stamp`]s.
static NEXT_STAMP: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

fn fresh_stamp() -> u64 {
    NEXT_STAMP.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// The serialised form of [`Bvh`], validated before it becomes one.
#[derive(Deserialize)]
struct BvhData {
    options: BvhOptions,
    root: u32,
    height: u32,
    nodes: Vec<Node>,
    children: Vec<u32>,
    shape_sum: Vec<f32>,
    texture_sum: Vec<f32>,
    free_nodes: Vec<u32>,
    objects: Objects,
}

impl TryFrom<BvhData> for Bvh {
    type Error = InvalidTree;

    fn try_from(d: BvhData) -> Result<Self, InvalidTree> {
        let bvh = Self {
            options: d.options,
            root: d.root,
            height: d.height,
            nodes: d.nodes,
            children: d.children,
            shape_sum: d.shape_sum,
            texture_sum: d.texture_sum,
            free_nodes: d.free_nodes,
            objects: d.objects,
            stamp: fresh_stamp(),
        };
        bvh.validate()?;
        Ok(bvh)
    }
}

impl std::fmt::Debug for Bvh {
    /// A summary: a tree holds millions of numbers.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bvh")
            .field("objects", &self.len())
            .field("nodes", &self.node_count())
            .field("height", &self.height)
            .field("root", &self.root)
            .field("options", &self.options)
            .finish()
    }
}

impl Bvh {
    /// An empty tree (a root leaf with no objects).
    pub fn new(options: BvhOptions) -> Result<Self, BvhError> {
        options.validate()?;
        let mut bvh = Self {
            options,
            root: 0,
            height: 0,
            nodes: Vec::new(),
            children: Vec::new(),
            shape_sum: Vec::new(),
            texture_sum: Vec::new(),
            free_nodes: Vec::new(),
            objects: Objects::default(),
            stamp: fresh_stamp(),
        };
        bvh.root = bvh.alloc_node(NodeKind::Leaf, NONE);
        Ok(bvh)
    }

    /// A number that changes whenever the tree may have changed (an insert, remove, move or
    /// rebuild, even one that failed) and that no other tree in this process shares unless it
    /// is an unchanged clone. Equal stamps mean equal trees, so a standing query can tell
    /// that only its viewer moved.
    pub fn state_stamp(&self) -> u64 {
        self.stamp
    }

    /// Marks the tree as changed (called first by every operation that may change it).
    pub(crate) fn touch(&mut self) {
        self.stamp = fresh_stamp();
    }

    /// The options the tree was built with.
    pub fn options(&self) -> &BvhOptions {
        &self.options
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.objects.live
    }

    /// One more than the largest object id ever given (free ids included): the length of a
    /// table indexed by object id.
    pub fn object_slots(&self) -> usize {
        self.objects.model.len()
    }

    /// True when the tree holds no object.
    pub fn is_empty(&self) -> bool {
        self.objects.live == 0
    }

    /// Depth of the leaves: 0 when the root is a leaf.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The root node.
    pub fn root(&self) -> NodeId {
        NodeId(self.root)
    }

    /// Number of live nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len() - self.free_nodes.len()
    }

    /// A live node, or `None`.
    pub fn node(&self, id: NodeId) -> Option<NodeRef<'_>> {
        let node = self.nodes.get(id.0 as usize)?;
        (node.kind != NodeKind::Free).then_some(NodeRef {
            bvh: self,
            id: id.0,
        })
    }

    /// A live object, or `None`.
    pub fn object(&self, id: ObjectId) -> Option<ObjectRef<'_>> {
        self.objects.is_live(id.0).then_some(ObjectRef {
            bvh: self,
            id: id.0,
        })
    }

    /// The ids of every live object, in id order.
    pub fn object_ids(&self) -> impl Iterator<Item = ObjectId> + '_ {
        (0..self.objects.leaf.len() as u32)
            .filter(|&o| self.objects.is_live(o))
            .map(ObjectId)
    }

    /// Appends to `out` every object below `node` (none for an unknown node).
    pub fn objects_under(&self, node: NodeId, out: &mut Vec<ObjectId>) {
        if self.node(node).is_none() {
            return;
        }
        let mut stack = vec![node.0];
        while let Some(n) = stack.pop() {
            match self.nodes[n as usize].kind {
                NodeKind::Leaf => out.extend(self.kids(n).iter().map(|&o| ObjectId(o))),
                NodeKind::Internal => stack.extend_from_slice(self.kids(n)),
                NodeKind::Free => {}
            }
        }
    }

    /// Heap bytes held by the tree's arrays (capacities, so what the allocator gave).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        let o = &self.objects;
        self.nodes.capacity() * size_of::<Node>()
            + self.children.capacity() * size_of::<u32>()
            + (self.shape_sum.capacity() + self.texture_sum.capacity()) * size_of::<f32>()
            + self.free_nodes.capacity() * size_of::<u32>()
            + o.model.capacity() * size_of::<u64>()
            + o.transform.capacity() * size_of::<Affine3A>()
            + o.sphere.capacity() * size_of::<Sphere>()
            + (o.leaf.capacity() + o.free.capacity()) * size_of::<u32>()
            + (o.shape.capacity() + o.texture.capacity()) * size_of::<f32>()
            + size_of::<Self>()
    }

    /// Returns spare capacity to the allocator (after a bulk load of incremental inserts).
    pub fn shrink_to_fit(&mut self) {
        self.nodes.shrink_to_fit();
        self.children.shrink_to_fit();
        self.shape_sum.shrink_to_fit();
        self.texture_sum.shrink_to_fit();
        self.free_nodes.shrink_to_fit();
        let o = &mut self.objects;
        o.model.shrink_to_fit();
        o.transform.shrink_to_fit();
        o.sphere.shrink_to_fit();
        o.leaf.shrink_to_fit();
        o.shape.shrink_to_fit();
        o.texture.shrink_to_fit();
        o.free.shrink_to_fit();
    }

    // ---- Crate-internal arena helpers, used by every operation. ----

    /// Child slots per node: room for one overflowing child before a split.
    #[inline]
    pub(crate) fn stride(&self) -> usize {
        self.options.max_children + 1
    }

    /// The children of `n`: node ids (internal) or object ids (leaf).
    #[inline]
    pub(crate) fn kids(&self, n: u32) -> &[u32] {
        let start = n as usize * self.stride();
        &self.children[start..start + self.nodes[n as usize].len as usize]
    }

    /// Appends a child id to `n`'s slot (which has room for `max_children + 1`).
    pub(crate) fn push_kid(&mut self, n: u32, kid: u32) {
        let stride = self.stride();
        let node = &mut self.nodes[n as usize];
        debug_assert!((node.len as usize) < stride, "child slot overflow");
        self.children[n as usize * stride + node.len as usize] = kid;
        node.len += 1;
    }

    /// Removes a child id from `n`'s slot (order is not kept).
    pub(crate) fn remove_kid(&mut self, n: u32, kid: u32) {
        let stride = self.stride();
        let start = n as usize * stride;
        let len = self.nodes[n as usize].len as usize;
        let slot = &mut self.children[start..start + len];
        if let Some(i) = slot.iter().position(|&k| k == kid) {
            slot.swap(i, len - 1);
            self.nodes[n as usize].len -= 1;
        }
    }

    /// Replaces `n`'s children.
    pub(crate) fn set_kids(&mut self, n: u32, kids: &[u32]) {
        let start = n as usize * self.stride();
        self.children[start..start + kids.len()].copy_from_slice(kids);
        self.nodes[n as usize].len = kids.len() as u16;
    }

    #[inline]
    pub(crate) fn shape_sum(&self, n: u32) -> &[f32] {
        let i = n as usize * SHAPE_LEN;
        &self.shape_sum[i..i + SHAPE_LEN]
    }

    #[inline]
    pub(crate) fn texture_sum(&self, n: u32) -> &[f32] {
        let i = n as usize * TEXTURE_LEN;
        &self.texture_sum[i..i + TEXTURE_LEN]
    }

    /// A fresh node (reusing a free slot when there is one) with no children and zero totals.
    pub(crate) fn alloc_node(&mut self, kind: NodeKind, parent: u32) -> u32 {
        let node = Node {
            kind,
            parent,
            ..Node::FREE
        };
        match self.free_nodes.pop() {
            Some(id) => {
                self.nodes[id as usize] = node;
                let i = id as usize;
                self.shape_sum[i * SHAPE_LEN..(i + 1) * SHAPE_LEN].fill(0.0);
                self.texture_sum[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN].fill(0.0);
                id
            }
            None => {
                // Node ids stay below the sentinels: a tree has fewer nodes than objects + 1,
                // and object ids are bounded the same way.
                let id = self.nodes.len() as u32;
                self.nodes.push(node);
                self.children
                    .resize(self.children.len() + self.stride(), NONE);
                self.shape_sum.resize(self.shape_sum.len() + SHAPE_LEN, 0.0);
                self.texture_sum
                    .resize(self.texture_sum.len() + TEXTURE_LEN, 0.0);
                id
            }
        }
    }

    /// Returns a node's slot to the free list.
    pub(crate) fn free_node(&mut self, n: u32) {
        self.nodes[n as usize] = Node::FREE;
        self.free_nodes.push(n);
    }

    /// Recomputes `n`'s bounds (max-sphere, r_max, box) from its children.
    pub(crate) fn refit(&mut self, n: u32) {
        let (sphere, r_max, aabb) = match self.nodes[n as usize].kind {
            NodeKind::Leaf => bounds_of_objects(&self.objects, self.kids(n)),
            NodeKind::Internal => bounds_of_nodes(self.kids(n), |c| &self.nodes[c as usize]),
            NodeKind::Free => return,
        };
        let node = &mut self.nodes[n as usize];
        node.centre = sphere.centre;
        node.radius = sphere.radius;
        node.r_max = r_max;
        node.aabb = aabb;
    }

    /// Refits `n` and every ancestor.
    pub(crate) fn refit_upward(&mut self, mut n: u32) {
        while n != NONE {
            self.refit(n);
            n = self.nodes[n as usize].parent;
        }
    }

    /// Adds object `o` to the count and descriptor sums of `n` and every ancestor: O(1) per
    /// node plus the descriptor length.
    pub(crate) fn add_object_totals(&mut self, mut n: u32, o: u32) {
        let (s0, t0) = (o as usize * SHAPE_LEN, o as usize * TEXTURE_LEN);
        let shape = &self.objects.shape[s0..s0 + SHAPE_LEN];
        let texture = &self.objects.texture[t0..t0 + TEXTURE_LEN];
        while n != NONE {
            let i = n as usize;
            let node = &mut self.nodes[i];
            node.count += 1;
            add_f32(
                &mut self.shape_sum[i * SHAPE_LEN..(i + 1) * SHAPE_LEN],
                shape,
            );
            add_f32(
                &mut self.texture_sum[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN],
                texture,
            );
            n = node.parent;
        }
    }

    /// Recomputes `n`'s count and descriptor sums from its children (summed in f64).
    pub(crate) fn recompute_totals(&mut self, n: u32) {
        let i = n as usize;
        let start = i * self.stride();
        let len = self.nodes[i].len as usize;
        let mut shape = [0.0f64; SHAPE_LEN];
        let mut texture = [0.0f64; TEXTURE_LEN];
        let mut count = 0u32;
        for &k in &self.children[start..start + len] {
            match self.nodes[i].kind {
                NodeKind::Leaf => {
                    add_widened(&mut shape, self.objects.shape(k));
                    add_widened(&mut texture, self.objects.texture(k));
                    count += 1;
                }
                _ => {
                    add_widened(&mut shape, self.shape_sum(k));
                    add_widened(&mut texture, self.texture_sum(k));
                    count += self.nodes[k as usize].count;
                }
            }
        }
        narrow_into(
            &mut self.shape_sum[i * SHAPE_LEN..(i + 1) * SHAPE_LEN],
            &shape,
        );
        narrow_into(
            &mut self.texture_sum[i * TEXTURE_LEN..(i + 1) * TEXTURE_LEN],
            &texture,
        );
        self.nodes[i].count = count;
    }

    /// The slot of a live object, or [`BvhError::UnknownObject`].
    pub(crate) fn live_object(&self, id: ObjectId) -> Result<u32, BvhError> {
        if self.objects.is_live(id.0) {
            Ok(id.0)
        } else {
            Err(BvhError::UnknownObject(id))
        }
    }

    /// Full validation after each operation in debug builds, for small trees only (the check
    /// is O(n log n); larger trees are checked by the tests that build them).
    #[inline]
    pub(crate) fn debug_validate(&self) {
        #[cfg(debug_assertions)]
        if self.len() <= 64 {
            if let Err(e) = self.validate() {
                panic!("{e}");
            }
        }
    }
}

/// `dst += src`, widening to f64.
#[inline]
pub(crate) fn add_widened(dst: &mut [f64], src: &[f32]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d += f64::from(s);
    }
}

/// `dst += src`.
#[inline]
pub(crate) fn add_sums(dst: &mut [f64], src: &[f64]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d += s;
    }
}

/// `dst += src` in f32.
#[inline]
pub(crate) fn add_f32(dst: &mut [f32], src: &[f32]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d += s;
    }
}

/// `dst = src`, rounded to f32.
#[inline]
pub(crate) fn narrow_into(dst: &mut [f32], src: &[f64]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = s as f32;
    }
}

/// Max-sphere bound (around the object centres), r_max and box of a leaf's objects.
pub(crate) fn bounds_of_objects(objects: &Objects, kids: &[u32]) -> (Sphere, f32, Aabb) {
    if kids.is_empty() {
        return (Sphere::default(), 0.0, Aabb::ZERO);
    }
    let centres = kids
        .iter()
        .map(|&o| Sphere::new(objects.sphere[o as usize].centre, 0.0));
    let mut r_max = 0.0f32;
    let mut aabb = Aabb::EMPTY;
    for &o in kids {
        let s = objects.sphere[o as usize];
        r_max = r_max.max(s.radius);
        aabb = aabb.union(Aabb::of_sphere(s));
    }
    (fit_sphere(centres), r_max, aabb)
}

/// Max-sphere bound (around the children's bounds), r_max and box of an internal node.
pub(crate) fn bounds_of_nodes<'a, F>(kids: &[u32], node: F) -> (Sphere, f32, Aabb)
where
    F: Fn(u32) -> &'a Node + Copy,
{
    if kids.is_empty() {
        return (Sphere::default(), 0.0, Aabb::ZERO);
    }
    let spheres = kids.iter().map(|&c| {
        let n = node(c);
        Sphere::new(n.centre, n.radius)
    });
    let mut r_max = 0.0f32;
    let mut aabb = Aabb::EMPTY;
    for &c in kids {
        let n = node(c);
        r_max = r_max.max(n.r_max);
        aabb = aabb.union(n.aabb);
    }
    (fit_sphere(spheres), r_max, aabb)
}

/// A read-only view of a live node.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    bvh: &'a Bvh,
    id: u32,
}

impl std::fmt::Debug for NodeRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeRef")
            .field("id", &self.id)
            .field("node", self.node())
            .finish()
    }
}

impl<'a> NodeRef<'a> {
    fn node(&self) -> &'a Node {
        &self.bvh.nodes[self.id as usize]
    }

    /// This node's id.
    pub fn id(&self) -> NodeId {
        NodeId(self.id)
    }

    /// The parent, `None` for the root.
    pub fn parent(&self) -> Option<NodeId> {
        let p = self.node().parent;
        (p != NONE).then_some(NodeId(p))
    }

    /// True for a leaf (its children are objects).
    pub fn is_leaf(&self) -> bool {
        self.node().kind == NodeKind::Leaf
    }

    /// Number of children (objects of a leaf, nodes of an internal node).
    pub fn len(&self) -> usize {
        self.node().len as usize
    }

    /// True for a node with no children (only an empty tree's root).
    pub fn is_empty(&self) -> bool {
        self.node().len == 0
    }

    /// The child nodes (none for a leaf).
    pub fn child_nodes(&self) -> impl Iterator<Item = NodeId> + 'a {
        let kids = if self.is_leaf() {
            &[][..]
        } else {
            self.bvh.kids(self.id)
        };
        kids.iter().map(|&c| NodeId(c))
    }

    /// The objects of a leaf (none for an internal node).
    pub fn objects(&self) -> impl Iterator<Item = ObjectId> + 'a {
        let kids = if self.is_leaf() {
            self.bvh.kids(self.id)
        } else {
            &[][..]
        };
        kids.iter().map(|&o| ObjectId(o))
    }

    /// The max-sphere bound (c, Rc): every object centre below lies inside it.
    pub fn bound(&self) -> Sphere {
        Sphere::new(self.node().centre, self.node().radius)
    }

    /// The largest object radius below.
    pub fn r_max(&self) -> f32 {
        self.node().r_max
    }

    /// A sphere holding every object sphere below: (c, Rc + r_max).
    pub fn outer_sphere(&self) -> Sphere {
        self.node().outer_sphere()
    }

    /// The box of the object spheres below.
    pub fn aabb(&self) -> Aabb {
        self.node().aabb
    }

    /// Number of objects below.
    pub fn count(&self) -> u32 {
        self.node().count
    }

    /// Sum of the shape descriptors below.
    pub fn shape_sum(&self) -> &'a [f32] {
        self.bvh.shape_sum(self.id)
    }

    /// Sum of the texture descriptors below.
    pub fn texture_sum(&self) -> &'a [f32] {
        self.bvh.texture_sum(self.id)
    }

    /// Mean shape descriptor below (zeros for an empty node).
    pub fn shape_centroid(&self) -> Vec<f32> {
        centroid(self.shape_sum(), self.count())
    }

    /// Mean texture descriptor below (zeros for an empty node).
    pub fn texture_centroid(&self) -> Vec<f32> {
        centroid(self.texture_sum(), self.count())
    }
}

fn centroid(sum: &[f32], count: u32) -> Vec<f32> {
    let inv = if count == 0 { 0.0 } else { 1.0 / count as f32 };
    sum.iter().map(|&s| s * inv).collect()
}

/// A read-only view of a live object.
#[derive(Clone, Copy)]
pub struct ObjectRef<'a> {
    bvh: &'a Bvh,
    id: u32,
}

impl std::fmt::Debug for ObjectRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ObjectRef")
            .field("id", &self.id)
            .field("model", &self.model())
            .field("sphere", &self.sphere())
            .field("leaf", &self.leaf())
            .finish()
    }
}

impl<'a> ObjectRef<'a> {
    /// This object's id.
    pub fn id(&self) -> ObjectId {
        ObjectId(self.id)
    }

    /// The model it instantiates.
    pub fn model(&self) -> u64 {
        self.bvh.objects.model[self.id as usize]
    }

    /// Its model-to-world transform.
    pub fn transform(&self) -> Affine3A {
        self.bvh.objects.transform[self.id as usize]
    }

    /// Its world-space bounding sphere.
    pub fn sphere(&self) -> Sphere {
        self.bvh.objects.sphere[self.id as usize]
    }

    /// Its shape descriptor.
    pub fn shape(&self) -> &'a [f32] {
        self.bvh.objects.shape(self.id)
    }

    /// Its texture descriptor.
    pub fn texture(&self) -> &'a [f32] {
        self.bvh.objects.texture(self.id)
    }

    /// The leaf holding it.
    pub fn leaf(&self) -> NodeId {
        NodeId(self.bvh.objects.leaf[self.id as usize])
    }
}
