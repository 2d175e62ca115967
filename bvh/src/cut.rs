//! The solid-angle cut query (Sirikata's max-sphere cut, Cheslack-Postava et al. 2012; core
//! paper eq. 3 and section 3; `DESIGN.md`, "Cut test").
//!
//! Best-first refinement from the root: a max-heap holds the cut's nodes keyed by their
//! worst-case solid angle (an `r_max` object at the bound's nearest point). The node on top is
//! replaced by its children (a leaf by its objects) while its worst case subtends at least
//! `Omega_min` and the result stays within `max_results`; otherwise it stays in the cut as an
//! aggregate. Objects are never refined. Since every refinement replaces a node by exactly its
//! children, the result covers every object exactly once, itself or through one ancestor:
//! the complete-view invariant.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::bounds::{Aabb, Sphere};
use crate::solid_angle::{solid_angle, worst_case_solid_angle};
use crate::tree::{Bvh, Node, NodeId, NodeKind, ObjectId, NONE};

/// The smallest solid angle (steradians) a client sees as itself unless it asks for another:
/// an object of 1 m radius at 56 m. The aggregates' budgets assume it too.
pub const DEFAULT_MIN_SOLID_ANGLE: f64 = 1e-3;

/// The most entries a cut holds unless a client asks for another number.
pub const DEFAULT_MAX_RESULTS: usize = 4000;

/// A client's view request.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CutQuery {
    /// The viewer's position in world space.
    pub position: Vec3,
    /// The smallest solid angle (steradians) that must be shown as itself: a node whose worst
    /// case subtends at least this much is refined.
    pub min_solid_angle: f32,
    /// The most entries the cut may hold (at least 1 is always returned for a non-empty
    /// tree: the root).
    pub max_results: usize,
}

/// What a cut entry stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CutItem {
    /// An object shown as itself.
    Object(ObjectId),
    /// A node shown as one aggregate of every object below it.
    Aggregate(NodeId),
}

/// The two kinds of cut entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum EntryKind {
    /// An object.
    Object,
    /// A node's aggregate.
    Aggregate,
}

/// One entry of a cut.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CutEntry {
    /// The object or node.
    pub item: CutItem,
    /// The node above it (the leaf of an object), `None` for the root.
    pub parent: Option<NodeId>,
    /// A sphere holding everything the entry covers: the object's bounding sphere, or the
    /// node's max-sphere bound widened by `r_max`.
    pub sphere: Sphere,
    /// The box of the object spheres it covers.
    pub aabb: Aabb,
    /// Number of objects it covers (1 for an object).
    pub covers: u32,
    /// Solid angle from the viewer: exact for an object, the worst case for an aggregate.
    pub solid_angle: f32,
}

impl CutEntry {
    /// Object or aggregate.
    pub fn kind(&self) -> EntryKind {
        match self.item {
            CutItem::Object(_) => EntryKind::Object,
            CutItem::Aggregate(_) => EntryKind::Aggregate,
        }
    }
}

/// A cut through the tree.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Cut {
    /// The entries, covering every object exactly once.
    pub entries: Vec<CutEntry>,
    /// Nodes whose worst-case solid angle was evaluated (the root and every child of a
    /// refined internal node).
    pub nodes_visited: usize,
}

/// Scratch space for cut queries, reused between calls so a query allocates nothing once the
/// buffers have grown.
#[derive(Debug, Default)]
pub struct CutWorkspace {
    pub(crate) heap: BinaryHeap<Candidate>,
    /// The nodes the last query refined, in order.
    pub(crate) refined: Vec<u32>,
    /// Their refinement-order keys ([`order_key`]).
    pub(crate) refined_keys: Vec<u64>,
    /// How many nodes were refined when the budget first kept a node from refining, or
    /// `None` if the budget did not bind.
    pub(crate) skipped_at: Option<usize>,
}

impl CutWorkspace {
    /// An empty workspace.
    pub fn new() -> Self {
        Self::default()
    }
}

impl Bvh {
    /// The cut for `query` (allocates its result; see [`Bvh::cut_into`] to reuse buffers).
    pub fn cut(&self, query: &CutQuery) -> Cut {
        let mut cut = Cut::default();
        self.cut_into(query, &mut CutWorkspace::new(), &mut cut);
        cut
    }

    /// The cut for `query`, written into `out` (cleared first) with `workspace`'s heap.
    pub fn cut_into(&self, query: &CutQuery, workspace: &mut CutWorkspace, out: &mut Cut) {
        out.entries.clear();
        out.nodes_visited = 0;
        workspace.heap.clear();
        workspace.refined.clear();
        workspace.refined_keys.clear();
        workspace.skipped_at = None;
        if self.is_empty() {
            return;
        }
        // Start from the root alone.
        workspace
            .heap
            .push(self.candidate(query.position, self.root));
        out.nodes_visited = 1;
        self.refine_best_first(query, workspace, 1, out);
    }

    /// The best-first refinement, continued from a partial cut: `workspace.heap` holds its
    /// unrefined nodes that may still be refined, `out.entries` the rest of it, and `size`
    /// counts both. Appends every node it refines to `workspace.refined` (and its key to
    /// `refined_keys`).
    ///
    /// Seeded with the root alone this is the whole query. Seeded with the frontier of any
    /// cut that refines exactly the nodes whose [`order_key`] is at least some key, if that
    /// cut fits the budget, it gives the same result: the best-first order refines every
    /// node of such a cut before any other, and none of them can be kept for the budget
    /// (`StandingQuery` relies on this).
    pub(crate) fn refine_best_first(
        &self,
        query: &CutQuery,
        workspace: &mut CutWorkspace,
        mut size: usize,
        out: &mut Cut,
    ) {
        let max_results = query.max_results.max(1);
        let viewer = query.position;
        let CutWorkspace {
            heap,
            refined,
            refined_keys,
            skipped_at,
        } = workspace;
        // Once no refinement can fit, stop popping: every node but the root (which may have
        // one child) has at least `min_children`.
        let smallest_growth = self.options.min_children.saturating_sub(1);
        // Refine the largest worst case first.
        while let Some(top) = heap.pop() {
            let node = &self.nodes[top.node as usize];
            if top.solid_angle < query.min_solid_angle {
                // Everything left in the heap subtends less: all of it stays as aggregates.
                out.entries
                    .push(self.aggregate(top.node, node, top.solid_angle));
                break;
            }
            let len = node.len as usize;
            if size + len > max_results + 1 {
                // Refining would exceed the budget: it stays as an aggregate.
                out.entries
                    .push(self.aggregate(top.node, node, top.solid_angle));
                skipped_at.get_or_insert(refined.len());
                if smallest_growth > 0 && size + smallest_growth > max_results {
                    break;
                }
                continue;
            }
            size += len - 1;
            refined.push(top.node);
            refined_keys.push(top.key());
            let kids = self.kids(top.node);
            match node.kind {
                NodeKind::Leaf => {
                    for &o in kids {
                        out.entries.push(self.object_entry(viewer, o, top.node));
                    }
                }
                _ => {
                    out.nodes_visited += len;
                    for &c in kids {
                        heap.push(self.candidate(viewer, c));
                    }
                }
            }
        }
        // What is left in the heap is part of the cut as aggregates.
        for c in heap.drain() {
            let node = &self.nodes[c.node as usize];
            out.entries
                .push(self.aggregate(c.node, node, c.solid_angle));
        }
    }

    #[inline]
    fn candidate(&self, viewer: Vec3, n: u32) -> Candidate {
        let node = &self.nodes[n as usize];
        Candidate {
            solid_angle: worst_case_solid_angle(viewer, node.centre, node.radius, node.r_max),
            node: n,
        }
    }

    /// Refines node `n` of a heap-free walk: a leaf's objects become entries, an internal
    /// node's children go on `stack`. Returns how many went on the stack.
    pub(crate) fn refine_onto(
        &self,
        viewer: Vec3,
        n: u32,
        entries: &mut Vec<CutEntry>,
        stack: &mut Vec<u32>,
    ) -> usize {
        let kids = self.kids(n);
        match self.nodes[n as usize].kind {
            NodeKind::Leaf => {
                entries.extend(kids.iter().map(|&o| self.object_entry(viewer, o, n)));
                0
            }
            _ => {
                stack.extend_from_slice(kids);
                kids.len()
            }
        }
    }

    pub(crate) fn aggregate(&self, n: u32, node: &Node, solid_angle: f32) -> CutEntry {
        CutEntry {
            item: CutItem::Aggregate(NodeId(n)),
            parent: (node.parent != NONE).then_some(NodeId(node.parent)),
            sphere: node.outer_sphere(),
            aabb: node.aabb,
            covers: node.count,
            solid_angle,
        }
    }

    pub(crate) fn object_entry(&self, viewer: Vec3, o: u32, leaf: u32) -> CutEntry {
        let sphere = self.objects.sphere[o as usize];
        CutEntry {
            item: CutItem::Object(ObjectId(o)),
            parent: Some(NodeId(leaf)),
            sphere,
            aabb: Aabb::of_sphere(sphere),
            covers: 1,
            solid_angle: solid_angle(sphere.radius, (viewer - sphere.centre).length()),
        }
    }
}

/// A node in the refinement heap, ordered by worst-case solid angle (ties by id, so the
/// result does not depend on heap internals). Shared with the spatial baseline.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Candidate {
    pub(crate) solid_angle: f32,
    pub(crate) node: u32,
}

impl Candidate {
    /// Its [`order_key`].
    #[inline]
    pub(crate) fn key(&self) -> u64 {
        order_key(self.solid_angle, self.node)
    }
}

/// The best-first refinement order as one integer: a larger key is refined first. The solid
/// angle's bits, then the node id reversed (ties go to the smaller id). Solid angles are
/// never negative, and the bits of non-negative floats (NaN included) order as
/// `f32::total_cmp` does.
#[inline]
pub(crate) fn order_key(solid_angle: f32, node: u32) -> u64 {
    debug_assert!(solid_angle.is_sign_positive());
    (u64::from(solid_angle.to_bits()) << 32) | u64::from(u32::MAX - node)
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.key() == other.key()
    }
}

impl Eq for Candidate {}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Candidate {
    #[inline]
    fn cmp(&self, other: &Self) -> Ordering {
        self.key().cmp(&other.key())
    }
}
