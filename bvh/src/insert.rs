//! Incremental insertion by the core paper's eq. 1 (Azim et al. 2014, section 4.2).
//!
//! From the root, descend into the child minimising
//! `mu * [(1 - w) |S - Cs| / shape_scale + w |T - Ct| / texture_scale] +
//! (1 - mu) * (Vc - Vold) / Vmax`,
//! where `S`, `T` are the object's shape (L2) and texture (L1) descriptors, `Cs`, `Ct` the
//! child's descriptor centroids, `Vc` and `Vold` the volumes of the child's box with and
//! without the object, and `Vmax` the largest `Vc` among the children. Volumes are those of
//! the axis-aligned boxes of the object spheres (the R-tree's measure; a sphere always has a
//! box of positive volume, so flat worlds do not degenerate). The paper's typeset eq. 1 puts
//! both descriptor differences inside one norm; `DESIGN.md` spells out the two distances and
//! their normalisation, which is what is implemented.

use crate::bounds::Aabb;
use crate::options::MAX_BRANCHING;
use crate::tree::{Bvh, NewObject, NodeKind, ObjectId, NONE};
use crate::{BvhError, BvhOptions};

impl Bvh {
    /// Adds an object, descending by eq. 1 and splitting what overflows. O(height * branching *
    /// descriptor length). The tree is unchanged when an error is returned.
    pub fn insert(&mut self, object: &NewObject<'_>) -> Result<ObjectId, BvhError> {
        self.touch();
        // Refuse bad input before anything changes.
        object.check()?;
        // Store the object, then place it in the hierarchy.
        let o = self.objects.alloc(object)?;
        self.place(o);
        self.debug_validate();
        Ok(ObjectId(o))
    }

    /// Puts a stored, unplaced object into the leaf eq. 1 chooses, updating the path's totals
    /// and bounds and splitting overflowing nodes.
    pub(crate) fn place(&mut self, o: u32) {
        // Descend by eq. 1.
        let leaf = self.choose_leaf(o);
        // Add it to the running totals of the path and to the leaf.
        self.add_object_totals(leaf, o);
        self.push_kid(leaf, o);
        self.objects.leaf[o as usize] = leaf;
        self.grow_leaf(leaf, o);
        // Split what overflows and refit the bounds up to the root.
        self.split_and_refit_upward(leaf);
    }

    /// The leaf eq. 1 leads `o` to.
    fn choose_leaf(&self, o: u32) -> u32 {
        let mut n = self.root;
        while self.nodes[n as usize].kind == NodeKind::Internal {
            n = self.choose_child(n, o);
        }
        n
    }

    /// The child of internal node `n` minimising eq. 1 for object `o`. Ties go to the smaller
    /// volume growth, then to the smaller child.
    fn choose_child(&self, n: u32, o: u32) -> u32 {
        let opts = &self.options;
        let kids = self.kids(n);
        let object_box = Aabb::of_sphere(self.objects.sphere[o as usize]);
        // Volume terms: growth of each child's box, normalised by the largest grown volume.
        let mut growth = [0.0f32; MAX_BRANCHING + 1];
        let mut old = [0.0f32; MAX_BRANCHING + 1];
        let mut v_max = 0.0f32;
        for (i, &c) in kids.iter().enumerate() {
            let aabb = self.nodes[c as usize].aabb;
            let v_old = aabb.volume();
            let v_c = aabb.union(object_box).volume();
            v_max = v_max.max(v_c);
            growth[i] = v_c - v_old;
            old[i] = v_old;
        }
        let inv_v_max = if v_max > 0.0 { 1.0 / v_max } else { 0.0 };
        // Eq. 1 per child; the descriptor term is skipped when mu = 0.
        let shape = self.objects.shape(o);
        let texture = self.objects.texture(o);
        let mut best = (f32::INFINITY, f32::INFINITY, f32::INFINITY, NONE);
        for (i, &c) in kids.iter().enumerate() {
            let similarity = if opts.mu > 0.0 {
                descriptor_distance(
                    opts,
                    shape,
                    texture,
                    self.shape_sum(c),
                    self.texture_sum(c),
                    self.nodes[c as usize].count,
                )
            } else {
                0.0
            };
            let volume = growth[i] * inv_v_max;
            let cost = opts.mu * similarity + (1.0 - opts.mu) * volume;
            let key = (cost, growth[i], old[i], c);
            if key < best {
                best = key;
            }
        }
        best.3
    }

    /// Grows a leaf's bounds to take in its newly added last object: O(1), the smallest
    /// sphere holding the old bound and the new centre.
    fn grow_leaf(&mut self, leaf: u32, o: u32) {
        let sphere = self.objects.sphere[o as usize];
        let node = &mut self.nodes[leaf as usize];
        if node.len == 1 {
            node.centre = sphere.centre;
            node.radius = 0.0;
            node.r_max = sphere.radius;
            node.aabb = Aabb::of_sphere(sphere);
            return;
        }
        let offset = sphere.centre - node.centre;
        let d = offset.length();
        if d > node.radius {
            let radius = 0.5 * (node.radius + d);
            node.centre += offset * ((radius - node.radius) / d);
            // Rounding may leave the new centre a hair outside; cover it exactly.
            node.radius = radius.max((sphere.centre - node.centre).length());
        }
        node.r_max = node.r_max.max(sphere.radius);
        node.aabb = node.aabb.union(Aabb::of_sphere(sphere));
    }

    /// Walks from `n` to the root, splitting overflowing nodes and refitting internal nodes'
    /// bounds from their children (the children's records were just read by the descent, so
    /// this touches warm memory).
    pub(crate) fn split_and_refit_upward(&mut self, mut n: u32) {
        loop {
            if self.nodes[n as usize].len as usize > self.options.max_children {
                self.split(n);
            } else if self.nodes[n as usize].kind == NodeKind::Internal {
                self.refit(n);
            }
            let parent = self.nodes[n as usize].parent;
            if parent == NONE {
                break;
            }
            n = parent;
        }
    }
}

/// Eq. 1's similarity term between a descriptor pair (`shape`, `texture`) and the centroid
/// (`shape_sum / count`, `texture_sum / count`):
/// `(1 - w) |S - Cs|_2 / shape_scale + w |T - Ct|_1 / texture_scale`.
#[inline]
pub(crate) fn descriptor_distance(
    opts: &BvhOptions,
    shape: &[f32],
    texture: &[f32],
    shape_sum: &[f32],
    texture_sum: &[f32],
    count: u32,
) -> f32 {
    let inv = 1.0 / count.max(1) as f32;
    let l2 = lanes(shape, shape_sum, |x, s| {
        let d = x - s * inv;
        d * d
    });
    let l1 = lanes(texture, texture_sum, |x, s| (x - s * inv).abs());
    (1.0 - opts.w) * l2.sqrt() / opts.shape_scale + opts.w * l1 / opts.texture_scale
}

/// `sum_i term(a_i, b_i)` accumulated in eight independent lanes, so that the compiler can
/// vectorise it (a single running sum fixes the order of the additions and stays scalar).
#[inline]
fn lanes(a: &[f32], b: &[f32], term: impl Fn(f32, f32) -> f32) -> f32 {
    const LANES: usize = 8;
    let mut acc = [0.0f32; LANES];
    let (a8, b8) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (a_rest, b_rest) = (a8.remainder(), b8.remainder());
    for (x, s) in a8.zip(b8) {
        for lane in 0..LANES {
            acc[lane] += term(x[lane], s[lane]);
        }
    }
    let mut total: f32 = acc.iter().sum();
    for (&x, &s) in a_rest.iter().zip(b_rest) {
        total += term(x, s);
    }
    total
}
