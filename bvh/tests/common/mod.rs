//! Shared fixtures for the BVH tests: the workspace's seeded generator, objects with class
//! descriptors, and the complete-view checker for cuts.

#![allow(dead_code)]

use std::collections::HashMap;

use glam::{Affine3A, Vec3};
use horizon_bvh::{
    worst_case_solid_angle, Bvh, Cut, CutItem, CutQuery, NewObject, NodeId, ObjectId, Sphere,
    SHAPE_LEN, TEXTURE_LEN,
};

pub use horizon_mesh::rng::Rng;

/// An owned object to insert.
#[derive(Debug, Clone)]
pub struct Obj {
    pub model: u64,
    pub sphere: Sphere,
    pub shape: Vec<f32>,
    pub texture: Vec<f32>,
}

impl Obj {
    pub fn as_new(&self) -> NewObject<'_> {
        NewObject {
            model: self.model,
            transform: Affine3A::from_translation(self.sphere.centre),
            sphere: self.sphere,
            shape: &self.shape,
            texture: &self.texture,
        }
    }
}

/// Descriptors of class `class`: far apart between classes (shape L2 distance about 1.1,
/// texture L1 distance 320 between neighbouring classes).
pub fn class_descriptors(class: u32) -> (Vec<f32>, Vec<f32>) {
    let c = class as f32;
    let shape = (0..SHAPE_LEN).map(|i| 0.1 * c + 0.001 * i as f32).collect();
    let texture = (0..TEXTURE_LEN)
        .map(|i| 10.0 * c + (i % 4) as f32)
        .collect();
    (shape, texture)
}

/// An object of `class` at `centre` with `radius`.
pub fn object(centre: Vec3, radius: f32, class: u32) -> Obj {
    let (shape, texture) = class_descriptors(class);
    Obj {
        model: u64::from(class),
        sphere: Sphere::new(centre, radius),
        shape,
        texture,
    }
}

/// An object of `class` with descriptor noise from `rng`.
pub fn noisy_object(rng: &mut Rng, centre: Vec3, radius: f32, class: u32) -> Obj {
    let mut o = object(centre, radius, class);
    for v in &mut o.shape {
        *v += rng.range(-0.01, 0.01);
    }
    for v in &mut o.texture {
        *v += rng.range(-2.0, 2.0);
    }
    o
}

/// Inserts every object; returns their ids in order.
pub fn insert_all(bvh: &mut Bvh, objects: &[Obj]) -> Vec<ObjectId> {
    objects
        .iter()
        .map(|o| bvh.insert(&o.as_new()).expect("fixture objects are valid"))
        .collect()
}

/// The objects below `node`.
pub fn objects_under(bvh: &Bvh, node: NodeId) -> Vec<ObjectId> {
    let mut out = Vec::new();
    bvh.objects_under(node, &mut out);
    out
}

/// Worst-case solid angle of `node` from `position` (the cut's refinement test).
pub fn node_solid_angle(bvh: &Bvh, node: NodeId, position: Vec3) -> f32 {
    let n = bvh.node(node).expect("live node");
    worst_case_solid_angle(position, n.bound().centre, n.bound().radius, n.r_max())
}

/// Asserts everything a cut promises:
/// - complete view: every live object is covered exactly once, itself or through one
///   aggregate, and `covers` and `parent` agree with the tree;
/// - the budget: at most `max(1, max_results)` entries;
/// - every refined node (a strict ancestor of an entry) passed the refinement test;
/// - every aggregate failed the test or could not be refined within the budget.
pub fn check_cut(bvh: &Bvh, cut: &Cut, query: &CutQuery) {
    if bvh.is_empty() {
        assert!(cut.entries.is_empty(), "an empty tree has an empty cut");
        return;
    }
    let budget = query.max_results.max(1);
    assert!(
        cut.entries.len() <= budget,
        "{} entries exceed the budget {budget}",
        cut.entries.len()
    );
    let mut covered: HashMap<ObjectId, usize> = HashMap::new();
    for entry in &cut.entries {
        match entry.item {
            CutItem::Object(o) => {
                let object = bvh.object(o).expect("entries name live objects");
                assert_eq!(entry.covers, 1);
                assert_eq!(entry.parent, Some(object.leaf()));
                assert_eq!(entry.sphere, object.sphere());
                *covered.entry(o).or_default() += 1;
            }
            CutItem::Aggregate(n) => {
                let node = bvh.node(n).expect("entries name live nodes");
                assert_eq!(entry.parent, node.parent());
                assert_eq!(entry.covers, node.count());
                let under = objects_under(bvh, n);
                assert_eq!(under.len(), node.count() as usize);
                for o in under {
                    *covered.entry(o).or_default() += 1;
                }
                // Kept as an aggregate: failed the test, or refining would break the budget.
                let omega = node_solid_angle(bvh, n, query.position);
                assert!(
                    omega < query.min_solid_angle || cut.entries.len() + node.len() - 1 > budget,
                    "aggregate {n:?} (omega {omega}, {} children) passes the test and fits \
                     the budget ({} of {budget})",
                    node.len(),
                    cut.entries.len()
                );
            }
        }
        // Every strict ancestor was refined, so it passed the test.
        let mut up = entry.parent;
        while let Some(a) = up {
            let omega = node_solid_angle(bvh, a, query.position);
            assert!(
                omega >= query.min_solid_angle,
                "ancestor {a:?} was refined with omega {omega} < {}",
                query.min_solid_angle
            );
            up = bvh.node(a).expect("live ancestor").parent();
        }
    }
    assert_eq!(covered.len(), bvh.len(), "every object is covered");
    assert!(
        covered.values().all(|&c| c == 1),
        "no object is covered twice"
    );
}

/// Fraction of objects that share their leaf's majority class (1 = every leaf pure).
pub fn leaf_purity(bvh: &Bvh, class_of: &HashMap<ObjectId, u32>) -> f64 {
    let mut majority = 0usize;
    let mut stack = vec![bvh.root()];
    while let Some(n) = stack.pop() {
        let node = bvh.node(n).expect("live node");
        if node.is_leaf() {
            let mut counts: HashMap<u32, usize> = HashMap::new();
            for o in node.objects() {
                *counts.entry(class_of[&o]).or_default() += 1;
            }
            majority += counts.values().copied().max().unwrap_or(0);
        } else {
            stack.extend(node.child_nodes());
        }
    }
    majority as f64 / bvh.len().max(1) as f64
}
