//! Standing cut queries (Sirikata's `RTreeCutQueryHandler`; `DESIGN.md`, "Cut test"): deltas
//! applied to the old cut equal the cut recomputed from scratch, delta order, hysteresis.

mod common;

use std::collections::{HashMap, HashSet};

use common::{check_cut, insert_all, object, Obj, Rng};
use glam::{Affine3A, Vec3};
use horizon_bvh::{
    apply_deltas, worst_case_solid_angle, Aabb, Bvh, BvhOptions, CutDelta, CutEntry, CutItem,
    CutQuery, NodeId, Sphere, StandingOptions, StandingQuery,
};
use proptest::collection::vec;
use proptest::prelude::*;

/// What a client must agree on for each entry (everything but the solid angle, which is as of
/// the update that last sent the entry).
type View = HashMap<CutItem, (Option<NodeId>, u32, Sphere, Aabb)>;

fn view<'a>(entries: impl Iterator<Item = &'a CutEntry>) -> View {
    entries
        .map(|e| (e.item, (e.parent, e.covers, e.sphere, e.aabb)))
        .collect()
}

/// Adds, then reparents, then removes; permanent removals only for objects that left.
fn check_deltas(bvh: &Bvh, deltas: &[CutDelta]) {
    let rank = |d: &CutDelta| match d {
        CutDelta::Add(_) => 0,
        CutDelta::Reparent { .. } => 1,
        CutDelta::Remove { .. } => 2,
    };
    assert!(
        deltas.windows(2).all(|w| rank(&w[0]) <= rank(&w[1])),
        "deltas out of order: {deltas:?}"
    );
    for d in deltas {
        if let CutDelta::Remove {
            item: CutItem::Object(o),
            transient,
        } = *d
        {
            assert_eq!(transient, bvh.object(o).is_some(), "permanence of {o:?}");
        }
    }
}

/// Every live object covered exactly once, itself or through one aggregate.
fn check_complete_view(bvh: &Bvh, entries: &[CutEntry]) {
    let mut covered = HashSet::new();
    for e in entries {
        match e.item {
            CutItem::Object(o) => assert!(covered.insert(o), "{o:?} covered twice"),
            CutItem::Aggregate(n) => {
                let mut under = Vec::new();
                bvh.objects_under(n, &mut under);
                assert_eq!(under.len() as u32, e.covers);
                for o in under {
                    assert!(covered.insert(o), "{o:?} covered twice");
                }
            }
        }
    }
    assert_eq!(covered.len(), bvh.len(), "every object covered");
}

fn omega(bvh: &Bvh, n: NodeId, p: Vec3) -> f32 {
    let node = bvh.node(n).expect("live node");
    worst_case_solid_angle(p, node.bound().centre, node.bound().radius, node.r_max())
}

/// The strict ancestors of the entries: the refined set.
fn refined_set(bvh: &Bvh, entries: &[CutEntry]) -> HashSet<NodeId> {
    let mut set = HashSet::new();
    for e in entries {
        let mut up = e.parent;
        while let Some(a) = up {
            if !set.insert(a) {
                break;
            }
            up = bvh.node(a).expect("live").parent();
        }
    }
    set
}

/// From scratch: the hysteresis rule given the previous refined set (module docs).
fn hysteresis_reference(
    bvh: &Bvh,
    previous: &HashSet<NodeId>,
    p: Vec3,
    options: &StandingOptions,
) -> HashSet<CutItem> {
    let lo = options.min_solid_angle * (1.0 - options.hysteresis);
    let hi = options.min_solid_angle * (1.0 + options.hysteresis);
    let mut out = HashSet::new();
    if bvh.is_empty() {
        return out;
    }
    let mut stack = vec![bvh.root()];
    while let Some(n) = stack.pop() {
        let threshold = if previous.contains(&n) { lo } else { hi };
        if omega(bvh, n, p) < threshold {
            out.insert(CutItem::Aggregate(n));
            continue;
        }
        let node = bvh.node(n).expect("live");
        if node.is_leaf() {
            out.extend(node.objects().map(CutItem::Object));
        } else {
            stack.extend(node.child_nodes());
        }
    }
    out
}

fn entries_of(sq: &StandingQuery) -> Vec<CutEntry> {
    sq.entries().copied().collect()
}

#[derive(Debug, Clone)]
enum Op {
    Step(Vec3),
    Insert { at: Vec3, radius: f32, class: u32 },
    Remove { pick: usize },
    Move { pick: usize, to: Vec3 },
    Rebuild,
}

fn point(extent: f32) -> impl Strategy<Value = Vec3> {
    (0.0..extent, 0.0..extent, 0.0..extent / 20.0).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn step() -> impl Strategy<Value = Vec3> {
    (-8.0f32..8.0, -8.0f32..8.0).prop_map(|(x, y)| Vec3::new(x, y, 0.0))
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        8 => step().prop_map(Op::Step),
        3 => (point(150.0), 0.1f32..4.0, 0u32..4)
            .prop_map(|(at, radius, class)| Op::Insert { at, radius, class }),
        2 => any::<usize>().prop_map(|pick| Op::Remove { pick }),
        1 => (any::<usize>(), point(150.0)).prop_map(|(pick, to)| Op::Move { pick, to }),
        1 => Just(Op::Rebuild),
    ]
}

fn world(seed: u64, n: usize) -> Vec<Obj> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let at = Vec3::new(
                rng.range(0.0, 150.0),
                rng.range(0.0, 150.0),
                rng.range(0.0, 5.0),
            );
            object(at, rng.range(0.1, 4.0), rng.below(4) as u32)
        })
        .collect()
}

fn config() -> ProptestConfig {
    let mut config = ProptestConfig::default();
    if cfg!(debug_assertions) && std::env::var_os("PROPTEST_CASES").is_none() {
        config.cases /= 4;
    }
    config
}

/// Applies a tree change; returns false for a viewer step.
fn apply_op(bvh: &mut Bvh, op: &Op, viewer: &mut Vec3) {
    match *op {
        Op::Step(by) => *viewer += by,
        Op::Insert { at, radius, class } => {
            bvh.insert(&object(at, radius, class).as_new())
                .expect("valid object");
        }
        Op::Remove { pick } => {
            let ids: Vec<_> = bvh.object_ids().collect();
            if !ids.is_empty() {
                bvh.remove(ids[pick % ids.len()]).expect("live object");
            }
        }
        Op::Move { pick, to } => {
            let ids: Vec<_> = bvh.object_ids().collect();
            if !ids.is_empty() {
                let id = ids[pick % ids.len()];
                let radius = bvh.object(id).expect("live").sphere().radius;
                bvh.move_object(id, Affine3A::from_translation(to), Sphere::new(to, radius))
                    .expect("valid move");
            }
        }
        Op::Rebuild => bvh.rebuild(),
    }
}

proptest! {
    #![proptest_config(config())]

    /// h = 0: after every viewer step, insert, remove, move and rebuild, the old cut plus the
    /// deltas equals the one-shot cut recomputed from scratch (budget binding or not), the
    /// deltas are ordered, and the cut keeps the complete-view invariant.
    #[test]
    fn deltas_applied_to_old_cut_equal_fresh_cut(
        seed in any::<u64>(),
        n in 0usize..150,
        branching in 3usize..=10,
        bulk in any::<bool>(),
        log_omega in -4.0f32..-0.5,
        max_results in prop_oneof![1usize..40, Just(100_000usize)],
        start in point(150.0),
        ops in vec(op(), 1..30),
    ) {
        let objects = world(seed, n);
        let options = BvhOptions::with_branching(branching);
        let mut bvh = if bulk {
            let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
            Bvh::bulk_build(options, &new).expect("valid")
        } else {
            let mut bvh = Bvh::new(options).expect("valid");
            insert_all(&mut bvh, &objects);
            bvh
        };
        let standing = StandingOptions {
            min_solid_angle: 10f32.powf(log_omega),
            max_results,
            hysteresis: 0.0,
        };
        let mut sq = StandingQuery::new(standing);
        let mut client = HashMap::new();
        let mut deltas = Vec::new();
        let mut viewer = start;
        for op in std::iter::once(&Op::Step(Vec3::ZERO)).chain(&ops) {
            apply_op(&mut bvh, op, &mut viewer);
            deltas.clear();
            sq.update(&bvh, viewer, &mut deltas);
            check_deltas(&bvh, &deltas);
            apply_deltas(&mut client, &deltas);
            let query = CutQuery {
                position: viewer,
                min_solid_angle: standing.min_solid_angle,
                max_results,
            };
            let fresh = bvh.cut(&query);
            check_cut(&bvh, &fresh, &query);
            let expected = view(fresh.entries.iter());
            prop_assert_eq!(&view(client.values()), &expected);
            prop_assert_eq!(&view(sq.entries()), &expected);
        }
    }

    /// h > 0 on a fixed tree: every update equals the hysteresis rule evaluated from scratch
    /// given the previous refined set, keeps the complete view, and every refined node is
    /// within the band (at least (1 - h) Omega_min), every aggregate below (1 + h) Omega_min.
    #[test]
    fn hysteresis_cut_matches_rule_from_scratch(
        seed in any::<u64>(),
        n in 1usize..150,
        branching in 3usize..=10,
        log_omega in -3.0f32..-0.5,
        h in 0.01f32..0.5,
        start in point(150.0),
        steps in vec(step(), 1..30),
    ) {
        let objects = world(seed, n);
        let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
        let bvh = Bvh::bulk_build(BvhOptions::with_branching(branching), &new).expect("valid");
        let options = StandingOptions {
            min_solid_angle: 10f32.powf(log_omega),
            max_results: usize::MAX,
            hysteresis: h,
        };
        let mut sq = StandingQuery::new(options);
        let mut client = HashMap::new();
        let mut deltas = Vec::new();
        let mut viewer = start;
        let mut previous = HashSet::new();
        for by in std::iter::once(Vec3::ZERO).chain(steps) {
            viewer += by;
            deltas.clear();
            let stats = sq.update(&bvh, viewer, &mut deltas);
            prop_assert!(!stats.fell_back);
            check_deltas(&bvh, &deltas);
            apply_deltas(&mut client, &deltas);
            let entries = entries_of(&sq);
            check_complete_view(&bvh, &entries);
            let expected = hysteresis_reference(&bvh, &previous, viewer, &options);
            let got: HashSet<CutItem> = entries.iter().map(|e| e.item).collect();
            prop_assert_eq!(&got, &expected);
            prop_assert_eq!(&view(client.values()), &view(entries.iter()));
            previous = refined_set(&bvh, &entries);
            for &r in &previous {
                prop_assert!(omega(&bvh, r, viewer) >= options.min_solid_angle * (1.0 - h));
            }
            for e in &entries {
                if let CutItem::Aggregate(a) = e.item {
                    prop_assert!(omega(&bvh, a, viewer) < options.min_solid_angle * (1.0 + h));
                }
            }
        }
    }
}

/// Two clusters of 8 unit objects 10 km apart, branching 8: the root and two leaves.
fn two_clusters() -> (Bvh, NodeId) {
    let mut objects: Vec<Obj> = Vec::new();
    for (cluster, x) in [(0u32, 0.0f32), (1, 10_000.0)] {
        for i in 0..8 {
            let offset = Vec3::new((i % 4) as f32, (i / 4) as f32 * 2.0, 0.0);
            objects.push(object(Vec3::new(x, 0.0, 0.0) + offset, 1.0, cluster));
        }
    }
    let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
    let bvh = Bvh::bulk_build(BvhOptions::with_branching(8), &new).expect("valid objects");
    let root = bvh.node(bvh.root()).expect("root");
    let near = root
        .child_nodes()
        .find(|&n| bvh.node(n).expect("leaf").bound().centre.x < 5_000.0)
        .expect("a leaf near the origin");
    (bvh, near)
}

/// A viewer oscillating 0.5 m either side of the distance where the near leaf's worst case
/// equals Omega_min: with h = 0 every step refines or coarsens; with h = 0.1 nothing changes
/// after the first update.
#[test]
fn hysteresis_stops_ping_pong_at_the_threshold() {
    let (bvh, leaf) = two_clusters();
    let at = Vec3::new(-100.0, 1.0, 0.0);
    let threshold = omega(&bvh, leaf, at);
    let a = at + Vec3::new(0.5, 0.0, 0.0);
    let b = at - Vec3::new(0.5, 0.0, 0.0);
    assert!(omega(&bvh, leaf, a) > threshold && omega(&bvh, leaf, b) < threshold);
    for (h, expect_changes) in [(0.0, true), (0.1, false)] {
        let mut sq = StandingQuery::new(StandingOptions {
            min_solid_angle: threshold,
            max_results: 1000,
            hysteresis: h,
        });
        let mut deltas = Vec::new();
        sq.update(&bvh, a, &mut deltas);
        for i in 0..10 {
            deltas.clear();
            sq.update(&bvh, if i % 2 == 0 { b } else { a }, &mut deltas);
            assert_eq!(
                !deltas.is_empty(),
                expect_changes,
                "h {h}, step {i}: {deltas:?}"
            );
        }
    }
}

/// Walking up to the near cluster refines its leaf: the 8 objects are added before the
/// leaf's aggregate is removed (transiently); walking away coarsens, the aggregate first.
#[test]
fn refinement_and_coarsening_load_before_dropping() {
    let (bvh, leaf) = two_clusters();
    let mut sq = StandingQuery::new(StandingOptions {
        min_solid_angle: 1e-4,
        max_results: 1000,
        hysteresis: 0.1,
    });
    let mut deltas = Vec::new();
    sq.update(&bvh, Vec3::new(0.0, -1_000.0, 0.0), &mut deltas);
    assert!(deltas
        .iter()
        .any(|d| matches!(d, CutDelta::Add(e) if e.item == CutItem::Aggregate(leaf))));
    for (to, added, removed) in [
        (Vec3::new(1.5, -10.0, 0.0), 8usize, 1usize),
        (Vec3::new(0.0, -1_000.0, 0.0), 1, 8),
    ] {
        deltas.clear();
        sq.update(&bvh, to, &mut deltas);
        check_deltas(&bvh, &deltas);
        let adds = deltas
            .iter()
            .filter(|d| matches!(d, CutDelta::Add(_)))
            .count();
        let removes = deltas
            .iter()
            .filter(|d| {
                matches!(
                    d,
                    CutDelta::Remove {
                        transient: true,
                        ..
                    }
                )
            })
            .count();
        assert_eq!((adds, removes), (added, removed), "{deltas:?}");
        assert!(matches!(deltas[0], CutDelta::Add(_)));
    }
}

/// Tree changes reach the client: an insert that splits a refined leaf reparents the
/// objects that moved, a removed object is removed permanently, and the cut stays equal to
/// the one-shot cut.
#[test]
fn splits_reparent_and_removals_are_permanent() {
    let mut bvh = Bvh::new(BvhOptions::with_branching(4)).expect("valid");
    let mut rng = Rng::new(7);
    let ids = insert_all(
        &mut bvh,
        &(0..4)
            .map(|i| object(Vec3::new(i as f32 * 3.0, 0.0, 0.0), 1.0, 0))
            .collect::<Vec<_>>(),
    );
    let options = StandingOptions {
        min_solid_angle: 1e-4,
        max_results: 1000,
        hysteresis: 0.0,
    };
    let viewer = Vec3::new(5.0, 5.0, 0.0);
    let mut sq = StandingQuery::new(options);
    let mut client = HashMap::new();
    let mut deltas = Vec::new();
    sq.update(&bvh, viewer, &mut deltas);
    apply_deltas(&mut client, &deltas);
    assert_eq!(client.len(), 4, "every object shown as itself");
    // A fifth object overflows the root leaf: it splits under a new root.
    bvh.insert(&object(Vec3::new(rng.range(0.0, 9.0), 1.0, 0.0), 1.0, 0).as_new())
        .expect("valid");
    deltas.clear();
    sq.update(&bvh, viewer, &mut deltas);
    check_deltas(&bvh, &deltas);
    apply_deltas(&mut client, &deltas);
    let reparents = deltas
        .iter()
        .filter(|d| matches!(d, CutDelta::Reparent { .. }))
        .count();
    assert!(reparents >= 1, "{deltas:?}");
    assert!(!deltas.iter().any(|d| matches!(d, CutDelta::Remove { .. })));
    let query = CutQuery {
        position: viewer,
        min_solid_angle: options.min_solid_angle,
        max_results: options.max_results,
    };
    assert_eq!(view(client.values()), view(bvh.cut(&query).entries.iter()));
    // Remove one object: a permanent removal.
    bvh.remove(ids[0]).expect("live");
    deltas.clear();
    sq.update(&bvh, viewer, &mut deltas);
    check_deltas(&bvh, &deltas);
    apply_deltas(&mut client, &deltas);
    assert!(deltas.contains(&CutDelta::Remove {
        item: CutItem::Object(ids[0]),
        transient: false
    }));
    assert_eq!(view(client.values()), view(bvh.cut(&query).entries.iter()));
}

/// An empty tree has an empty standing cut; emptying a tree removes everything permanently.
#[test]
fn empty_tree_and_emptied_tree() {
    let mut bvh = Bvh::new(BvhOptions::default()).expect("valid");
    let mut sq = StandingQuery::new(StandingOptions::new(1e-3, 100));
    let mut deltas = Vec::new();
    sq.update(&bvh, Vec3::ZERO, &mut deltas);
    assert!(deltas.is_empty() && sq.is_empty());
    let id = bvh
        .insert(&object(Vec3::new(1.0, 0.0, 0.0), 0.5, 0).as_new())
        .expect("valid");
    sq.update(&bvh, Vec3::ZERO, &mut deltas);
    assert_eq!(sq.len(), 1);
    deltas.clear();
    bvh.remove(id).expect("live");
    sq.update(&bvh, Vec3::ZERO, &mut deltas);
    assert_eq!(
        deltas,
        vec![CutDelta::Remove {
            item: CutItem::Object(id),
            transient: false
        }]
    );
    assert!(sq.is_empty());
}

/// A viewer walking 1 m steps through 3,000 objects with a budget that binds at every step:
/// after the first update, every budget-bound update is seeded by the heap-free threshold
/// walk (the margin adapts when it overflows), only a few nodes pass through the heap, and
/// every cut still equals the one-shot best-first cut, on a bulk-built and an incrementally
/// built tree.
#[test]
fn budget_bound_walk_is_seeded_and_equals_the_one_shot_cut() {
    let objects = world(11, 3_000);
    let options = BvhOptions::default();
    let new: Vec<_> = objects.iter().map(Obj::as_new).collect();
    let bulk = Bvh::bulk_build(options.clone(), &new).expect("valid");
    let mut incremental = Bvh::new(options).expect("valid");
    insert_all(&mut incremental, &objects);
    for bvh in [&bulk, &incremental] {
        let standing = StandingOptions {
            min_solid_angle: 1e-5,
            max_results: 400,
            hysteresis: 0.1,
        };
        let mut sq = StandingQuery::new(standing);
        let mut client = HashMap::new();
        let mut deltas = Vec::new();
        let mut viewer = Vec3::new(20.0, 30.0, 2.0);
        let (mut bound, mut seeded, mut through_heap, mut refined) = (0, 0, 0, 0);
        for step in 0..150 {
            deltas.clear();
            let stats = sq.update(bvh, viewer, &mut deltas);
            check_deltas(bvh, &deltas);
            apply_deltas(&mut client, &deltas);
            let query = CutQuery {
                position: viewer,
                min_solid_angle: standing.min_solid_angle,
                max_results: standing.max_results,
            };
            let fresh = bvh.cut(&query);
            assert_eq!(
                view(client.values()),
                view(fresh.entries.iter()),
                "step {step}"
            );
            assert_eq!(
                view(sq.entries()),
                view(fresh.entries.iter()),
                "step {step}"
            );
            if step > 0 {
                bound += usize::from(stats.fell_back);
                seeded += usize::from(stats.seeded);
                through_heap += stats.heap_refinements;
                refined += refined_set(bvh, &fresh.entries).len();
            }
            viewer += Vec3::new(0.8, 0.6, 0.0);
        }
        assert_eq!(bound, 149, "the budget binds at every step");
        assert!(
            seeded >= 140,
            "{seeded} of {bound} budget-bound updates seeded"
        );
        assert!(
            through_heap * 4 < refined,
            "{through_heap} of {refined} refinements through the heap"
        );
    }
}

/// The tree's state stamp changes with every change and is shared only by unchanged clones.
#[test]
fn state_stamp_tracks_changes() {
    let mut bvh = Bvh::new(BvhOptions::default()).expect("valid");
    let empty = bvh.state_stamp();
    let id = bvh
        .insert(&object(Vec3::ZERO, 1.0, 0).as_new())
        .expect("valid");
    let inserted = bvh.state_stamp();
    assert_ne!(empty, inserted);
    let clone = bvh.clone();
    assert_eq!(clone.state_stamp(), inserted);
    bvh.move_object(
        id,
        Affine3A::from_translation(Vec3::X),
        Sphere::new(Vec3::X, 1.0),
    )
    .expect("valid move");
    assert_ne!(bvh.state_stamp(), inserted);
    assert_eq!(clone.state_stamp(), inserted);
    let moved = bvh.state_stamp();
    bvh.rebuild();
    assert_ne!(bvh.state_stamp(), moved);
    let rebuilt = bvh.state_stamp();
    bvh.remove(id).expect("live");
    assert_ne!(bvh.state_stamp(), rebuilt);
    let other = Bvh::new(BvhOptions::default()).expect("valid");
    assert_ne!(other.state_stamp(), empty);
}
