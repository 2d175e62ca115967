//! Insert (eq. 1), split (section 4.2), remove and move, bulk rebuild (section 4.3) and
//! snapshots, on small hand-built inputs.

mod common;

use std::collections::HashMap;

use common::{class_descriptors, insert_all, leaf_purity, noisy_object, object, Obj, Rng};
use glam::{Affine3A, Vec3};
use horizon_bvh::{Bvh, BvhError, BvhOptions, CutQuery, NewObject, ObjectId, Sphere, SHAPE_LEN};

fn grid(n: usize, spacing: f32, classes: u32) -> Vec<Obj> {
    let side = (n as f32).sqrt().ceil() as usize;
    (0..n)
        .map(|i| {
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            object(Vec3::new(x, y, 0.0) * spacing, 1.0, (i as u32) % classes)
        })
        .collect()
}

#[test]
fn insert_refuses_bad_input_and_leaves_the_tree_unchanged() {
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let good = object(Vec3::ZERO, 1.0, 0);
    bvh.insert(&good.as_new()).expect("valid");
    let short = vec![0.0f32; SHAPE_LEN - 1];
    let nan_shape = {
        let mut s = good.shape.clone();
        s[3] = f32::NAN;
        s
    };
    let cases: Vec<(NewObject<'_>, &str)> = vec![
        (
            NewObject {
                shape: &short,
                ..good.as_new()
            },
            "short shape",
        ),
        (
            NewObject {
                texture: &short,
                ..good.as_new()
            },
            "long texture",
        ),
        (
            NewObject {
                shape: &nan_shape,
                ..good.as_new()
            },
            "NaN shape",
        ),
        (
            NewObject {
                sphere: Sphere::new(Vec3::ZERO, -1.0),
                ..good.as_new()
            },
            "negative radius",
        ),
        (
            NewObject {
                sphere: Sphere::new(Vec3::new(f32::INFINITY, 0.0, 0.0), 1.0),
                ..good.as_new()
            },
            "infinite centre",
        ),
        (
            NewObject {
                transform: Affine3A::from_translation(Vec3::splat(f32::NAN)),
                ..good.as_new()
            },
            "NaN transform",
        ),
    ];
    for (bad, why) in cases {
        assert!(bvh.insert(&bad).is_err(), "{why} accepted");
    }
    assert_eq!(bvh.len(), 1);
    bvh.validate().expect("unchanged tree");
    // Unknown ids are refused too.
    assert_eq!(
        bvh.remove(ObjectId(7)),
        Err(BvhError::UnknownObject(ObjectId(7)))
    );
    assert!(bvh
        .move_object(
            ObjectId(7),
            Affine3A::IDENTITY,
            Sphere::new(Vec3::ZERO, 1.0)
        )
        .is_err());
    // Bad options are refused.
    let options = BvhOptions {
        min_children: 6,
        ..BvhOptions::default()
    };
    assert!(Bvh::new(options).is_err(), "min fill above leaf_size / 2");
    assert!(Bvh::new(BvhOptions::default().with_weights(1.5, 0.2)).is_err());
}

#[test]
fn eleventh_insert_splits_the_root_leaf() {
    // Branching 10: ten objects fit in the root leaf, the eleventh splits it into two leaves
    // of at least min_children (4) each under a new root.
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let objects = grid(11, 5.0, 1);
    insert_all(&mut bvh, &objects[..10]);
    assert_eq!(bvh.height(), 0);
    insert_all(&mut bvh, &objects[10..]);
    bvh.validate().expect("valid tree");
    assert_eq!(bvh.height(), 1);
    let root = bvh.node(bvh.root()).expect("root");
    assert_eq!(root.len(), 2);
    for leaf in root.child_nodes() {
        assert!(bvh.node(leaf).expect("leaf").len() >= 4);
    }
}

#[test]
fn split_separates_coincident_objects_by_shape() {
    // Eleven objects at the same spot: every pair wastes the same volume, so the seeds are
    // the pair with the largest shape difference (one of each class), and eq. 1's descriptor
    // term (the volume term is 0 for identical boxes) sends each object to its own class.
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let objects: Vec<Obj> = (0..11)
        .map(|i| object(Vec3::ZERO, 1.0, if i % 2 == 0 { 0 } else { 3 }))
        .collect();
    let ids = insert_all(&mut bvh, &objects);
    bvh.validate().expect("valid tree");
    let class_of: HashMap<ObjectId, u32> = ids
        .iter()
        .zip(&objects)
        .map(|(&id, o)| (id, o.model as u32))
        .collect();
    assert_eq!(leaf_purity(&bvh, &class_of), 1.0);
}

#[test]
fn insertion_grows_a_balanced_tree() {
    // 2,000 random objects: every leaf stays at one depth and every node within its fill.
    let mut rng = Rng::new(7);
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let objects: Vec<Obj> = (0..2000)
        .map(|_| {
            let p = Vec3::new(rng.range(0.0, 1000.0), rng.range(0.0, 1000.0), 0.0);
            let class = rng.below(5) as u32;
            let r = rng.range(0.5, 5.0);
            noisy_object(&mut rng, p, r, class)
        })
        .collect();
    insert_all(&mut bvh, &objects);
    bvh.validate().expect("valid tree");
    assert_eq!(bvh.len(), 2000);
    assert!(bvh.height() >= 3, "2000 objects need at least 4 levels");
}

#[test]
fn removing_everything_condenses_to_an_empty_root() {
    let mut rng = Rng::new(11);
    let mut bvh = Bvh::new(BvhOptions::with_branching(4)).expect("valid options");
    let objects = grid(200, 3.0, 3);
    let mut ids = insert_all(&mut bvh, &objects);
    rng.shuffle(&mut ids);
    for (i, id) in ids.iter().enumerate() {
        bvh.remove(*id).expect("live object");
        if i % 17 == 0 {
            bvh.validate().expect("valid after remove");
        }
    }
    bvh.validate().expect("valid empty tree");
    assert!(bvh.is_empty());
    assert_eq!(bvh.height(), 0);
    assert_eq!(bvh.node_count(), 1);
    // Freed ids are reused.
    let id = bvh.insert(&objects[0].as_new()).expect("valid");
    assert!(ids.contains(&id));
}

#[test]
fn move_within_the_leaf_refits_and_far_move_reinserts() {
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let objects = grid(100, 10.0, 2);
    let ids = insert_all(&mut bvh, &objects);
    let id = ids[55];
    let leaf = bvh.object(id).expect("live").leaf();
    // Growing the radius in place keeps the leaf (the centre did not move) and raises r_max
    // on the whole path.
    let centre = bvh.object(id).expect("live").sphere().centre;
    bvh.move_object(
        id,
        Affine3A::from_translation(centre),
        Sphere::new(centre, 30.0),
    )
    .expect("valid move");
    bvh.validate().expect("valid after refit");
    assert_eq!(bvh.object(id).expect("live").leaf(), leaf);
    assert_eq!(bvh.node(bvh.root()).expect("root").r_max(), 30.0);
    // Moving 10 km away leaves every bound: the object is reinserted, keeping its id.
    let far = Vec3::new(10_000.0, 0.0, 0.0);
    bvh.move_object(id, Affine3A::from_translation(far), Sphere::new(far, 1.0))
        .expect("valid move");
    bvh.validate().expect("valid after reinsert");
    assert_eq!(bvh.object(id).expect("live").sphere().centre, far);
    assert_eq!(bvh.node(bvh.root()).expect("root").r_max(), 1.0);
    assert_eq!(bvh.len(), 100);
}

#[test]
fn bulk_build_respects_fill_limits_and_keeps_ids_on_rebuild() {
    for (n, branching) in [
        (0usize, 10usize),
        (1, 10),
        (10, 10),
        (11, 10),
        (1000, 10),
        (777, 4),
        (300, 2),
        (5000, 16),
    ] {
        let mut rng = Rng::new(n as u64);
        let objects: Vec<Obj> = (0..n)
            .map(|_| {
                let p = Vec3::new(
                    rng.range(0.0, 500.0),
                    rng.range(0.0, 500.0),
                    rng.range(0.0, 5.0),
                );
                let class = rng.below(4) as u32;
                noisy_object(&mut rng, p, 1.0, class)
            })
            .collect();
        let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
        let mut bvh = Bvh::bulk_build(BvhOptions::with_branching(branching), &new).expect("valid");
        bvh.validate().expect("valid bulk tree");
        assert_eq!(bvh.len(), n);
        // Object ids are the input order.
        for (i, o) in objects.iter().enumerate() {
            assert_eq!(
                bvh.object(ObjectId(i as u32)).expect("live").sphere(),
                o.sphere
            );
        }
        // Remove a few, rebuild: the survivors keep their ids.
        for i in (0..n).step_by(3) {
            bvh.remove(ObjectId(i as u32)).expect("live");
        }
        bvh.rebuild();
        bvh.validate().expect("valid rebuilt tree");
        for (i, o) in objects.iter().enumerate() {
            let live = bvh.object(ObjectId(i as u32));
            assert_eq!(live.is_some(), i % 3 != 0);
            if let Some(live) = live {
                assert_eq!(live.sphere(), o.sphere);
                assert_eq!(live.shape(), &o.shape[..]);
            }
        }
    }
}

#[test]
fn bulk_build_splits_by_descriptor_dispersion() {
    // 64 objects on a 16 x 4 grid, 40 m apart along x and 2 m along y; class 0 in the two
    // rows with y < 3 and class 5 in the other two. The class boundary runs along the long
    // axis, where no spatial rule would cut first. With mu = 1 (the paper's rule) the plane
    // y = 3 is the only one with zero dispersion on both sides, so it is chosen, and every
    // later plane cuts within one class: every leaf is pure.
    let mut objects = Vec::new();
    for i in 0..64 {
        let x = (i % 16) as f32 * 40.0;
        let y = (i / 16) as f32 * 2.0;
        objects.push(object(Vec3::new(x, y, 0.0), 1.0, u32::from(y >= 3.0) * 5));
    }
    let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
    let options = BvhOptions::default().with_weights(1.0, 0.2);
    let bvh = Bvh::bulk_build(options, &new).expect("valid");
    bvh.validate().expect("valid tree");
    let class_of: HashMap<ObjectId, u32> = (0..64)
        .map(|i| (ObjectId(i as u32), objects[i].model as u32))
        .collect();
    assert_eq!(leaf_purity(&bvh, &class_of), 1.0);
    // A purely spatial build (mu = 0) makes leaves of 2 columns x 4 rows (box 42 x 8 m, far
    // less surface than 4 x 2 rows' 122 x 4 m), which mixes the classes.
    let spatial =
        Bvh::bulk_build(BvhOptions::default().with_weights(0.0, 0.2), &new).expect("valid");
    spatial.validate().expect("valid tree");
    assert!(leaf_purity(&spatial, &class_of) < 1.0);
}

#[test]
fn bulk_build_is_deterministic() {
    // rayon only runs independent halves in parallel: the result may not depend on it.
    let mut rng = Rng::new(3);
    let objects: Vec<Obj> = (0..20_000)
        .map(|_| {
            let p = Vec3::new(rng.range(0.0, 2000.0), rng.range(0.0, 2000.0), 0.0);
            let class = rng.below(6) as u32;
            let r = rng.range(1.0, 5.0);
            noisy_object(&mut rng, p, r, class)
        })
        .collect();
    let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
    let a = Bvh::bulk_build(BvhOptions::default(), &new).expect("valid");
    let b = Bvh::bulk_build(BvhOptions::default(), &new).expect("valid");
    a.validate().expect("valid tree");
    let q = CutQuery {
        position: Vec3::new(500.0, 500.0, 2.0),
        min_solid_angle: 1e-3,
        max_results: 500,
    };
    assert_eq!(a.cut(&q), b.cut(&q));
    assert_eq!(a.node_count(), b.node_count());
}

#[test]
fn snapshot_round_trips_and_corrupt_snapshots_are_refused() {
    let mut rng = Rng::new(5);
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let objects: Vec<Obj> = (0..300)
        .map(|_| {
            let p = Vec3::new(rng.range(0.0, 100.0), rng.range(0.0, 100.0), 0.0);
            let class = rng.below(3) as u32;
            noisy_object(&mut rng, p, 1.0, class)
        })
        .collect();
    let ids = insert_all(&mut bvh, &objects);
    bvh.remove(ids[4]).expect("live");
    let json = serde_json::to_string(&bvh).expect("serialisable");
    let back: Bvh = serde_json::from_str(&json).expect("valid snapshot");
    back.validate().expect("valid tree");
    let q = CutQuery {
        position: Vec3::new(50.0, 50.0, 1.0),
        min_solid_angle: 1e-2,
        max_results: 100,
    };
    assert_eq!(back.cut(&q), bvh.cut(&q));
    assert_eq!(back.len(), bvh.len());
    // A snapshot whose root points nowhere is refused, not trusted.
    let mut value: serde_json::Value = serde_json::from_str(&json).expect("json");
    value["root"] = serde_json::json!(123_456);
    assert!(serde_json::from_value::<Bvh>(value).is_err());
    // So is one whose descriptor sums were tampered with.
    let mut value: serde_json::Value = serde_json::from_str(&json).expect("json");
    value["shape_sum"][0] = serde_json::json!(1e9);
    assert!(serde_json::from_value::<Bvh>(value).is_err());
}

#[test]
fn descriptors_and_centroids_are_exposed() {
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let a = object(Vec3::ZERO, 1.0, 0);
    let b = object(Vec3::X, 1.0, 2);
    insert_all(&mut bvh, &[a.clone(), b.clone()]);
    let root = bvh.node(bvh.root()).expect("root");
    assert_eq!(root.count(), 2);
    // The centroid of two objects is their mean.
    let (sa, _) = class_descriptors(0);
    let (sb, _) = class_descriptors(2);
    for (c, (x, y)) in root.shape_centroid().iter().zip(sa.iter().zip(&sb)) {
        assert!((c - 0.5 * (x + y)).abs() < 1e-6);
    }
    assert_eq!(root.texture_centroid().len(), horizon_bvh::TEXTURE_LEN);
    // The bound holds both centres; the outer sphere holds both spheres.
    assert!(root.bound().radius >= 0.5 - 1e-6);
    assert!(root.outer_sphere().radius >= 1.5 - 1e-6);
    assert!(bvh.memory_bytes() > 0);
}
