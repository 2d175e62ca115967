//! The spatial baseline: the same objects in a purely spatial, SAH-optimised binary BVH built
//! by the `obvhs` crate (the "query-optimised" tree of the core paper's Figure 4), with the same
//! solid-angle cut (Sirikata's max-sphere worst case; `DESIGN.md`, "Cut test"), so the query
//! cost of the similarity-aware tree can be compared against it.
//!
//! `obvhs` stores boxes only. A box's bounding sphere is not Sirikata's max-sphere bound (a
//! sphere around the object *centres* plus the largest object radius), so a side array holds,
//! for every `obvhs` node, the max-sphere bound `(c, Rc)` and `r_max`, computed bottom-up:
//! a leaf fits a sphere around its objects' centres, an inner node around its two children's
//! bound spheres (the same fit as [`Bvh`]'s nodes). The cut is then the same best-first
//! refinement as [`Bvh::cut`]: nodes in a max-heap by worst-case solid angle, refined while at
//! least `Omega_min` and within `max_results`, a leaf replaced by its objects.
//!
//! The `obvhs` build is `BvhBuildParams::medium_build()`: PLOC clustering, then SAH-driven
//! reinsertion and leaf collapsing, on one thread (the crate's `parallel` feature is off).

use std::collections::BinaryHeap;
use std::time::Duration;

use obvhs::aabb::Aabb as ObAabb;
use obvhs::bvh2::Bvh2;
use obvhs::BvhBuildParams;

use crate::bounds::{fit_sphere, Sphere};
use crate::cut::{Candidate, CutQuery};
use crate::solid_angle::{solid_angle, worst_case_solid_angle};
use crate::tree::{Bvh, ObjectId};

/// An `obvhs` SAH BVH of a [`Bvh`]'s objects with max-sphere bounds per node.
pub struct SpatialBaseline {
    tree: Bvh2,
    /// Per `obvhs` node: the max-sphere bound and `r_max`, and the objects below.
    bounds: Vec<NodeBound>,
    /// Input index to object.
    ids: Vec<ObjectId>,
    /// Input index to bounding sphere.
    spheres: Vec<Sphere>,
}

impl std::fmt::Debug for SpatialBaseline {
    /// A summary (`obvhs`'s tree has no `Debug`).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpatialBaseline")
            .field("objects", &self.ids.len())
            .field("nodes", &self.tree.nodes.len())
            .finish()
    }
}

/// What a spatial cut entry stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SpatialItem {
    /// An object shown as itself.
    Object(ObjectId),
    /// An `obvhs` node (index into its node list) shown as one aggregate.
    Node(u32),
}

/// One entry of a spatial cut.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialEntry {
    /// The object or node.
    pub item: SpatialItem,
    /// Objects it covers.
    pub covers: u32,
    /// Exact solid angle of an object, worst case of a node.
    pub solid_angle: f32,
}

/// A cut through the spatial baseline.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SpatialCut {
    /// The entries, covering every object exactly once.
    pub entries: Vec<SpatialEntry>,
    /// Nodes whose worst case was evaluated.
    pub nodes_visited: usize,
}

impl SpatialBaseline {
    /// Builds the baseline over every live object of `bvh` (each object's sphere as a box).
    pub fn build(bvh: &Bvh) -> Self {
        let ids: Vec<ObjectId> = bvh.object_ids().collect();
        let spheres: Vec<Sphere> = ids
            .iter()
            .map(|&id| bvh.objects.sphere[id.0 as usize])
            .collect();
        let boxes: Vec<ObAabb> = spheres.iter().map(|s| to_obvhs(*s)).collect();
        let tree = if boxes.is_empty() {
            Bvh2::default()
        } else {
            let mut build_time = Duration::ZERO;
            obvhs::bvh2::builder::build_bvh2(
                &boxes,
                BvhBuildParams::medium_build(),
                &mut build_time,
            )
        };
        let mut baseline = Self {
            tree,
            bounds: Vec::new(),
            ids,
            spheres,
        };
        baseline.compute_bounds();
        baseline
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether it holds no object.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Number of `obvhs` nodes.
    pub fn node_count(&self) -> usize {
        self.tree.nodes.len()
    }

    /// The objects below `node`, appended to `out`.
    pub fn objects_under(&self, node: u32, out: &mut Vec<ObjectId>) {
        let mut stack = vec![node];
        while let Some(n) = stack.pop() {
            let nd = &self.tree.nodes[n as usize];
            if nd.is_leaf() {
                out.extend(self.prims(n).iter().map(|&p| self.ids[p as usize]));
            } else {
                stack.extend([nd.first_index, nd.first_index + 1]);
            }
        }
    }

    /// The cut for `query` (same rule and budget as [`Bvh::cut`]), written into `out`, with
    /// `heap` as reusable scratch.
    pub fn cut_into(&self, query: &CutQuery, heap: &mut SpatialWorkspace, out: &mut SpatialCut) {
        out.entries.clear();
        out.nodes_visited = 0;
        let heap = &mut heap.heap;
        heap.clear();
        if self.is_empty() {
            return;
        }
        let viewer = query.position;
        let max_results = query.max_results.max(1);
        heap.push(self.candidate(viewer, 0));
        out.nodes_visited = 1;
        let mut size = 1usize;
        while let Some(top) = heap.pop() {
            if top.solid_angle < query.min_solid_angle {
                out.entries.push(self.aggregate(top));
                break;
            }
            let node = &self.tree.nodes[top.node as usize];
            let len = if node.is_leaf() {
                node.prim_count as usize
            } else {
                2
            };
            if size + len > max_results + 1 {
                out.entries.push(self.aggregate(top));
                continue;
            }
            size += len - 1;
            if node.is_leaf() {
                for &p in self.prims(top.node) {
                    let s = self.spheres[p as usize];
                    out.entries.push(SpatialEntry {
                        item: SpatialItem::Object(self.ids[p as usize]),
                        covers: 1,
                        solid_angle: solid_angle(s.radius, (viewer - s.centre).length()),
                    });
                }
            } else {
                out.nodes_visited += 2;
                heap.push(self.candidate(viewer, node.first_index));
                heap.push(self.candidate(viewer, node.first_index + 1));
            }
        }
        for c in heap.drain() {
            out.entries.push(self.aggregate(c));
        }
    }

    /// The cut for `query` (allocates).
    pub fn cut(&self, query: &CutQuery) -> SpatialCut {
        let mut out = SpatialCut::default();
        self.cut_into(query, &mut SpatialWorkspace::default(), &mut out);
        out
    }

    fn prims(&self, n: u32) -> &[u32] {
        let node = &self.tree.nodes[n as usize];
        let start = node.first_index as usize;
        &self.tree.primitive_indices[start..start + node.prim_count as usize]
    }

    fn candidate(&self, viewer: glam::Vec3, n: u32) -> Candidate {
        let b = &self.bounds[n as usize];
        Candidate {
            solid_angle: worst_case_solid_angle(viewer, b.bound.centre, b.bound.radius, b.r_max),
            node: n,
        }
    }

    fn aggregate(&self, c: Candidate) -> SpatialEntry {
        SpatialEntry {
            item: SpatialItem::Node(c.node),
            covers: self.bounds[c.node as usize].count,
            solid_angle: c.solid_angle,
        }
    }

    /// The max-sphere bounds, children before parents (reverse preorder).
    fn compute_bounds(&mut self) {
        self.bounds = vec![NodeBound::default(); self.tree.nodes.len()];
        if self.is_empty() {
            return;
        }
        let mut order = Vec::with_capacity(self.tree.nodes.len());
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            order.push(n);
            let node = &self.tree.nodes[n as usize];
            if !node.is_leaf() {
                stack.extend([node.first_index, node.first_index + 1]);
            }
        }
        for &n in order.iter().rev() {
            let node = &self.tree.nodes[n as usize];
            let bound = if node.is_leaf() {
                let prims = self.prims(n);
                let spheres = &self.spheres;
                let mut r_max = 0.0f32;
                for &p in prims {
                    r_max = r_max.max(spheres[p as usize].radius);
                }
                NodeBound {
                    bound: fit_sphere(
                        prims
                            .iter()
                            .map(|&p| Sphere::new(spheres[p as usize].centre, 0.0)),
                    ),
                    r_max,
                    count: prims.len() as u32,
                }
            } else {
                let (a, b) = (
                    self.bounds[node.first_index as usize],
                    self.bounds[node.first_index as usize + 1],
                );
                NodeBound {
                    bound: fit_sphere([a.bound, b.bound].into_iter()),
                    r_max: a.r_max.max(b.r_max),
                    count: a.count + b.count,
                }
            };
            self.bounds[n as usize] = bound;
        }
    }
}

/// Scratch for [`SpatialBaseline::cut_into`].
#[derive(Debug, Default)]
pub struct SpatialWorkspace {
    heap: BinaryHeap<Candidate>,
}

/// The max-sphere bound of an `obvhs` node.
#[derive(Clone, Copy, Debug, Default)]
struct NodeBound {
    bound: Sphere,
    r_max: f32,
    count: u32,
}

/// An `obvhs` box from a sphere. `obvhs` uses its own `glam` version, so the components are
/// set one by one rather than converted.
fn to_obvhs(s: Sphere) -> ObAabb {
    let mut b = ObAabb::default();
    let (lo, hi) = (s.centre - s.radius, s.centre + s.radius);
    (b.min.x, b.min.y, b.min.z) = (lo.x, lo.y, lo.z);
    (b.max.x, b.max.y, b.max.z) = (hi.x, hi.y, hi.z);
    b
}
