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
    // Each representative with the norm of its shape descriptor, for `could_match`.
    let mut representatives: Vec<(&ModelUse, f32)> = Vec::new();
    let mut out = BTreeMap::new();
    for u in order {
        let omega = solid_angle(f64::from(u.radius), distance);
        // The largest shape difference any match can have: the row's, or 0 (an exact match) when
        // the model is too large for every row.
        let z_cap = table.thresholds(omega).map_or(0.0, |(z, _)| z);
        let norm = norm(u.shape);
        let found = representatives.iter().find_map(|&(r, r_norm)| {
            if !could_match(norm, r_norm, z_cap) {
                return None;
            }
            let z = zernike_distance(u.shape, r.shape);
            if z > z_cap {
                return None;
            }
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
            None => representatives.push((u, norm)),
        }
    }
    out
}

/// The Euclidean norm of a descriptor.
fn norm(v: &[f32]) -> f32 {
    v.iter().map(|x| x * x).sum::<f32>().sqrt()
}

/// Whether two descriptors of these norms can be within `z_cap` of each other: by the
/// triangle inequality their distance is at least the difference of their norms. The margin
/// covers the rounding of the norms and of `zernike_distance` (a few float ulps on 121
/// terms), so no pair `zernike_distance` would accept is ever skipped; it only spares
/// computing the distance of pairs whose norms alone rule them out, which is nearly all: the
/// calibrated z_diff thresholds are hundreds of times smaller than descriptor norms.
fn could_match(a: f32, b: f32, z_cap: f32) -> bool {
    (a - b).abs() <= z_cap + 1e-4 * a.max(b) + 1e-6
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The plan without the norm bound: every representative's distances computed.
    fn brute_force(uses: &[ModelUse], distance: f64, table: &Table1) -> BTreeMap<u64, Replacement> {
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

    fn frame() -> PcaFrame {
        PcaFrame::of(&crate::pca::tests::lump()).expect("a solid has a frame")
    }

    /// Descriptors in a few clusters: a base shape each, moved by up to `spread` per
    /// component, so that some pairs fall within Table 1's thresholds and some just outside.
    fn descriptors(seed: u64, count: usize, spread: f32) -> Vec<(Vec<f32>, Vec<f32>, f32)> {
        let mut rng = uniform(seed);
        let bases: Vec<(Vec<f32>, Vec<f32>)> = (0..4)
            .map(|_| {
                let shape = (0..121).map(|_| rng() * 0.2).collect();
                let texture = (0..32).map(|_| (rng() * 8.0).floor()).collect();
                (shape, texture)
            })
            .collect();
        (0..count)
            .map(|i| {
                let (shape, texture) = &bases[i % bases.len()];
                let shape = shape.iter().map(|x| x + (rng() - 0.5) * spread).collect();
                let mut texture = texture.clone();
                if spread > 0.0 {
                    // A texture within 0, 1 or 2 of its cluster's (Table 1's t_diff is 1 to 256).
                    for _ in 0..2 {
                        let bin = (rng() * 32.0) as usize % 32;
                        texture[bin] += (rng() * 2.0).floor();
                    }
                }
                (shape, texture, 0.5 + 20.0 * rng())
            })
            .collect()
    }

    /// Uniform values in [0, 1) from the workspace's seeded generator.
    fn uniform(seed: u64) -> impl FnMut() -> f32 {
        let mut rng = horizon_mesh::rng::Rng::new(seed);
        move || rng.unit()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// The norm bound only skips pairs the thresholds would refuse: the plan is the
        /// brute-force one, replacement for replacement.
        #[test]
        fn the_norm_bound_never_changes_the_plan(
            seed in any::<u64>(),
            count in 1usize..60,
            spread in prop::sample::select(vec![0.0f32, 1e-5, 1e-4, 3e-4, 1e-3]),
            distance in prop::sample::select(vec![30.0f64, 300.0, 3000.0]),
        ) {
            let frame = frame();
            let data = descriptors(seed, count, spread);
            let uses: Vec<ModelUse> = data
                .iter()
                .enumerate()
                .map(|(i, (shape, texture, radius))| ModelUse {
                    model: i as u64,
                    shape,
                    texture,
                    radius: *radius,
                    placements: 1 + i % 3,
                    frame: Some(&frame),
                })
                .collect();
            let table = Table1::calibrated();
            let fast = plan(&uses, distance, &table);
            let slow = brute_force(&uses, distance, &table);
            prop_assert_eq!(&fast, &slow);
            if spread == 0.0 && count > 4 {
                // Identical copies always merge.
                prop_assert!(!fast.is_empty());
            }
        }
    }
}
