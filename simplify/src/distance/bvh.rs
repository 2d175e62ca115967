//! A binary bounding-volume hierarchy over triangles for exact closest-point queries.
//!
//! Built top-down with binned SAH (16 bins along the widest centroid axis; Wald 2007, "On fast
//! construction of SAH-based bounding volume hierarchies"), falling back to an object-median
//! split when SAH cannot separate the centroids or the tree gets deep, so depth stays
//! O(log n). Subtrees above [`PARALLEL_BUILD`] triangles are built in parallel. Nodes are
//! stored depth-first: an internal node's left child follows it, its right child is at
//! `first`. The query visits the nearer child first and prunes every box farther than the best
//! distance found so far.

use glam::{DVec3, Vec3};
use horizon_mesh::Aabb;
use rayon::prelude::*;

use super::triangle::closest_on_triangle;

/// Leaves hold at most this many triangles.
const MAX_LEAF: usize = 4;
/// SAH bins per axis.
const BINS: usize = 16;
/// Below this depth SAH chooses splits; from it on, object medians (which halve the count).
const SAH_DEPTH: u32 = 40;
/// Subtrees with at least this many triangles build their children in parallel.
const PARALLEL_BUILD: usize = 1 << 15;

/// A node: its box, and either a leaf range (`count > 0`: triangles `first..first + count`) or,
/// for an internal node (`count == 0`), the index of the right child (the left child is next).
#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    first: u32,
    count: u32,
}

/// The result of a closest-point query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// The closest point on the surface.
    pub point: DVec3,
    /// Its squared distance to the query point.
    pub distance_squared: f64,
    /// The index of the triangle it lies on, in the order the triangles were given.
    pub triangle: u32,
}

/// A broken invariant found by [`TriangleBvh::validate`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("BVH node {node}: {problem}")]
pub struct InvalidBvh {
    /// The offending node (0 for problems with the whole tree).
    pub node: usize,
    /// What is wrong.
    pub problem: String,
}

/// A bounding-volume hierarchy over a triangle soup, answering exact closest-point queries.
#[derive(Clone, Debug, Default)]
pub struct TriangleBvh {
    nodes: Vec<Node>,
    /// Triangles in leaf order.
    triangles: Vec<[Vec3; 3]>,
    /// For each slot of `triangles`, its index in the input.
    ids: Vec<u32>,
}

/// What the builder moves around for each triangle: its box, centroid and input index. Records
/// are partitioned in place, so every pass over a node's triangles reads memory sequentially.
#[derive(Clone, Copy)]
struct Prim {
    lo: Vec3,
    hi: Vec3,
    centroid: Vec3,
    id: u32,
}

impl TriangleBvh {
    /// Builds the hierarchy in O(n log n). Triangles may be degenerate (points or segments);
    /// coordinates must be finite ([`TriangleBvh::from_mesh`] checks).
    ///
    /// # Panics
    /// If there are 2^32 or more triangles.
    pub fn new(triangles: Vec<[Vec3; 3]>) -> Self {
        assert!(
            u32::try_from(triangles.len()).is_ok(),
            "too many triangles for a BVH"
        );
        if triangles.is_empty() {
            return Self::default();
        }
        let mut prims: Vec<Prim> = triangles
            .par_iter()
            .enumerate()
            .map(|(id, t)| {
                let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
                Prim {
                    lo,
                    hi,
                    centroid: (lo + hi) * 0.5,
                    id: id as u32,
                }
            })
            .collect();
        let mut nodes = Vec::with_capacity(triangles.len() / 2 + 1);
        let bounds = Bounds::of(&prims);
        build_into(&mut prims, bounds, 0, 0, &mut nodes);
        let ids: Vec<u32> = prims.iter().map(|p| p.id).collect();
        let triangles = ids.par_iter().map(|&i| triangles[i as usize]).collect();
        Self {
            nodes,
            triangles,
            ids,
        }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Number of nodes, leaves included.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Longest root-to-leaf path, counted in nodes (0 when empty).
    pub fn depth(&self) -> usize {
        let mut deepest = 0;
        let mut stack = Vec::new();
        if !self.nodes.is_empty() {
            stack.push((0usize, 1usize));
        }
        while let Some((i, d)) = stack.pop() {
            deepest = deepest.max(d);
            let node = self.nodes[i];
            if node.count == 0 {
                stack.push((i + 1, d + 1));
                stack.push((node.first as usize, d + 1));
            }
        }
        deepest
    }

    /// The box around every triangle (empty when there are none).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| Aabb {
            min: n.min,
            max: n.max,
        })
    }

    /// The closest point of the triangles to `p`, or `None` when there are no triangles.
    pub fn closest(&self, p: DVec3) -> Option<Closest> {
        let mut stack = Vec::with_capacity(64);
        self.closest_hinted(p, None, &mut stack)
            .map(|(slot, point, d2)| Closest {
                point,
                distance_squared: d2,
                triangle: self.ids[slot as usize],
            })
    }

    /// The query behind [`TriangleBvh::closest`], seeded with the triangle in leaf slot `hint`
    /// (typically the answer for a nearby point) so that pruning starts tight. Returns the leaf
    /// slot, the closest point and its squared distance.
    pub(crate) fn closest_hinted(
        &self,
        p: DVec3,
        hint: Option<u32>,
        stack: &mut Vec<(u32, f64)>,
    ) -> Option<(u32, DVec3, f64)> {
        let root = self.nodes.first()?;
        let mut best = (0u32, DVec3::ZERO, f64::INFINITY);
        if let Some(slot) = hint.filter(|&s| (s as usize) < self.triangles.len()) {
            let (q, d2) = self.closest_on_slot(p, slot as usize);
            best = (slot, q, d2);
        }
        stack.clear();
        stack.push((0, box_distance_squared(root, p)));
        while let Some((index, d2)) = stack.pop() {
            if d2 >= best.2 {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                let start = node.first as usize;
                for slot in start..start + node.count as usize {
                    let (q, d2) = self.closest_on_slot(p, slot);
                    if d2 < best.2 {
                        best = (slot as u32, q, d2);
                    }
                }
                continue;
            }
            let (left, right) = (index + 1, node.first);
            let dl = box_distance_squared(&self.nodes[left as usize], p);
            let dr = box_distance_squared(&self.nodes[right as usize], p);
            // Push the farther child first so that the nearer one is visited first.
            let (near, far) = if dl <= dr {
                ((left, dl), (right, dr))
            } else {
                ((right, dr), (left, dl))
            };
            if far.1 < best.2 {
                stack.push(far);
            }
            if near.1 < best.2 {
                stack.push(near);
            }
        }
        best.2.is_finite().then_some(best)
    }

    fn closest_on_slot(&self, p: DVec3, slot: usize) -> (DVec3, f64) {
        let [a, b, c] = self.triangles[slot];
        closest_on_triangle(p, a.as_dvec3(), b.as_dvec3(), c.as_dvec3())
    }

    /// Checks the structure: every triangle in exactly one leaf, every leaf holding 1 to 4
    /// triangles inside its box, every child box inside its parent's box, every node
    /// reachable exactly once from the root, and the ids a permutation of the input indices.
    pub fn validate(&self) -> Result<(), InvalidBvh> {
        let fail = |node: usize, problem: String| Err(InvalidBvh { node, problem });
        if self.triangles.len() != self.ids.len() {
            return fail(0, "triangle and id arrays differ in length".into());
        }
        if self.nodes.is_empty() {
            return if self.triangles.is_empty() {
                Ok(())
            } else {
                fail(0, "triangles but no nodes".into())
            };
        }
        let mut seen_id = vec![false; self.ids.len()];
        for &id in &self.ids {
            match seen_id.get_mut(id as usize) {
                Some(seen) if !*seen => *seen = true,
                _ => return fail(0, format!("triangle id {id} repeated or out of range")),
            }
        }
        let mut covered = vec![false; self.triangles.len()];
        let mut visited = vec![false; self.nodes.len()];
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            if std::mem::replace(&mut visited[i], true) {
                return fail(i, "reached twice".into());
            }
            let node = self.nodes[i];
            if node.min.cmpgt(node.max).any() {
                return fail(i, "empty box".into());
            }
            if node.count > 0 {
                let start = node.first as usize;
                let end = start + node.count as usize;
                if end > self.triangles.len() {
                    return fail(i, format!("leaf range {start}..{end} past the triangles"));
                }
                if node.count as usize > MAX_LEAF {
                    return fail(i, format!("leaf holds {} triangles", node.count));
                }
                let leaf = covered[start..end]
                    .iter_mut()
                    .zip(&self.triangles[start..end]);
                for (slot, (covered, triangle)) in (start..).zip(leaf) {
                    if std::mem::replace(covered, true) {
                        return fail(i, format!("triangle slot {slot} in two leaves"));
                    }
                    for v in triangle {
                        if v.cmplt(node.min).any() || v.cmpgt(node.max).any() {
                            return fail(i, format!("triangle slot {slot} outside the leaf box"));
                        }
                    }
                }
                continue;
            }
            let (left, right) = (i + 1, node.first as usize);
            if right <= left || right >= self.nodes.len() {
                return fail(i, format!("bad right child {right}"));
            }
            for child in [left, right] {
                let c = self.nodes[child];
                if c.min.cmplt(node.min).any() || c.max.cmpgt(node.max).any() {
                    return fail(i, format!("child {child} box sticks out of the parent box"));
                }
                stack.push(child);
            }
        }
        if let Some(slot) = covered.iter().position(|&c| !c) {
            return fail(0, format!("triangle slot {slot} in no leaf"));
        }
        if let Some(node) = visited.iter().position(|&v| !v) {
            return fail(node, "unreachable".into());
        }
        Ok(())
    }
}

/// Squared distance from `p` to the node's box (0 inside).
#[inline]
fn box_distance_squared(node: &Node, p: DVec3) -> f64 {
    let below = node.min.as_dvec3() - p;
    let above = p - node.max.as_dvec3();
    below.max(above).max(DVec3::ZERO).length_squared()
}

/// Bounds of a set of primitives: their boxes' union and their centroids' box.
#[derive(Clone, Copy)]
struct Bounds {
    lo: Vec3,
    hi: Vec3,
    clo: Vec3,
    chi: Vec3,
}

impl Bounds {
    const EMPTY: Self = Self {
        lo: Vec3::INFINITY,
        hi: Vec3::NEG_INFINITY,
        clo: Vec3::INFINITY,
        chi: Vec3::NEG_INFINITY,
    };

    fn of(prims: &[Prim]) -> Self {
        prims.iter().fold(Self::EMPTY, |mut b, p| {
            b.add(p);
            b
        })
    }

    #[inline]
    fn add(&mut self, p: &Prim) {
        self.lo = self.lo.min(p.lo);
        self.hi = self.hi.max(p.hi);
        self.clo = self.clo.min(p.centroid);
        self.chi = self.chi.max(p.centroid);
    }

    fn union(&self, o: &Self) -> Self {
        Self {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
            clo: self.clo.min(o.clo),
            chi: self.chi.max(o.chi),
        }
    }
}

/// Builds the subtree over `prims` (reordered in place), whose bounds are `bounds`, and appends
/// it to `out` depth-first. `offset` is the position of `prims[0]` in the whole array.
fn build_into(prims: &mut [Prim], bounds: Bounds, offset: usize, depth: u32, out: &mut Vec<Node>) {
    let me = out.len();
    let n = prims.len();
    out.push(Node {
        min: bounds.lo,
        max: bounds.hi,
        first: offset as u32,
        count: n as u32,
    });
    if n <= MAX_LEAF {
        return;
    }
    let (mid, lb, rb) = split(prims, &bounds, depth);
    let (left, right) = prims.split_at_mut(mid);
    let right_index = if n >= PARALLEL_BUILD {
        let (l, r) = rayon::join(
            || subtree(left, lb, offset, depth + 1),
            || subtree(right, rb, offset + mid, depth + 1),
        );
        append(out, l);
        let right_index = out.len();
        append(out, r);
        right_index
    } else {
        build_into(left, lb, offset, depth + 1, out);
        let right_index = out.len();
        build_into(right, rb, offset + mid, depth + 1, out);
        right_index
    };
    out[me].first = right_index as u32;
    out[me].count = 0;
}

fn subtree(prims: &mut [Prim], bounds: Bounds, offset: usize, depth: u32) -> Vec<Node> {
    let mut out = Vec::with_capacity(prims.len() / 2 + 1);
    build_into(prims, bounds, offset, depth, &mut out);
    out
}

/// Appends a subtree built on its own, shifting its internal child links.
fn append(out: &mut Vec<Node>, subtree: Vec<Node>) {
    let base = out.len() as u32;
    out.extend(subtree.into_iter().map(|mut n| {
        if n.count == 0 {
            n.first += base;
        }
        n
    }));
}

/// Half the surface area of a box (the SAH weight); 0 for an empty box.
fn half_area(lo: Vec3, hi: Vec3) -> f32 {
    let e = (hi - lo).max(Vec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// Partitions `prims` into two non-empty parts; returns the size of the first and the bounds of
/// both.
fn split(prims: &mut [Prim], bounds: &Bounds, depth: u32) -> (usize, Bounds, Bounds) {
    let extent = bounds.chi - bounds.clo;
    let axis = extent.max_position();
    if depth < SAH_DEPTH && extent[axis] > 0.0 && extent[axis].is_finite() {
        let (lo, scale) = (bounds.clo[axis], BINS as f32 / extent[axis]);
        if let Some((bin, lb, rb)) = best_sah_split(prims, axis, lo, scale) {
            let mid = partition(prims, |p| bin_of(p.centroid[axis], lo, scale) <= bin);
            if mid > 0 && mid < prims.len() {
                return (mid, lb, rb);
            }
        }
    }
    // Object median along the widest centroid axis (any split works when all coincide).
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
    (mid, Bounds::of(&prims[..mid]), Bounds::of(&prims[mid..]))
}

#[inline]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    // `as` saturates: NaN and negatives go to 0, overflow to the last bin.
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Binned SAH along `axis`: the last bin of the left side minimising the cost, with the bounds of
/// both sides, or `None` when every centroid falls in one bin.
fn best_sah_split(
    prims: &[Prim],
    axis: usize,
    lo: f32,
    scale: f32,
) -> Option<(usize, Bounds, Bounds)> {
    let mut count = [0usize; BINS];
    let mut bins = [Bounds::EMPTY; BINS];
    for p in prims {
        let b = bin_of(p.centroid[axis], lo, scale);
        count[b] += 1;
        bins[b].add(p);
    }
    // Sweep from the right: bounds and cost of the right side of each split.
    let mut right = [Bounds::EMPTY; BINS];
    let mut right_cost = [0f32; BINS];
    let (mut acc, mut rn) = (Bounds::EMPTY, 0usize);
    for b in (1..BINS).rev() {
        acc = acc.union(&bins[b]);
        rn += count[b];
        right[b] = acc;
        right_cost[b] = half_area(acc.lo, acc.hi) * rn as f32;
    }
    let mut best: Option<(f32, usize, Bounds)> = None;
    let (mut acc, mut ln) = (Bounds::EMPTY, 0usize);
    for b in 0..BINS - 1 {
        acc = acc.union(&bins[b]);
        ln += count[b];
        if ln == 0 || ln == prims.len() {
            continue;
        }
        let cost = half_area(acc.lo, acc.hi) * ln as f32 + right_cost[b + 1];
        if best.is_none_or(|(c, _, _)| cost < c) {
            best = Some((cost, b, acc));
        }
    }
    best.map(|(_, b, left)| (b, left, right[b + 1]))
}

/// In-place partition; returns the number of elements satisfying `pred` (now in front).
fn partition(prims: &mut [Prim], pred: impl Fn(&Prim) -> bool) -> usize {
    let mut i = 0;
    for j in 0..prims.len() {
        if pred(&prims[j]) {
            prims.swap(i, j);
            i += 1;
        }
    }
    i
}
