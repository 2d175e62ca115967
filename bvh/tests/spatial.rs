//! The spatial baseline (an `obvhs` SAH BVH with max-sphere bounds): its cut keeps the
//! complete-view invariant and the budget, and shows as themselves the same objects as the
//! similarity-aware tree's cut whenever the budget does not bind.
#![cfg(feature = "baseline")]

mod common;

use std::collections::HashSet;

use common::{object, Obj, Rng};
use glam::Vec3;
use horizon_bvh::{
    solid_angle, Bvh, BvhOptions, CutItem, CutQuery, ObjectId, SpatialBaseline, SpatialItem,
};
use proptest::prelude::*;

fn world(seed: u64, n: usize) -> Vec<Obj> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let at = Vec3::new(
                rng.range(0.0, 300.0),
                rng.range(0.0, 300.0),
                rng.range(0.0, 5.0),
            );
            object(at, rng.range(0.1, 4.0), rng.below(4) as u32)
        })
        .collect()
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: if cfg!(debug_assertions) { 24 } else { 128 },
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn spatial_cut_covers_everything_once_and_agrees_on_objects(
        seed in any::<u64>(),
        n in 1usize..400,
        log_omega in -4.0f32..-0.5,
        max_results in prop_oneof![1usize..60, Just(1_000_000usize)],
        at in (0.0f32..300.0, 0.0f32..300.0),
    ) {
        let objects = world(seed, n);
        let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
        let bvh = Bvh::bulk_build(BvhOptions::default(), &new).expect("valid");
        let baseline = SpatialBaseline::build(&bvh);
        prop_assert_eq!(baseline.len(), n);
        let query = CutQuery {
            position: Vec3::new(at.0, at.1, 1.7),
            min_solid_angle: 10f32.powf(log_omega),
            max_results,
        };
        let cut = baseline.cut(&query);
        prop_assert!(cut.entries.len() <= max_results.max(1));
        let mut covered = HashSet::new();
        let mut shown = HashSet::new();
        for e in &cut.entries {
            match e.item {
                SpatialItem::Object(o) => {
                    prop_assert!(covered.insert(o));
                    shown.insert(o);
                }
                SpatialItem::Node(nd) => {
                    let mut under = Vec::new();
                    baseline.objects_under(nd, &mut under);
                    prop_assert_eq!(under.len() as u32, e.covers);
                    for o in under {
                        prop_assert!(covered.insert(o));
                    }
                }
            }
        }
        prop_assert_eq!(covered.len(), n);
        if max_results == 1_000_000 {
            // Every object subtending at least Omega_min is shown as itself in both trees
            // (no bound can hide it), and both cuts show the same such objects.
            let big: HashSet<ObjectId> = bvh
                .object_ids()
                .filter(|&o| {
                    let s = bvh.object(o).expect("live").sphere();
                    solid_angle(s.radius, (query.position - s.centre).length())
                        >= query.min_solid_angle
                })
                .collect();
            prop_assert!(big.is_subset(&shown));
            let similarity: HashSet<ObjectId> = bvh
                .cut(&query)
                .entries
                .iter()
                .filter_map(|e| match e.item {
                    CutItem::Object(o) => Some(o),
                    CutItem::Aggregate(_) => None,
                })
                .collect();
            prop_assert!(big.is_subset(&similarity));
        }
    }
}

#[test]
fn empty_world_has_an_empty_spatial_cut() {
    let bvh = Bvh::new(BvhOptions::default()).expect("valid");
    let baseline = SpatialBaseline::build(&bvh);
    assert!(baseline.is_empty());
    let cut = baseline.cut(&CutQuery {
        position: Vec3::ZERO,
        min_solid_angle: 1e-3,
        max_results: 10,
    });
    assert!(cut.entries.is_empty());
}
