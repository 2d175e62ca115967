//! Hand-built trees with known cuts (the solid-angle cut query, `DESIGN.md` "Cut test").

mod common;

use std::f32::consts::PI;

use common::{check_cut, object, Obj};
use glam::Vec3;
use horizon_bvh::{Bvh, BvhOptions, CutItem, CutQuery, CutWorkspace, EntryKind, NodeId};

/// Two clusters of 8 objects (radius 1 m, within 3 m of their centre), 10 km apart, bulk
/// built with branching 8: the only cut of 16 objects into two leaves of at most 8 is between
/// the clusters, so the root has exactly the two cluster leaves.
fn two_clusters() -> (Bvh, NodeId, NodeId) {
    let mut objects: Vec<Obj> = Vec::new();
    for (cluster, x) in [(0u32, 0.0f32), (1, 10_000.0)] {
        for i in 0..8 {
            let offset = Vec3::new((i % 4) as f32, (i / 4) as f32 * 2.0, 0.0);
            objects.push(object(Vec3::new(x, 0.0, 0.0) + offset, 1.0, cluster));
        }
    }
    let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
    let bvh = Bvh::bulk_build(BvhOptions::with_branching(8), &new).expect("valid objects");
    bvh.validate().expect("valid tree");
    let root = bvh.node(bvh.root()).expect("root");
    let kids: Vec<NodeId> = root.child_nodes().collect();
    assert_eq!(kids.len(), 2, "one leaf per cluster");
    let near_origin = |n: &NodeId| bvh.node(*n).expect("leaf").bound().centre.x < 5_000.0;
    let (a, b) = if near_origin(&kids[0]) {
        (kids[0], kids[1])
    } else {
        (kids[1], kids[0])
    };
    for leaf in [a, b] {
        assert!(bvh.node(leaf).expect("leaf").is_leaf());
        assert_eq!(bvh.node(leaf).expect("leaf").len(), 8);
    }
    (bvh, a, b)
}

fn query(position: Vec3, min_solid_angle: f32, max_results: usize) -> CutQuery {
    CutQuery {
        position,
        min_solid_angle,
        max_results,
    }
}

#[test]
fn near_cluster_is_objects_far_cluster_is_one_aggregate() {
    let (bvh, near, far) = two_clusters();
    // From 5 m above the near cluster: its leaf's worst case is huge (the viewer is almost
    // inside), the far leaf's is about pi / 1e8 sr, far below 1e-4.
    let q = query(Vec3::new(1.0, 1.0, 5.0), 1e-4, 100);
    let cut = bvh.cut(&q);
    check_cut(&bvh, &cut, &q);
    assert_eq!(cut.entries.len(), 9, "8 near objects + 1 far aggregate");
    let objects = cut.entries.iter().filter(|e| e.kind() == EntryKind::Object);
    assert!(objects.clone().all(|e| e.parent == Some(near)));
    assert_eq!(objects.count(), 8);
    let aggregate = cut
        .entries
        .iter()
        .find(|e| e.kind() == EntryKind::Aggregate)
        .expect("one aggregate");
    assert_eq!(aggregate.item, CutItem::Aggregate(far));
    assert_eq!(aggregate.covers, 8);
    assert_eq!(aggregate.parent, Some(bvh.root()));
    // The root and its two children were evaluated; the leaves' objects are not nodes.
    assert_eq!(cut.nodes_visited, 3);
}

#[test]
fn zero_min_solid_angle_returns_every_object() {
    // Everything subtends at least 0 sr: all refinement passes.
    let (bvh, _, _) = two_clusters();
    let q = query(Vec3::new(5_000.0, 0.0, 0.0), 0.0, 1000);
    let cut = bvh.cut(&q);
    check_cut(&bvh, &cut, &q);
    assert_eq!(cut.entries.len(), 16);
    assert!(cut.entries.iter().all(|e| e.kind() == EntryKind::Object));
}

#[test]
fn huge_min_solid_angle_returns_the_root_alone() {
    // No solid angle exceeds 4 pi, so nothing is refined, not even the root.
    let (bvh, _, _) = two_clusters();
    let q = query(Vec3::ZERO, 4.0 * PI + 1.0, 1000);
    let cut = bvh.cut(&q);
    check_cut(&bvh, &cut, &q);
    assert_eq!(cut.entries.len(), 1);
    assert_eq!(cut.entries[0].item, CutItem::Aggregate(bvh.root()));
    assert_eq!(cut.entries[0].covers, 16);
    assert_eq!(cut.entries[0].parent, None);
}

#[test]
fn max_results_caps_the_cut_largest_solid_angle_first() {
    let (bvh, near, far) = two_clusters();
    let position = Vec3::new(1.0, 1.0, 5.0);
    // Budget 2: the root's two children fit, neither leaf's 8 objects do.
    let q = query(position, 0.0, 2);
    let cut = bvh.cut(&q);
    check_cut(&bvh, &cut, &q);
    let mut items: Vec<_> = cut.entries.iter().map(|e| e.item).collect();
    items.sort_by_key(|i| format!("{i:?}"));
    let mut expected = vec![CutItem::Aggregate(near), CutItem::Aggregate(far)];
    expected.sort_by_key(|i| format!("{i:?}"));
    assert_eq!(items, expected);
    // Budget 9: the near leaf has the larger worst case, so it is refined first (2 + 7 = 9);
    // the far leaf no longer fits.
    let q = query(position, 0.0, 9);
    let cut = bvh.cut(&q);
    check_cut(&bvh, &cut, &q);
    assert_eq!(cut.entries.len(), 9);
    assert!(cut
        .entries
        .iter()
        .any(|e| e.item == CutItem::Aggregate(far)));
    // Budget 0 behaves as 1: the root alone still covers everything.
    let q = query(position, 0.0, 0);
    let cut = bvh.cut(&q);
    check_cut(&bvh, &cut, &q);
    assert_eq!(cut.entries.len(), 1);
}

#[test]
fn empty_and_single_object_trees() {
    let mut bvh = Bvh::new(BvhOptions::default()).expect("default options");
    let q = query(Vec3::ZERO, 0.0, 10);
    let cut = bvh.cut(&q);
    assert!(cut.entries.is_empty());
    assert_eq!(cut.nodes_visited, 0);
    // One object 100 m away with radius 1 subtends about 3.1e-4 sr.
    let id = bvh
        .insert(&object(Vec3::new(100.0, 0.0, 0.0), 1.0, 0).as_new())
        .expect("valid object");
    bvh.validate().expect("valid tree");
    let cut = bvh.cut(&query(Vec3::ZERO, 1e-4, 10));
    check_cut(&bvh, &cut, &query(Vec3::ZERO, 1e-4, 10));
    assert_eq!(cut.entries.len(), 1);
    assert_eq!(cut.entries[0].item, CutItem::Object(id));
    assert!((cut.entries[0].solid_angle - PI * 1e-4).abs() < 1e-7);
    // Above its solid angle it stays inside the root aggregate.
    let cut = bvh.cut(&query(Vec3::ZERO, 1e-3, 10));
    assert_eq!(cut.entries[0].item, CutItem::Aggregate(bvh.root()));
}

#[test]
fn workspace_reuse_gives_the_same_cut() {
    let (bvh, _, _) = two_clusters();
    let mut workspace = CutWorkspace::new();
    let mut out = horizon_bvh::Cut::default();
    for position in [
        Vec3::ZERO,
        Vec3::new(10_000.0, 0.0, 3.0),
        Vec3::new(5_000.0, 0.0, 0.0),
    ] {
        let q = query(position, 1e-4, 100);
        bvh.cut_into(&q, &mut workspace, &mut out);
        assert_eq!(out, bvh.cut(&q));
        check_cut(&bvh, &out, &q);
    }
}
