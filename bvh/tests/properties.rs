//! Property tests of the BVH's promises (house style 8): after any sequence of inserts,
//! removes, moves and rebuilds every invariant holds and every object is held exactly once;
//! every cut covers every object exactly once within its budget (the complete-view
//! invariant); eq. 1 with mu = 1 groups same-descriptor objects more purely than mu = 0.

mod common;

use std::collections::{HashMap, HashSet};

use common::{check_cut, insert_all, leaf_purity, noisy_object, object, Obj, Rng};
use glam::{Affine3A, Vec3};
use horizon_bvh::{Bvh, BvhOptions, CutQuery, ObjectId, Sphere};
use proptest::collection::vec;
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Op {
    Insert { at: Vec3, radius: f32, class: u32 },
    Remove { pick: usize },
    Move { pick: usize, by: Vec3, radius: f32 },
    Rebuild,
}

fn point(extent: f32) -> impl Strategy<Value = Vec3> {
    (0.0..extent, 0.0..extent, 0.0..extent / 20.0).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        8 => (point(200.0), 0.1f32..8.0, 0u32..4)
            .prop_map(|(at, radius, class)| Op::Insert { at, radius, class }),
        3 => any::<usize>().prop_map(|pick| Op::Remove { pick }),
        3 => (any::<usize>(), point(100.0), 0.1f32..8.0).prop_map(|(pick, by, radius)| Op::Move {
            pick,
            by: by - Vec3::new(50.0, 50.0, 2.5),
            radius,
        }),
        1 => Just(Op::Rebuild),
    ]
}

fn weights() -> impl Strategy<Value = f32> {
    prop_oneof![Just(0.0f32), Just(0.8f32), Just(1.0f32), 0.0f32..=1.0]
}

/// proptest's default of 256 cases per property in release builds, a quarter of that in
/// unoptimised debug builds (where the tree also validates itself after every operation);
/// PROPTEST_CASES overrides both.
fn config() -> ProptestConfig {
    let mut config = ProptestConfig::default();
    if cfg!(debug_assertions) && std::env::var_os("PROPTEST_CASES").is_none() {
        config.cases /= 4;
    }
    config
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn any_operation_sequence_keeps_every_invariant(
        branching in 2usize..=12,
        mu in weights(),
        seed in any::<u64>(),
        ops in vec(op(), 1..160),
    ) {
        let options = BvhOptions::with_branching(branching).with_weights(mu, 0.2);
        let mut bvh = Bvh::new(options).expect("valid options");
        let mut rng = Rng::new(seed);
        // The model: what each live object's sphere should be.
        let mut live: Vec<(ObjectId, Sphere)> = Vec::new();
        for op in ops {
            match op {
                Op::Insert { at, radius, class } => {
                    let o = noisy_object(&mut rng, at, radius, class);
                    let id = bvh.insert(&o.as_new()).expect("valid object");
                    prop_assert!(live.iter().all(|(l, _)| *l != id), "id {id:?} reused while live");
                    live.push((id, o.sphere));
                }
                Op::Remove { pick } if !live.is_empty() => {
                    let (id, _) = live.swap_remove(pick % live.len());
                    bvh.remove(id).expect("live object");
                    prop_assert!(bvh.object(id).is_none());
                }
                Op::Move { pick, by, radius } if !live.is_empty() => {
                    let i = pick % live.len();
                    let sphere = Sphere::new(live[i].1.centre + by, radius);
                    bvh.move_object(live[i].0, Affine3A::from_translation(sphere.centre), sphere)
                        .expect("valid move");
                    live[i].1 = sphere;
                }
                Op::Rebuild => bvh.rebuild(),
                _ => {}
            }
            if let Err(e) = bvh.validate() {
                prop_assert!(false, "{e}");
            }
        }
        // Every object is held exactly once (validate), and they are exactly the model's.
        prop_assert_eq!(bvh.len(), live.len());
        let ids: HashSet<ObjectId> = bvh.object_ids().collect();
        prop_assert_eq!(ids, live.iter().map(|(id, _)| *id).collect::<HashSet<_>>());
        for (id, sphere) in &live {
            prop_assert_eq!(bvh.object(*id).expect("live").sphere(), *sphere);
        }
    }

    #[test]
    fn cuts_cover_every_object_once_within_budget(
        seed in any::<u64>(),
        n in 0usize..500,
        bulk in any::<bool>(),
        branching in 2usize..=12,
        queries in vec((point(300.0), -7.0f32..1.5, 0usize..300), 1..8),
    ) {
        let mut rng = Rng::new(seed);
        let objects: Vec<Obj> = (0..n)
            .map(|_| {
                let at = Vec3::new(rng.range(0.0, 250.0), rng.range(0.0, 250.0), rng.range(0.0, 10.0));
                let (radius, class) = (rng.range(0.1, 10.0), rng.below(4) as u32);
                noisy_object(&mut rng, at, radius, class)
            })
            .collect();
        let options = BvhOptions::with_branching(branching);
        let bvh = if bulk {
            let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
            Bvh::bulk_build(options, &new).expect("valid objects")
        } else {
            let mut bvh = Bvh::new(options).expect("valid options");
            insert_all(&mut bvh, &objects);
            bvh
        };
        if let Err(e) = bvh.validate() {
            prop_assert!(false, "{e}");
        }
        for (position, log_omega, max_results) in queries {
            // Omega_min from 1e-7 sr (nearly everything refines) to 30 sr (more than 4 pi:
            // nothing does).
            let q = CutQuery { position, min_solid_angle: 10f32.powf(log_omega), max_results };
            let cut = bvh.cut(&q);
            check_cut(&bvh, &cut, &q);
            prop_assert!(cut.nodes_visited <= bvh.node_count());
        }
    }

    #[test]
    fn mu_one_groups_classes_more_purely_than_mu_zero(
        seed in any::<u64>(),
        side in 8usize..18,
    ) {
        // A checkerboard of two classes 10 m apart, inserted in a random order: neighbours
        // are always of the other class, so proximity alone (mu = 0) mixes them in every
        // leaf, while descriptors alone (mu = 1) can keep each leaf to one class.
        let mut objects: Vec<Obj> = (0..side * side)
            .map(|i| {
                let (x, y) = (i % side, i / side);
                let class = ((x + y) % 2) as u32 * 4;
                object(Vec3::new(x as f32, y as f32, 0.0) * 10.0, 1.0, class)
            })
            .collect();
        Rng::new(seed).shuffle(&mut objects);
        let purity = |mu: f32| {
            let mut bvh = Bvh::new(BvhOptions::default().with_weights(mu, 0.2)).expect("valid");
            let ids = insert_all(&mut bvh, &objects);
            bvh.validate().expect("valid tree");
            let class_of: HashMap<ObjectId, u32> =
                ids.iter().zip(&objects).map(|(&id, o)| (id, o.model as u32)).collect();
            leaf_purity(&bvh, &class_of)
        };
        let (similar, spatial) = (purity(1.0), purity(0.0));
        prop_assert!(similar > spatial, "purity mu=1 {similar} <= mu=0 {spatial}");
    }
}
