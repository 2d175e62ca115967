//! Near-duplicate dedup inside one aggregate (core paper section 5.1, Table 1, eqs. 2 and 3;
//! `DESIGN.md`, "Dedup thresholds").
//!
//! At the dedup distance (where the aggregate subtends the largest queryable solid angle),
//! each model's largest placement subtends some solid angle; that selects a row of the
//! calibrated Table 1, whose `z_diff` (Zernike, L2) and `t_diff` (CSD, L1) bound how
//! different a replacement may be. Models are visited by decreasing use (most placements
//! first, then by number): each either matches an earlier representative within its
//! thresholds and is replaced by it, or becomes a representative itself. A replacement is
//! placed by PCA alignment (`pca.rs`); beyond the paper, a match whose best alignment still
//! leaves the surfaces more than [`MAX_ALIGN_SCORE`] RMS radii apart is refused, so a
//! symmetric model whose axes are ambiguous is never put in crooked.

use std::collections::BTreeMap;

use glam::Affine3A;
use horizon_descriptors::calibrate::Table1;
use horizon_descriptors::{csd_distance, zernike_distance};

use crate::budget::solid_angle;
use crate::pca::PcaFrame;

/// Largest accepted alignment score (mean surface distance over the RMS radius).
pub const MAX_ALIGN_SCORE: f32 = 0.1;

/// One model as used inside an aggregate.
#[derive(Clone, Copy, Debug)]
pub struct ModelUse<'a> {
    /// The BVH's model number.
    pub model: u64,
    /// 3D Zernike descriptor.
    pub shape: &'a [f32],
    /// Color Structure Descriptor.
    pub texture: &'a [f32],
    /// World radius of its largest placement in the aggregate.
    pub radius: f32,
    /// Its number of placements in the aggregate.
    pub placements: usize,
    /// Its principal frame, `None` for a model without area (never replaced or used).
    pub frame: Option<&'a PcaFrame>,
}

/// A model replaced by another.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Replacement {
    /// The model drawn instead.
    pub by: u64,
    /// Maps the replacement's model space onto the replaced model's model space.
    pub align: Affine3A,
}

/// Which models of `uses` are replaced, and by what, for an aggregate whose dedup distance
/// is `distance`.
pub fn plan(uses: &[ModelUse], distance: f64, table: &Table1) -> BTreeMap<u64, Replacement> {
    let mut order: Vec<&ModelUse> = uses.iter().filter(|u| u.frame.is_some()).collect();
    order.sort_by(|a, b| b.placements.cmp(&a.placements).then(a.model.cmp(&b.model)));
    let mut representatives: Vec<&ModelUse> = Vec::new();
    let mut out = BTreeMap::new();
    for u in order {
        let omega = solid_angle(f64::from(u.radius), distance);
        let found = representatives.iter().find_map(|r| {
            let z = zernike_distance(u.shape, r.shape);
            let t = csd_distance(u.texture, r.texture);
            let exact = z == 0.0 && t == 0.0;
            if !(exact || table.allows(omega, z, t)) {
                return None;
            }
            let (align, score) = u.frame?.align(r.frame?);
            (score <= MAX_ALIGN_SCORE).then_some(Replacement { by: r.model, align })
        });
        match found {
            Some(rep) => {
                out.insert(u.model, rep);
            }
            None => representatives.push(u),
        }
    }
    out
}
