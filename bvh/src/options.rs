//! Options of the similarity-aware BVH: branching, eq. 1's weights and scales, bulk-build and
//! move policies (core paper section 4).

use serde::{Deserialize, Serialize};

use crate::BvhError;

/// The largest branching factor. Per-node scratch (eq. 1 costs of the children, split
/// groups) lives in fixed arrays of this size on the stack, so an insert never allocates.
pub const MAX_BRANCHING: usize = 64;

/// Eq. 1's default mu, the weight of similarity against volume: the paper's choice from its
/// Figures 5 and 6.
pub const DEFAULT_MU: f32 = 0.8;

/// Eq. 1's default w, the weight of texture against shape: the paper's choice.
pub const DEFAULT_W: f32 = 0.2;

/// How the tree is shaped and how eq. 1 weighs similarity against volume.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BvhOptions {
    /// Largest number of children of a node (internal nodes: nodes, leaves: objects). The
    /// paper's Sirikata tree uses 10. At least 2 and at most [`MAX_BRANCHING`].
    pub max_children: usize,
    /// Smallest number of children of every node but the root. A split leaves at least this
    /// many in each half; a node that falls below it on a remove is dissolved and its objects
    /// reinserted. Default: 40% of `max_children` rounded down (4 of 10), the R*-tree's
    /// recommended fill (Beckmann et al. 1990). At least 1, and `2 * min_children` may not
    /// exceed `leaf_size` (nor, therefore, `max_children`).
    pub min_children: usize,
    /// Eq. 1's mu: the weight of descriptor similarity against volume growth, in [0, 1].
    /// Default [`DEFAULT_MU`]. At 1 the tree groups by descriptors only; at 0 it is a plain
    /// R-tree.
    pub mu: f32,
    /// Eq. 1's w: the weight of texture against shape within the similarity term, in [0, 1].
    /// Default [`DEFAULT_W`].
    pub w: f32,
    /// The shape (Zernike L2) distance that counts as one unit in eq. 1. Default 0.5: the
    /// coarsest `z_diff` of the paper's Table 1, the largest shape difference still
    /// deduplicated at the smallest on-screen size, so one unit means "distinguishable even
    /// when tiny". Set it from data, e.g. the median distance between distinct models.
    pub shape_scale: f32,
    /// The texture (CSD L1) distance that counts as one unit in eq. 1. Default 500: Table 1's
    /// coarsest `t_diff`, for the same reason as `shape_scale`.
    pub texture_scale: f32,
    /// Objects per leaf that the bulk build aims for: leaves get at most this many, leaving
    /// `max_children - leaf_size` free slots so that later inserts do not split at once.
    /// Default 8 of 10. Between `2 * min_children` and `max_children`.
    pub leaf_size: usize,
    /// Candidate planes per axis in the bulk build: the objects' centres are binned into this
    /// many equal slabs per axis and every slab boundary is tried. Default 16, as in binned
    /// SAH builders; at least 2.
    pub bulk_bins: usize,
}

impl Default for BvhOptions {
    fn default() -> Self {
        Self::with_branching(10)
    }
}

impl BvhOptions {
    /// Defaults for a branching factor `max_children`: min fill 40% (at least 1), leaf size
    /// 80% (at least twice the min fill, at most the branching factor), [`DEFAULT_MU`],
    /// [`DEFAULT_W`].
    pub fn with_branching(max_children: usize) -> Self {
        // 40% min fill, but never so high that a bulk-built leaf cannot hold two minimum
        // groups (leaf_size >= 2 * min_children, see `bulk.rs`).
        // (For every branching factor 2..=64 this leaf size stays within max_children.)
        let min_children = (max_children * 2 / 5).max(1);
        let leaf_size = (max_children * 4).div_ceil(5).max(2 * min_children);
        Self {
            max_children,
            min_children,
            mu: DEFAULT_MU,
            w: DEFAULT_W,
            shape_scale: 0.5,
            texture_scale: 500.0,
            leaf_size: leaf_size.min(max_children),
            bulk_bins: 16,
        }
    }

    /// These options with eq. 1's weights replaced.
    #[must_use]
    pub fn with_weights(mut self, mu: f32, w: f32) -> Self {
        self.mu = mu;
        self.w = w;
        self
    }

    /// Checks every documented constraint.
    pub fn validate(&self) -> Result<(), BvhError> {
        let bad = |msg: String| Err(BvhError::BadOptions(msg));
        if !(2..=MAX_BRANCHING).contains(&self.max_children) {
            return bad(format!(
                "max_children {} is not in 2..={MAX_BRANCHING}",
                self.max_children
            ));
        }
        if self.min_children < 1 || 2 * self.min_children > self.leaf_size {
            return bad(format!(
                "min_children {} must be at least 1 and at most leaf_size / 2 ({})",
                self.min_children,
                self.leaf_size / 2
            ));
        }
        if self.leaf_size > self.max_children {
            return bad(format!(
                "leaf_size {} exceeds max_children {}",
                self.leaf_size, self.max_children
            ));
        }
        if !(0.0..=1.0).contains(&self.mu) || !(0.0..=1.0).contains(&self.w) {
            return bad(format!(
                "mu {} and w {} must lie in [0, 1]",
                self.mu, self.w
            ));
        }
        let positive = |x: f32| x.is_finite() && x > 0.0;
        if !positive(self.shape_scale) || !positive(self.texture_scale) {
            return bad(format!(
                "shape_scale {} and texture_scale {} must be finite and positive",
                self.shape_scale, self.texture_scale
            ));
        }
        if self.bulk_bins < 2 {
            return bad(format!("bulk_bins {} is below 2", self.bulk_bins));
        }
        Ok(())
    }
}
