//! Top-down bulk rebuild (Azim et al. 2014, section 4.3).
//!
//! "A top-down bulk construction algorithm considers a set of axis-aligned candidate split
//! planes at each level of the tree. It computes the mutual similarity, defined as the average
//! distance of the shape descriptors from their centroid, of the groups of objects on either
//! side of each plane [...] The partition plane is then chosen as the plane that yields the
//! maximum similarity among objects in the two partitions."
//!
//! Implementation:
//! - Candidate planes: the object centres are binned into `bulk_bins` equal slabs per axis
//!   and every slab boundary is a candidate (binned SAH builders do the same for their cost).
//! - Dispersion: the sum over both sides of the squared descriptor distances to the side's
//!   centroid, `SSE = sum |x|^2 - |sum x|^2 / n`, which per-bin sums turn into prefix sums:
//!   one pass over the objects and one over the bins per node, so each level is O(n) and the
//!   build O(n log n). The squared distance (a variance) is what prefix sums can add up; the
//!   paper's plain mean distance cannot be. Shape and texture are weighted as in eq. 1:
//!   `(1 - w) SSE_shape / shape_scale^2 + w SSE_texture / texture_scale^2` (w = 0 is the
//!   paper's shape-only measure).
//! - Cost of a plane: `mu * dispersion(L, R) / dispersion(parent) +
//!   (1 - mu) * (n_L A_L + n_R A_R) / (n A_parent)`, A the surface area of a side's box of
//!   object spheres. At mu = 1 only the dispersion counts, as in the paper; below 1 the
//!   spatial term (the SAH) weighs in as the volume term does in eq. 1, and it alone decides
//!   when the descriptors do not vary across the node (so identical models still split
//!   compactly).
//! - Branching: a node of `n` objects gets `k` children, about `n / (leaf_size * B^t)` for
//!   children of height t; the objects are cut in two by the best plane, each side taking a
//!   share of the `k` children in proportion to its objects, recursively until each share is
//!   one child. Every child of height t must hold between `min^(t+1)` and `B^(t+1)` objects
//!   (so that it can itself be filled within the limits all the way down); planes breaking
//!   that are skipped, and when none is left the node is cut at the feasible count closest to
//!   its share along its widest axis (a median-style split).
//! - Parallelism: the two sides of every cut are built with `rayon::join`, and the binning of
//!   large nodes is a parallel fold.

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;

use crate::bounds::Aabb;
use crate::tree::{
    add_sums, add_widened, bounds_of_nodes, bounds_of_objects, narrow_into, Bvh, NewObject, Node,
    NodeKind, Objects, NONE,
};
use crate::{BvhError, BvhOptions, SHAPE_LEN, TEXTURE_LEN};

/// Below this many objects the two sides of a cut are built on the calling thread: the
/// work is then too small to be worth handing to another thread.
const PARALLEL_MIN: usize = 4096;
/// At or above this many objects a node's binning is split into parallel chunks.
const PARALLEL_BINNING_MIN: usize = 1 << 16;
/// Objects per parallel binning chunk.
const BINNING_CHUNK: usize = 1 << 14;
/// Dispersion below this fraction of the descriptors' second moment is rounding noise: the
/// descriptors are then taken as identical across the node.
const DISPERSION_NOISE: f64 = 1e-9;

impl Bvh {
    /// A tree over `objects`, built top-down (section 4.3) on all of rayon's threads. Object
    /// ids are `0..objects.len()` in order. Nothing is built if any object is refused.
    pub fn bulk_build(options: BvhOptions, objects: &[NewObject<'_>]) -> Result<Self, BvhError> {
        // Refuse bad options or input before storing anything.
        let mut bvh = Self::new(options)?;
        for object in objects {
            object.check()?;
        }
        // Store the objects, then build over them.
        bvh.objects.reserve(objects.len());
        for object in objects {
            bvh.objects.alloc(object)?;
        }
        bvh.rebuild();
        Ok(bvh)
    }

    /// Rebuilds the hierarchy over the current objects (section 4.3: "every few hours, the
    /// system reconstructs the BVH"). Object ids are kept; node ids are all new.
    pub fn rebuild(&mut self) {
        self.touch();
        // The live objects, in id order.
        let mut ids: Vec<u32> = (0..self.objects.leaf.len() as u32)
            .filter(|&o| self.objects.is_live(o))
            .collect();
        // The size limits per height, and the height that holds every object.
        let limits = Limits::new(&self.options, ids.len());
        // Plan the hierarchy top-down, in parallel.
        let planner = Planner {
            objects: &self.objects,
            options: &self.options,
            limits: &limits,
        };
        let plan = planner.plan_root(&mut ids);
        // Lay the nodes out breadth-first and fill in totals and bounds bottom-up.
        self.assemble(&plan, &ids, limits.height);
        self.debug_validate();
    }

    /// Writes the planned hierarchy into the arena: node ids in breadth-first order (siblings
    /// contiguous, each level one range), then counts, sums and bounds one level at a time
    /// from the leaves up, each level in parallel.
    fn assemble(&mut self, plan: &Plan, ids: &[u32], height: u32) {
        // Breadth-first order, level by level.
        let mut order: Vec<&Plan> = vec![plan];
        // The root alone is the first level.
        let mut levels: Vec<Range<usize>> = Vec::new();
        levels.push(0..1);
        loop {
            let last = levels[levels.len() - 1].clone();
            for i in last.clone() {
                let p: &Plan = order[i];
                if let Plan::Internal(kids) = p {
                    order.extend(kids.iter());
                }
            }
            if order.len() == last.end {
                break;
            }
            levels.push(last.end..order.len());
        }
        // Fresh arrays.
        let stride = self.stride();
        let total = order.len();
        self.nodes = vec![
            Node {
                centre: Vec3::ZERO,
                radius: 0.0,
                r_max: 0.0,
                parent: NONE,
                count: 0,
                len: 0,
                kind: NodeKind::Leaf,
                aabb: Aabb::ZERO,
            };
            total
        ];
        self.children = vec![NONE; total * stride];
        self.shape_sum = vec![0.0; total * SHAPE_LEN];
        self.texture_sum = vec![0.0; total * TEXTURE_LEN];
        self.free_nodes = Vec::new();
        self.root = 0;
        self.height = height;
        // Links: children of node i are the next ids in breadth-first order.
        let mut next = 1u32;
        for (i, p) in order.iter().enumerate() {
            let slot = &mut self.children[i * stride..(i + 1) * stride];
            match p {
                Plan::Leaf(range) => {
                    let objects = &ids[range.clone()];
                    slot[..objects.len()].copy_from_slice(objects);
                    for &o in objects {
                        self.objects.leaf[o as usize] = i as u32;
                    }
                    self.nodes[i].len = objects.len() as u16;
                }
                Plan::Internal(kids) => {
                    for (j, s) in slot[..kids.len()].iter_mut().enumerate() {
                        *s = next + j as u32;
                        self.nodes[(next as usize) + j].parent = i as u32;
                    }
                    next += kids.len() as u32;
                    self.nodes[i].kind = NodeKind::Internal;
                    self.nodes[i].len = kids.len() as u16;
                }
            }
        }
        // Totals and bounds, deepest level first.
        for level in levels.iter().rev() {
            self.fill_level(level.clone());
        }
    }

    /// Counts, bounds and descriptor sums of the nodes in `level`, whose children (nodes of
    /// the next level, or objects) are already filled.
    fn fill_level(&mut self, level: Range<usize>) {
        let stride = self.stride();
        let (a, b) = (level.start, level.end);
        let children = &self.children;
        let objects = &self.objects;
        // Counts and bounds.
        {
            let (head, tail) = self.nodes.split_at_mut(b);
            let tail: &[Node] = tail;
            head[a..].par_iter_mut().enumerate().for_each(|(j, node)| {
                let start = (a + j) * stride;
                let kids = &children[start..start + node.len as usize];
                let (sphere, r_max, aabb) = match node.kind {
                    NodeKind::Leaf => {
                        node.count = kids.len() as u32;
                        bounds_of_objects(objects, kids)
                    }
                    _ => {
                        node.count = kids.iter().map(|&c| tail[c as usize - b].count).sum();
                        bounds_of_nodes(kids, |c| &tail[c as usize - b])
                    }
                };
                node.centre = sphere.centre;
                node.radius = sphere.radius;
                node.r_max = r_max;
                node.aabb = aabb;
            });
        }
        // Descriptor sums, shape then texture.
        let nodes = &self.nodes;
        let shape = &self.objects.shape;
        let texture = &self.objects.texture;
        fill_sums(
            &mut self.shape_sum,
            SHAPE_LEN,
            shape,
            nodes,
            children,
            stride,
            a..b,
        );
        fill_sums(
            &mut self.texture_sum,
            TEXTURE_LEN,
            texture,
            nodes,
            children,
            stride,
            a..b,
        );
    }
}

/// Descriptor sums (`len` values per node in `sums`; per object in `source`) of the nodes in
/// `level`, from their objects (leaves) or from the next level's sums, added in f64.
fn fill_sums(
    sums: &mut [f32],
    len: usize,
    source: &[f32],
    nodes: &[Node],
    children: &[u32],
    stride: usize,
    level: Range<usize>,
) {
    let (a, b) = (level.start, level.end);
    let (head, tail) = sums.split_at_mut(b * len);
    let tail: &[f32] = tail;
    head[a * len..]
        .par_chunks_mut(len)
        .enumerate()
        .for_each(|(j, sum)| {
            let node = &nodes[a + j];
            let start = (a + j) * stride;
            let mut wide = [0.0f64; SHAPE_LEN];
            let wide = &mut wide[..len];
            for &k in &children[start..start + node.len as usize] {
                let k = k as usize;
                match node.kind {
                    NodeKind::Leaf => add_widened(wide, &source[k * len..(k + 1) * len]),
                    _ => add_widened(wide, &tail[(k - b) * len..(k - b + 1) * len]),
                }
            }
            narrow_into(sum, wide);
        });
}

/// The planned hierarchy: leaves are ranges of the permuted object ids.
enum Plan {
    Leaf(Range<usize>),
    Internal(Vec<Plan>),
}

/// Size limits per height t (a leaf is height 0): a subtree of height t holds between
/// `lo[t] = min^(t+1)` and `hi[t] = B^(t+1)` objects and aims for `target[t] = leaf_size *
/// B^t`.
struct Limits {
    lo: Vec<usize>,
    hi: Vec<usize>,
    target: Vec<usize>,
    /// The root's height: the lowest whose `target` holds every object.
    height: u32,
    min_children: usize,
    max_children: usize,
}

impl Limits {
    fn new(options: &BvhOptions, n: usize) -> Self {
        let (m, b, l) = (
            options.min_children,
            options.max_children,
            options.leaf_size,
        );
        let mut limits = Self {
            lo: vec![m],
            hi: vec![b],
            target: vec![l],
            height: 0,
            min_children: m,
            max_children: b,
        };
        // The height is the lowest whose *target* capacity, `leaf_size * B^height`, holds
        // every object, so that bulk-built leaves average about `leaf_size` objects and keep
        // room for inserts (the hard capacity `B^(height+1)` would fill them to the brim).
        while limits.target[limits.height as usize] < n {
            let t = limits.height as usize;
            limits.lo.push(limits.lo[t].saturating_mul(m));
            limits.hi.push(limits.hi[t].saturating_mul(b));
            limits.target.push(limits.target[t].saturating_mul(b));
            limits.height += 1;
        }
        limits
    }
}

/// What the top-down planning reads: the objects and the limits.
struct Planner<'a> {
    objects: &'a Objects,
    options: &'a BvhOptions,
    limits: &'a Limits,
}

impl Planner<'_> {
    /// The whole hierarchy over `ids` (reordered in place).
    fn plan_root(&self, ids: &mut [u32]) -> Plan {
        let height = self.limits.height as usize;
        if height == 0 {
            return Plan::Leaf(0..ids.len());
        }
        // The root needs only two children (no minimum fill).
        let k = self.child_count(ids.len(), height - 1, 2);
        Plan::Internal(self.partition(ids, 0, k, height - 1))
    }

    /// The subtree of height `t` over `ids`, which start at `offset` in the full order.
    fn plan_node(&self, ids: &mut [u32], offset: usize, t: usize) -> Plan {
        if t == 0 {
            return Plan::Leaf(offset..offset + ids.len());
        }
        let k = self.child_count(ids.len(), t - 1, self.limits.min_children);
        Plan::Internal(self.partition(ids, offset, k, t - 1))
    }

    /// Children for `n` objects in subtrees of height `t`: near `n / target[t]`, within what
    /// the limits allow (`n / hi[t]..=n / lo[t]`, `min_fill..=B`). The limits make this range
    /// non-empty (see the module documentation).
    fn child_count(&self, n: usize, t: usize, min_fill: usize) -> usize {
        let (lo, hi) = (self.limits.lo[t], self.limits.hi[t]);
        let low = n.div_ceil(hi).max(min_fill);
        let high = (n / lo).min(self.limits.max_children);
        let target = ((n as f64 / self.limits.target[t] as f64).round() as usize).max(1);
        target.clamp(low, high.max(low))
    }

    /// Cuts `ids` into `k` groups for subtrees of height `t`, recursively in two, and plans
    /// each group's subtree.
    fn partition(&self, ids: &mut [u32], offset: usize, k: usize, t: usize) -> Vec<Plan> {
        if k == 1 {
            return vec![self.plan_node(ids, offset, t)];
        }
        // The best plane (or the fallback cut), with each side's share of the k groups.
        let (k_left, n_left) = self.cut(ids, k, t);
        let parallel = ids.len() >= PARALLEL_MIN;
        let (left, right) = ids.split_at_mut(n_left);
        let k_right = k - k_left;
        let (mut plans, rest) = if parallel {
            rayon::join(
                || self.partition(left, offset, k_left, t),
                || self.partition(right, offset + n_left, k_right, t),
            )
        } else {
            (
                self.partition(left, offset, k_left, t),
                self.partition(right, offset + n_left, k_right, t),
            )
        };
        plans.extend(rest);
        plans
    }

    /// Chooses and applies the cut of `ids` into two sides holding `k_left` and `k - k_left`
    /// groups of height-`t` subtrees; returns `(k_left, n_left)` with the left side first in
    /// `ids`.
    fn cut(&self, ids: &mut [u32], k: usize, t: usize) -> (usize, usize) {
        let n = ids.len();
        let feasible = Feasible {
            n,
            k,
            lo: self.limits.lo[t],
            hi: self.limits.hi[t],
        };
        // Bin the centres along each axis.
        let bounds = self.centre_bounds(ids);
        let bins = (self.options.bulk_bins).min(n).max(2);
        let grid = BinGrid::new(bounds, bins);
        let binned = self.accumulate(ids, &grid);
        // The cheapest feasible plane.
        if let Some(plane) = self.best_plane(&binned, &grid, &feasible) {
            let n_left = partition_in_place(ids, |o| {
                grid.bin(plane.axis, self.centre(o)) < plane.boundary
            });
            debug_assert_eq!(n_left, plane.n_left, "binning and partition disagree");
            return (plane.k_left, n_left);
        }
        // No feasible plane: cut at a feasible count along the widest axis.
        let k_left = k / 2;
        let n_left = feasible.count_for(k_left);
        let axis = bounds.extent().max_position();
        ids.select_nth_unstable_by(n_left, |&a, &b| {
            self.centre(a)[axis].total_cmp(&self.centre(b)[axis])
        });
        (k_left, n_left)
    }

    #[inline]
    fn centre(&self, o: u32) -> Vec3 {
        self.objects.sphere[o as usize].centre
    }

    /// The box of the object centres (parallel for large sets).
    fn centre_bounds(&self, ids: &[u32]) -> Aabb {
        let fold = |acc: Aabb, &o: &u32| acc.with_point(self.centre(o));
        if ids.len() >= PARALLEL_BINNING_MIN {
            ids.par_iter()
                .fold(|| Aabb::EMPTY, fold)
                .reduce(|| Aabb::EMPTY, Aabb::union)
        } else {
            ids.iter().fold(Aabb::EMPTY, fold)
        }
    }

    /// Per-bin counts, boxes and descriptor sums along all three axes.
    fn accumulate(&self, ids: &[u32], grid: &BinGrid) -> Bins {
        if ids.len() >= PARALLEL_BINNING_MIN {
            ids.par_chunks(BINNING_CHUNK)
                .map(|chunk| {
                    let mut bins = Bins::new(grid.bins);
                    bins.add_objects(self.objects, chunk, grid);
                    bins
                })
                .reduce_with(|mut a, b| {
                    a.merge(&b);
                    a
                })
                .unwrap_or_else(|| Bins::new(grid.bins))
        } else {
            let mut bins = Bins::new(grid.bins);
            bins.add_objects(self.objects, ids, grid);
            bins
        }
    }

    /// The cheapest plane over all axes whose sides can be filled within the limits.
    fn best_plane(&self, binned: &Bins, grid: &BinGrid, feasible: &Feasible) -> Option<Plane> {
        let opts = self.options;
        let weights = DispersionWeights::new(opts);
        let nb = grid.bins;
        let mut best: Option<Plane> = None;
        // The parent's dispersion and area, from axis 0's bins (every axis bins all objects).
        let parent = Side::of_bins(binned, 0, 0..nb);
        let parent_dispersion = parent.dispersion(&weights);
        let descriptors_vary = parent_dispersion > DISPERSION_NOISE * parent.moment(&weights);
        let parent_area = parent.count as f64 * f64::from(parent.aabb.surface_area());
        let mu = f64::from(opts.mu);
        let mut right = vec![(0.0f64, 0.0f64, 0usize); nb];
        for axis in 0..3 {
            if grid.scale[axis] == 0.0 {
                continue;
            }
            // Right sides, from the last bin down: right[b] is bins b..nb.
            let mut side = Side::empty();
            for bin in (1..nb).rev() {
                side.add_bin(binned, axis * nb + bin);
                right[bin] = (side.dispersion(&weights), side.area(), side.count);
            }
            // Left sides, from the first bin up, each against its right side.
            let mut side = Side::empty();
            for (boundary, &(right_dispersion, right_area, _)) in right.iter().enumerate().skip(1) {
                side.add_bin(binned, axis * nb + boundary - 1);
                let n_left = side.count;
                let Some(k_left) = feasible.k_left(n_left) else {
                    continue;
                };
                let similarity = if descriptors_vary {
                    (side.dispersion(&weights) + right_dispersion) / parent_dispersion
                } else {
                    0.0
                };
                let spatial = if parent_area > 0.0 {
                    (side.area() + right_area) / parent_area
                } else {
                    0.0
                };
                let cost = mu * similarity + (1.0 - mu) * spatial;
                if best.as_ref().is_none_or(|b| cost < b.cost) {
                    best = Some(Plane {
                        axis,
                        boundary,
                        n_left,
                        k_left,
                        cost,
                    });
                }
            }
        }
        best
    }
}

/// A chosen plane: objects in bins `< boundary` along `axis` go left.
struct Plane {
    axis: usize,
    boundary: usize,
    n_left: usize,
    k_left: usize,
    cost: f64,
}

/// Which left-side counts can be filled within the limits, and with how many groups.
struct Feasible {
    n: usize,
    k: usize,
    lo: usize,
    hi: usize,
}

impl Feasible {
    /// The left side's share of the `k` groups for `n_left` objects, closest to proportional,
    /// or `None` when no share lets both sides fill their groups within `lo..=hi`.
    fn k_left(&self, n_left: usize) -> Option<usize> {
        let n_right = self.n.checked_sub(n_left)?;
        let low = 1
            .max(n_left.div_ceil(self.hi))
            .max(self.k.saturating_sub(n_right / self.lo));
        let high = (self.k - 1)
            .min(n_left / self.lo)
            .min(self.k.saturating_sub(n_right.div_ceil(self.hi)));
        if low > high {
            return None;
        }
        let proportional = (self.k as f64 * n_left as f64 / self.n as f64).round() as usize;
        Some(proportional.clamp(low, high))
    }

    /// A left-side count for `k_left` groups: proportional, moved into the feasible range.
    fn count_for(&self, k_left: usize) -> usize {
        let k_right = self.k - k_left;
        let low = (k_left * self.lo).max(self.n.saturating_sub(k_right * self.hi));
        let high = (k_left * self.hi).min(self.n - k_right * self.lo);
        (self.n * k_left / self.k).clamp(low, high.max(low))
    }
}

/// Equal-width bins over the centres' box.
struct BinGrid {
    min: Vec3,
    /// Bins per unit length along each axis (0 for an axis of zero extent: no planes there).
    scale: Vec3,
    bins: usize,
}

impl BinGrid {
    fn new(bounds: Aabb, bins: usize) -> Self {
        let extent = bounds.extent();
        let scale = Vec3::select(
            extent.cmpgt(Vec3::ZERO),
            Vec3::splat(bins as f32) / extent,
            Vec3::ZERO,
        );
        Self {
            min: bounds.min,
            scale,
            bins,
        }
    }

    /// The bin of `p` along `axis` (the same arithmetic for binning and partitioning, so
    /// both agree exactly).
    #[inline]
    fn bin(&self, axis: usize, p: Vec3) -> usize {
        // `as usize` saturates negative values to 0; the top edge lands in the last bin.
        (((p[axis] - self.min[axis]) * self.scale[axis]) as usize).min(self.bins - 1)
    }
}

/// Per-bin accumulators, `[axis][bin]`: count, box of the object spheres, the descriptor
/// sums, and the sums of squared norms `|s|^2`, `|t|^2` (for the dispersion by prefix sums).
struct Bins {
    bins: usize,
    count: Vec<usize>,
    aabb: Vec<Aabb>,
    square: Vec<[f64; 2]>,
    shape: Vec<f64>,
    texture: Vec<f64>,
}

impl Bins {
    fn new(bins: usize) -> Self {
        let cells = 3 * bins;
        Self {
            bins,
            count: vec![0; cells],
            aabb: vec![Aabb::EMPTY; cells],
            square: vec![[0.0; 2]; cells],
            shape: vec![0.0; cells * SHAPE_LEN],
            texture: vec![0.0; cells * TEXTURE_LEN],
        }
    }

    fn add_objects(&mut self, objects: &Objects, ids: &[u32], grid: &BinGrid) {
        for &o in ids {
            let sphere = objects.sphere[o as usize];
            let shape = objects.shape(o);
            let texture = objects.texture(o);
            let square = [squared_norm(shape), squared_norm(texture)];
            let aabb = Aabb::of_sphere(sphere);
            for axis in 0..3 {
                let cell = axis * self.bins + grid.bin(axis, sphere.centre);
                self.count[cell] += 1;
                self.aabb[cell] = self.aabb[cell].union(aabb);
                self.square[cell][0] += square[0];
                self.square[cell][1] += square[1];
                add_widened(
                    &mut self.shape[cell * SHAPE_LEN..(cell + 1) * SHAPE_LEN],
                    shape,
                );
                add_widened(
                    &mut self.texture[cell * TEXTURE_LEN..(cell + 1) * TEXTURE_LEN],
                    texture,
                );
            }
        }
    }

    fn merge(&mut self, other: &Self) {
        for cell in 0..self.count.len() {
            self.count[cell] += other.count[cell];
            self.aabb[cell] = self.aabb[cell].union(other.aabb[cell]);
            self.square[cell][0] += other.square[cell][0];
            self.square[cell][1] += other.square[cell][1];
        }
        add_sums(&mut self.shape, &other.shape);
        add_sums(&mut self.texture, &other.texture);
    }
}

/// `(1 - w) / shape_scale^2` and `w / texture_scale^2`: eq. 1's weights on squared distances.
struct DispersionWeights {
    shape: f64,
    texture: f64,
}

impl DispersionWeights {
    fn new(opts: &BvhOptions) -> Self {
        let w = f64::from(opts.w);
        Self {
            shape: (1.0 - w) / f64::from(opts.shape_scale).powi(2),
            texture: w / f64::from(opts.texture_scale).powi(2),
        }
    }
}

/// One side of a candidate plane, accumulated bin by bin.
struct Side {
    count: usize,
    aabb: Aabb,
    square: [f64; 2],
    shape: [f64; SHAPE_LEN],
    texture: [f64; TEXTURE_LEN],
}

impl Side {
    fn empty() -> Self {
        Self {
            count: 0,
            aabb: Aabb::EMPTY,
            square: [0.0; 2],
            shape: [0.0; SHAPE_LEN],
            texture: [0.0; TEXTURE_LEN],
        }
    }

    fn of_bins(bins: &Bins, axis: usize, range: Range<usize>) -> Self {
        let mut side = Self::empty();
        for bin in range {
            side.add_bin(bins, axis * bins.bins + bin);
        }
        side
    }

    fn add_bin(&mut self, bins: &Bins, cell: usize) {
        self.count += bins.count[cell];
        self.aabb = self.aabb.union(bins.aabb[cell]);
        self.square[0] += bins.square[cell][0];
        self.square[1] += bins.square[cell][1];
        add_sums(
            &mut self.shape,
            &bins.shape[cell * SHAPE_LEN..(cell + 1) * SHAPE_LEN],
        );
        add_sums(
            &mut self.texture,
            &bins.texture[cell * TEXTURE_LEN..(cell + 1) * TEXTURE_LEN],
        );
    }

    /// Weighted sum of squared distances to the side's centroid,
    /// `sum |x|^2 - |sum x|^2 / n` per descriptor (clamped at 0 against rounding).
    fn dispersion(&self, weights: &DispersionWeights) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let inv = 1.0 / self.count as f64;
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        let shape = (self.square[0] - norm(&self.shape) * inv).max(0.0);
        let texture = (self.square[1] - norm(&self.texture) * inv).max(0.0);
        weights.shape * shape + weights.texture * texture
    }

    /// Weighted second moment `sum |x|^2`: the scale of the dispersion's rounding error.
    fn moment(&self, weights: &DispersionWeights) -> f64 {
        weights.shape * self.square[0] + weights.texture * self.square[1]
    }

    /// The SAH term `n * A`.
    fn area(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        self.count as f64 * f64::from(self.aabb.surface_area())
    }
}

/// `|v|^2` in f64, in four independent lanes so that it vectorises.
fn squared_norm(v: &[f32]) -> f64 {
    let mut acc = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for lane in 0..4 {
            acc[lane] += f64::from(c[lane]) * f64::from(c[lane]);
        }
    }
    let tail: f64 = rest.iter().map(|&x| f64::from(x) * f64::from(x)).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Moves the ids for which `left` holds to the front; returns how many there are.
fn partition_in_place(ids: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let (mut i, mut j) = (0, ids.len());
    while i < j {
        if left(ids[i]) {
            i += 1;
        } else {
            j -= 1;
            ids.swap(i, j);
        }
    }
    i
}
