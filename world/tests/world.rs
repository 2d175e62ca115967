//! The [`World`] end to end on small generated content: create, describe, the tree, the
//! rebuild and its publication, replay after a reopen, garbage collection, the format-1
//! upgrade, uploads, and opening folders that hold no world.

mod common;

use common::TempDir;

use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use glam::{Affine3A, Quat, Vec3, Vec4};
use horizon_aggregate::{AggregateManifest, AggregateOptions};
use horizon_bvh::{CutQuery, DEFAULT_MU, DEFAULT_W};
use horizon_mesh::rng::Rng;
use horizon_mesh::{export_glb, ExportOptions, Instance, InstancedMesh, Material, Submesh};
use horizon_world::{BadModel, Change, RebuildReport, User, World, WorldError, SNAPSHOT_EVERY};

// -------------------------------------------------------------------------------------------
// Helpers
// -------------------------------------------------------------------------------------------

/// A mesh of one submesh, placed once, in one colour.
fn mesh(positions: Vec<Vec3>, indices: Vec<u32>, color: [f32; 4]) -> InstancedMesh {
    InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            normals: None,
            uvs: None,
            colors: None,
            indices,
            material: Some(0),
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        materials: vec![Material {
            base_color_factor: Vec4::from_array(color),
            metallic_factor: 0.0,
            ..Material::default()
        }],
        textures: Vec::new(),
    }
}

/// A box of `size`, its base on y = 0.
fn cuboid(size: Vec3, color: [f32; 4]) -> InstancedMesh {
    let (x, y, z) = (size.x * 0.5, size.y, size.z * 0.5);
    let positions = vec![
        Vec3::new(-x, 0.0, -z),
        Vec3::new(x, 0.0, -z),
        Vec3::new(x, 0.0, z),
        Vec3::new(-x, 0.0, z),
        Vec3::new(-x, y, -z),
        Vec3::new(x, y, -z),
        Vec3::new(x, y, z),
        Vec3::new(-x, y, z),
    ];
    let indices = vec![
        0, 1, 2, 0, 2, 3, // bottom
        4, 6, 5, 4, 7, 6, // top
        0, 4, 5, 0, 5, 1, // back
        2, 6, 7, 2, 7, 3, // front
        1, 5, 6, 1, 6, 2, // right
        3, 7, 4, 3, 4, 0, // left
    ];
    mesh(positions, indices, color)
}

/// A square pyramid of base `base` and height `height`.
fn pyramid(base: f32, height: f32, color: [f32; 4]) -> InstancedMesh {
    let b = base * 0.5;
    let positions = vec![
        Vec3::new(-b, 0.0, -b),
        Vec3::new(b, 0.0, -b),
        Vec3::new(b, 0.0, b),
        Vec3::new(-b, 0.0, b),
        Vec3::new(0.0, height, 0.0),
    ];
    let indices = vec![0, 1, 2, 0, 2, 3, 0, 4, 1, 1, 4, 2, 2, 4, 3, 3, 4, 0];
    mesh(positions, indices, color)
}

/// Three small, different models.
fn models() -> Vec<(String, InstancedMesh)> {
    vec![
        (
            "crate".into(),
            cuboid(Vec3::new(1.0, 1.0, 1.0), [0.8, 0.5, 0.2, 1.0]),
        ),
        (
            "pillar".into(),
            cuboid(Vec3::new(0.4, 3.0, 0.4), [0.7, 0.7, 0.7, 1.0]),
        ),
        ("tent".into(), pyramid(2.0, 1.5, [0.1, 0.6, 0.2, 1.0])),
    ]
}

/// A seeded placement in a 40 m square.
fn placement(rng: &mut Rng) -> Affine3A {
    Affine3A::from_scale_rotation_translation(
        Vec3::splat(rng.range(0.5, 2.0)),
        Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU)),
        Vec3::new(rng.range(-20.0, 20.0), 0.0, rng.range(-20.0, 20.0)),
    )
}

/// `n` seeded objects over the three models.
fn objects(n: usize, seed: u64) -> Vec<(usize, Affine3A)> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| (i % 3, placement(&mut rng)))
        .collect::<Vec<_>>()
}

/// A world of `n` objects, described, with its tree built (not yet rebuilt).
fn built_world(dir: &Path, n: usize) -> World {
    let world = World::create(dir, "test", 1, &models(), &objects(n, 11)).expect("create");
    world.describe_models(&|_, _| {}).expect("describe");
    world.build_tree(DEFAULT_MU, DEFAULT_W).expect("tree");
    world
}

fn rebuild(world: &World) -> RebuildReport {
    let report = world
        .rebuild_aggregates(AggregateOptions::default(), &|_| {})
        .expect("rebuild");
    assert!(
        report.build.failed.is_empty(),
        "aggregates failed: {:?}",
        report.build.failed
    );
    report
}

/// Every blob the manifest names: aggregate GLBs and parts files.
fn named(manifest: &AggregateManifest) -> BTreeSet<String> {
    manifest
        .nodes
        .values()
        .flat_map(|e| std::iter::once(e.glb.clone()).chain(e.parts.clone()))
        .collect()
}

/// The published manifest, which must exist, and every blob it names, which must too.
fn check_published(world: &World) -> AggregateManifest {
    let published = world.meta().published().expect("published");
    let hash = published.manifest.expect("a manifest is published");
    assert!(
        world.blobs().size(&hash).expect("size").is_some(),
        "the published manifest {hash} is missing"
    );
    let manifest = world
        .published_manifest()
        .expect("read the manifest")
        .expect("a manifest");
    for blob in named(&manifest) {
        assert!(
            world.blobs().size(&blob).expect("size").is_some(),
            "the published manifest names {blob}, which is not stored"
        );
    }
    if let Some(previous) = published.previous_manifest {
        let bytes = world
            .blob(&previous)
            .expect("read")
            .unwrap_or_else(|| panic!("the previous manifest {previous} is missing"));
        let previous: AggregateManifest = serde_json::from_slice(&bytes).expect("parse");
        for blob in named(&previous) {
            assert!(
                world.blobs().size(&blob).expect("size").is_some(),
                "the previous manifest names {blob}, which is not stored"
            );
        }
    }
    (*manifest).clone()
}

/// Everything that says which tree a world holds: the BVH itself as JSON, its generation,
/// size, the map between world and tree ids, and cuts from several viewpoints.
#[derive(Debug, PartialEq)]
struct TreeState {
    json: String,
    generation: u64,
    objects: usize,
    nodes: usize,
    height: u32,
    ids: Vec<(u64, Option<u32>)>,
    cuts: Vec<horizon_bvh::Cut>,
}

/// The ids of every object of `world`.
fn object_ids(world: &World) -> Vec<u64> {
    world
        .all_objects()
        .expect("objects")
        .iter()
        .map(|o| o.id)
        .collect()
}

fn tree_state(world: &World) -> TreeState {
    let ids: Vec<u64> = object_ids(world);
    world
        .with_tree(|t| {
            t.bvh.validate().expect("the tree validates");
            let cuts = [
                (Vec3::new(0.0, 2.0, 0.0), 1e-3),
                (Vec3::new(40.0, 10.0, 40.0), 1e-3),
                (Vec3::new(-25.0, 1.5, 5.0), 1e-2),
                (Vec3::new(5.0, 100.0, -5.0), 1e-4),
            ]
            .iter()
            .map(|&(position, min_solid_angle)| {
                t.bvh.cut(&CutQuery {
                    position,
                    min_solid_angle,
                    max_results: 4000,
                })
            })
            .collect();
            TreeState {
                json: serde_json::to_string(&t.bvh).expect("serialise"),
                generation: t.generation,
                objects: t.bvh.len(),
                nodes: t.bvh.node_count(),
                height: t.bvh.height(),
                ids: ids
                    .iter()
                    .map(|&id| (id, t.tree_id(id).map(|o| o.0)))
                    .collect(),
                cuts,
            }
        })
        .expect("the tree")
}

/// Applies `steps` seeded changes, each batch as the world (`None`) or as `user`, touching
/// only what the actor may touch. Returns how many generations they made.
fn seeded_changes(world: &World, user: &str, seed: u64, steps: usize) -> u64 {
    let mut rng = Rng::new(seed);
    let model_ids: Vec<String> = world
        .models_page(None, 100)
        .expect("models")
        .into_iter()
        .map(|m| m.id)
        .collect();
    let before = world.status().expect("status").generation;
    for _ in 0..steps {
        let actor = if rng.unit() < 0.5 { None } else { Some(user) };
        let mine: Vec<u64> = world
            .all_objects()
            .expect("objects")
            .into_iter()
            .filter(|o| actor.is_none() || o.owner.as_deref() == actor)
            .map(|o| o.id)
            .collect();
        let batch = 1 + (rng.unit() * 3.0) as usize;
        let mut changes = Vec::new();
        let mut gone = HashSet::new();
        for _ in 0..batch {
            let pick = rng.unit();
            let target = mine
                .get(((rng.unit() * mine.len() as f32) as usize).min(mine.len().max(1) - 1))
                .copied()
                .filter(|id| !gone.contains(id));
            match target {
                Some(id) if pick < 0.3 => {
                    gone.insert(id);
                    changes.push(Change::Delete { id });
                }
                Some(id) if pick < 0.65 => changes.push(Change::Move {
                    id,
                    transform: placement(&mut rng),
                }),
                _ => {
                    let m = ((rng.unit() * model_ids.len() as f32) as usize).min(2);
                    changes.push(Change::Create {
                        model: model_ids[m].clone(),
                        transform: placement(&mut rng),
                    });
                }
            }
        }
        world.apply(actor, &changes).expect("apply");
    }
    world.status().expect("status").generation - before
}

fn user(name: &str) -> User {
    User {
        name: name.into(),
        max_objects: None,
        max_bytes: None,
    }
}

// -------------------------------------------------------------------------------------------
// Create, build, publish
// -------------------------------------------------------------------------------------------

#[test]
fn create_describe_build_and_publish() {
    let dir = TempDir::new("publish");
    let world = World::create(dir.path(), "test", 1, &models(), &objects(30, 3)).expect("create");
    let s = world.status().expect("status");
    assert_eq!(
        (s.generation, s.published, s.objects, s.models),
        (30, 0, 30, 3)
    );
    assert_eq!(world.identity().expect("identity"), ("test".to_owned(), 1));
    assert_eq!(world.describe_models(&|_, _| {}).expect("describe"), 3);
    assert_eq!(world.describe_models(&|_, _| {}).expect("again"), 0);
    let (objects, nodes, _height) = world.build_tree(DEFAULT_MU, DEFAULT_W).expect("tree");
    assert_eq!(objects, 30);
    assert!(nodes > 1);
    let report = rebuild(&world);
    assert_eq!(report.generation, 30);
    assert!(report.build.built > 0);
    let s = world.status().expect("status");
    assert_eq!((s.generation, s.published, s.dirty_nodes), (30, 30, 0));
    assert!(s.last_rebuild_ms.is_some());
    assert!(s.bounds.is_some());
    let manifest = check_published(&world);
    assert_eq!(manifest.nodes.len(), report.build.nodes);
    assert_eq!(manifest.nodes.len(), nodes);
    // Creating over a world is refused.
    drop(world);
    assert!(World::create(dir.path(), "again", 2, &models(), &[]).is_err());
}

// -------------------------------------------------------------------------------------------
// Replay
// -------------------------------------------------------------------------------------------

#[test]
fn replay_after_reopening_gives_the_very_same_tree() {
    let dir = TempDir::new("replay");
    let world = built_world(dir.path(), 30);
    rebuild(&world);
    let token = world.create_token(&user("ann")).expect("token");
    let ann = world
        .user_of_token(&token)
        .expect("lookup")
        .expect("ann's token")
        .name;
    let made = seeded_changes(&world, &ann, 5, 25);
    assert!(made >= 25);
    // Both actors placed, moved and deleted objects.
    let owners: HashSet<Option<String>> = world
        .all_objects()
        .expect("objects")
        .into_iter()
        .map(|o| o.owner)
        .collect();
    assert!(owners.contains(&Some(ann.clone())) && owners.contains(&None));
    let published = rebuild(&world);
    let before = tree_state(&world);
    assert_eq!(
        before.generation,
        world.status().expect("status").generation
    );
    drop(world);

    let world = World::open(dir.path()).expect("reopen");
    world.ensure_tree().expect("replay");
    let after = tree_state(&world);
    assert_eq!(after.generation, before.generation);
    assert_eq!(
        (after.objects, after.nodes, after.height),
        (before.objects, before.nodes, before.height)
    );
    assert_eq!(after.ids, before.ids);
    assert!(after.cuts == before.cuts, "the cuts differ after replay");
    assert!(after.json == before.json, "the tree differs after replay");
    let s = world.status().expect("status");
    assert_eq!(
        (s.generation, s.published),
        (before.generation, before.generation)
    );
    let again = rebuild(&world);
    assert_eq!(again.generation, published.generation);
    assert_eq!(again.build.built, 0, "a replayed tree rebuilds nothing");
    assert_eq!(again.build.reused, published.build.nodes);

    // Changes not yet published when the world closes: replayed the same, due at once, and
    // published by the next rebuild.
    let made = seeded_changes(&world, &ann, 6, 10);
    let before = tree_state(&world);
    drop(world);
    let world = World::open(dir.path()).expect("reopen");
    let s = world.status().expect("status");
    assert_eq!(s.generation, before.generation);
    assert_eq!(s.published, before.generation - made);
    assert!(world
        .wait_for_rebuild(
            std::time::Duration::ZERO,
            std::time::Duration::ZERO,
            std::time::Duration::from_secs(5),
            &|| false
        )
        .expect("wait"));
    world.ensure_tree().expect("replay");
    let after = tree_state(&world);
    assert!(after == before, "the tree differs after replay");
    let report = rebuild(&world);
    assert_eq!(report.generation, before.generation);
    assert_eq!(world.status().expect("status").published, before.generation);
    check_published(&world);
}

#[test]
fn a_new_tree_snapshot_replaces_the_old_one_in_the_store() {
    let dir = TempDir::new("snapshot");
    let world = built_world(dir.path(), 20);
    rebuild(&world);
    let first = world
        .meta()
        .snapshot()
        .expect("snapshot")
        .expect("a built tree has a snapshot");
    let ids: Vec<u64> = object_ids(&world);
    let mut rng = Rng::new(21);
    let moves: Vec<Change> = (0..SNAPSHOT_EVERY as usize)
        .map(|k| Change::Move {
            id: ids[k % ids.len()],
            transform: placement(&mut rng),
        })
        .collect();
    world.apply(None, &moves).expect("moves");
    rebuild(&world);
    let second = world
        .meta()
        .snapshot()
        .expect("snapshot")
        .expect("still a snapshot");
    assert!(
        second.generation >= first.generation + SNAPSHOT_EVERY,
        "a rebuild {SNAPSHOT_EVERY} generations on takes a new snapshot"
    );
    assert_ne!(second.blob, first.blob);
    assert!(world.blob(&second.blob).expect("read").is_some());
    assert_eq!(
        world.blob(&first.blob).expect("read"),
        None,
        "the snapshot replaced is deleted, not left for the next open"
    );
    let before = tree_state(&world);
    drop(world);
    let world = World::open(dir.path()).expect("reopen");
    world.ensure_tree().expect("the new snapshot loads");
    assert!(
        tree_state(&world) == before,
        "the tree differs after reopening"
    );
}

#[test]
fn a_world_started_empty_keeps_its_objects_in_the_tree_across_a_reopen() {
    // What `horizon serve` does on a new folder: an empty world, models uploaded, objects
    // placed, the process stopped (or killed) and started again.
    let dir = TempDir::new("empty-start");
    let world = World::open_or_create(dir.path()).expect("an empty world");
    world.ensure_tree().expect("an empty tree");
    let glb = export_glb(&models()[0].1, &ExportOptions::plain()).expect("glb");
    let (model, _) = world.upload_model(&glb, "crate", "ann").expect("upload");
    let mut rng = Rng::new(3);
    let changes: Vec<Change> = (0..10)
        .map(|_| Change::Create {
            model: model.id.clone(),
            transform: placement(&mut rng),
        })
        .collect();
    world.apply(Some("ann"), &changes).expect("place");
    let before = tree_state(&world);
    assert_eq!(before.objects, 10);
    drop(world);

    let world = World::open(dir.path()).expect("reopen");
    world
        .ensure_tree()
        .expect("the tree of a world that was never bulk-built loads after a reopen");
    let after = tree_state(&world);
    assert!(after == before, "the tree differs after replay");
}

// -------------------------------------------------------------------------------------------
// Changes during a build
// -------------------------------------------------------------------------------------------

#[test]
fn a_change_during_a_build_stays_dirty_for_the_next() {
    let dir = TempDir::new("during");
    let world = built_world(dir.path(), 24);
    rebuild(&world);
    let ids: Vec<u64> = object_ids(&world);

    // A change before the build.
    let first = world
        .apply(
            None,
            &[Change::Move {
                id: ids[0],
                transform: Affine3A::from_translation(Vec3::new(30.0, 0.0, 30.0)),
            }],
        )
        .expect("move")[0]
        .generation;
    let s = world.status().expect("status");
    assert_eq!(s.generation, first);
    assert!(s.published < first && s.dirty_nodes > 0);

    // A change while the build runs, from inside its progress callback.
    let once = AtomicBool::new(false);
    let during = AtomicU64::new(0);
    let report = world
        .rebuild_aggregates(AggregateOptions::default(), &|_| {
            if !once.swap(true, Ordering::SeqCst) {
                let a = world
                    .apply(
                        None,
                        &[Change::Move {
                            id: ids[1],
                            transform: Affine3A::from_translation(Vec3::new(-30.0, 0.0, -30.0)),
                        }],
                    )
                    .expect("move during the build");
                during.store(a[0].generation, Ordering::SeqCst);
            }
        })
        .expect("rebuild");
    let during = during.load(Ordering::SeqCst);
    assert!(during > first, "the change during the build was made");
    assert_eq!(
        report.generation, first,
        "the build published what it started from"
    );
    let s = world.status().expect("status");
    assert_eq!((s.generation, s.published), (during, first));
    assert!(
        s.dirty_nodes > 0,
        "the change during the build is still dirty"
    );
    check_published(&world);

    // It is due, and the next rebuild publishes it.
    assert!(world
        .wait_for_rebuild(
            std::time::Duration::ZERO,
            std::time::Duration::ZERO,
            std::time::Duration::from_secs(5),
            &|| false
        )
        .expect("wait"));
    let next = rebuild(&world);
    assert_eq!(next.generation, during);
    assert!(next.build.built > 0);
    let s = world.status().expect("status");
    assert_eq!(
        (s.generation, s.published, s.dirty_nodes),
        (during, during, 0)
    );
    check_published(&world);
    // Nothing more is due.
    assert!(!world
        .wait_for_rebuild(
            std::time::Duration::ZERO,
            std::time::Duration::ZERO,
            std::time::Duration::from_millis(50),
            &|| false
        )
        .expect("wait"));
}

#[test]
fn a_change_the_tree_cannot_take_is_not_committed() {
    // A world created with models but no objects (never described): its tree is empty, and
    // placing a model that has no descriptors cannot go into it. The change must then fail
    // whole, as World::apply promises, not commit in the database behind the tree's back
    // (the client would be told it failed, and the log would hold a change that no replay
    // can apply).
    let dir = TempDir::new("undescribed");
    let world = World::create(dir.path(), "test", 1, &models(), &[]).expect("create");
    let model = world.models_page(None, 10).expect("models")[0].id.clone();
    let result = world.apply(
        None,
        &[Change::Create {
            model,
            transform: Affine3A::IDENTITY,
        }],
    );
    let s = world.status().expect("status");
    let in_tree = world.with_tree(|t| t.bvh.len()).expect("tree");
    let stored = world.meta().object_count().expect("count");
    match result {
        Ok(_) => assert_eq!((stored, in_tree, s.objects), (1, 1, 1)),
        Err(e) => assert_eq!(
            (
                stored,
                s.generation,
                world.meta().generation().expect("generation")
            ),
            (0, 0, 0),
            "apply failed ({e}) but committed the change"
        ),
    }
    drop(world);
    // Whatever happened, the world opens and loads its tree.
    let world = World::open(dir.path()).expect("reopen");
    world.ensure_tree().expect("the tree loads");
}

// -------------------------------------------------------------------------------------------
// Garbage collection
// -------------------------------------------------------------------------------------------

#[test]
fn rebuilds_keep_what_the_published_manifests_name_and_collect_the_rest() {
    let dir = TempDir::new("gc");
    let world = built_world(dir.path(), 30);
    let model_assets: BTreeSet<String> = world
        .models_page(None, 100)
        .expect("models")
        .into_iter()
        .map(|m| m.asset)
        .collect();
    let mut manifests: Vec<AggregateManifest> = Vec::new();
    let mut hashes: Vec<String> = Vec::new();
    let mut rng = Rng::new(9);
    for round in 0..4 {
        if round > 0 {
            // Move a few objects far apart, so that the aggregates above them change.
            let ids: Vec<u64> = object_ids(&world);
            let changes: Vec<Change> = (0..3)
                .map(|k| Change::Move {
                    id: ids[(round * 7 + k * 5) % ids.len()],
                    transform: placement(&mut rng),
                })
                .collect();
            world.apply(None, &changes).expect("move");
        }
        let report = rebuild(&world);
        if round > 0 {
            assert!(report.build.built > 0, "round {round} rebuilt something");
        }
        let manifest = check_published(&world);
        let published = world.meta().published().expect("published");
        assert_eq!(published.generation, report.generation);
        assert_eq!(
            published.previous_manifest,
            hashes.last().cloned(),
            "round {round}: the manifest before is remembered"
        );
        hashes.push(published.manifest.clone().expect("manifest"));
        manifests.push(manifest);

        let n = manifests.len();
        let mut keep: BTreeSet<String> = named(&manifests[n - 1]);
        let mut keys: BTreeSet<String> = manifests[n - 1]
            .nodes
            .values()
            .map(|e| e.key.clone())
            .collect();
        if n >= 2 {
            keep.extend(named(&manifests[n - 2]));
            keys.extend(manifests[n - 2].nodes.values().map(|e| e.key.clone()));
        }
        let stored: BTreeSet<String> = world.blobs().list().expect("list").into_iter().collect();
        assert!(
            keep.is_subset(&stored),
            "round {round}: a named blob is missing"
        );
        // Aggregate blobs of builds before those two are gone.
        for old in manifests.iter().take(n.saturating_sub(2)) {
            for blob in named(old) {
                if !keep.contains(&blob) && !model_assets.contains(&blob) {
                    assert!(
                        !stored.contains(&blob),
                        "round {round}: {blob} of an older build is still stored"
                    );
                }
            }
        }
        // So are their manifests.
        for old in hashes.iter().take(n.saturating_sub(2)) {
            assert!(
                !stored.contains(old),
                "round {round}: the manifest {old} of an older build is still stored"
            );
        }
        // So are their entries.
        let entries: BTreeSet<String> = world
            .meta()
            .aggregate_entries()
            .expect("entries")
            .into_iter()
            .map(|(k, _)| k)
            .collect();
        assert!(
            entries.is_subset(&keys),
            "round {round}: entries of older builds remain: {:?}",
            entries.difference(&keys).collect::<Vec<_>>()
        );
    }
    // Something was collected over the rounds.
    let first_only: Vec<String> = named(&manifests[0])
        .difference(&named(&manifests[3]))
        .cloned()
        .collect();
    assert!(!first_only.is_empty(), "the rounds changed some aggregate");
    let stored: BTreeSet<String> = world.blobs().list().expect("list").into_iter().collect();
    assert!(first_only
        .iter()
        .filter(|b| !named(&manifests[2]).contains(*b))
        .all(|b| !stored.contains(b)));

    // At open, blobs nothing names and temporary files go; the published ones stay.
    let stray = world.blobs().put(b"nothing names me").expect("stray");
    let tmp = dir.path().join("blobs").join("ab").join(".x.1.2.tmp");
    std::fs::create_dir_all(tmp.parent().expect("fan")).expect("fan");
    std::fs::write(&tmp, b"half").expect("tmp");
    drop(world);
    let world = World::open(dir.path()).expect("reopen");
    assert_eq!(
        world.blob(&stray).expect("read"),
        None,
        "an orphan is removed at open"
    );
    assert!(!tmp.exists(), "a temporary file is swept at open");
    check_published(&world);
    for asset in &model_assets {
        assert!(world.blob(asset).expect("read").is_some());
    }
    world.ensure_tree().expect("the snapshot survived");
    assert_eq!(rebuild(&world).build.built, 0);
}

#[test]
fn forget_aggregates_makes_the_next_rebuild_build_everything() {
    let dir = TempDir::new("forget");
    let world = built_world(dir.path(), 20);
    let first = rebuild(&world);
    world.forget_aggregates().expect("forget");
    let s = world.status().expect("status");
    assert_eq!(s.published, 0);
    assert!(world.published_manifest().expect("read").is_none());
    assert!(world
        .meta()
        .aggregate_entries()
        .expect("entries")
        .is_empty());
    for m in world.models_page(None, 100).expect("models") {
        assert!(world.blob(&m.asset).expect("read").is_some(), "models stay");
    }
    let again = rebuild(&world);
    assert_eq!(again.build.built, first.build.built);
    assert_eq!(again.build.reused, 0);
    check_published(&world);
}

// -------------------------------------------------------------------------------------------
// Opening other processes' worlds
// -------------------------------------------------------------------------------------------

#[test]
fn opening_a_world_another_process_serves_does_not_delete_its_writes_in_flight() {
    // `horizon token create` opens the world while `horizon serve` runs on it (DESIGN,
    // "Outputs that tools parse"). The server may be between writing a blob and recording
    // it (an upload's GLB before its model row, a rebuild's staged level before its commit,
    // a manifest before its publish); a second open must not remove those.
    let dir = TempDir::new("second-open");
    let server = built_world(dir.path(), 12);
    rebuild(&server);
    let staged = server
        .blobs()
        .stage(b"a rebuild's staged aggregate")
        .expect("stage");
    let written = server
        .blobs()
        .put(b"an upload's GLB, not yet recorded")
        .expect("put");

    let tokens = World::open_or_create(dir.path()).expect("the second open");
    tokens.create_token(&user("bob")).expect("token");
    drop(tokens);

    assert!(
        server.blob(&written).expect("read").is_some(),
        "the second open deleted a blob the server had just written"
    );
    server
        .blobs()
        .commit_staged()
        .expect("the server's staged blobs survive another process opening the world");
    assert!(server.blob(&staged).expect("read").is_some());
}

// -------------------------------------------------------------------------------------------
// The format-1 upgrade
// -------------------------------------------------------------------------------------------

/// Writes a format-1 world (the layout `horizon-lab gen world` wrote before the database):
/// two models and `n` objects. Returns the objects' transforms.
fn write_legacy(dir: &Path, n: usize) -> Vec<(String, [f32; 12])> {
    std::fs::create_dir_all(dir.join("models")).expect("models folder");
    let m = models();
    let hashes = [
        "0123456789abcdef0123456789abcdef",
        "fedcba9876543210fedcba9876543210",
    ];
    let mut records = Vec::new();
    for (k, hash) in hashes.iter().enumerate() {
        let glb = export_glb(&m[k].1, &ExportOptions::plain()).expect("glb");
        std::fs::write(dir.join("models").join(format!("{hash}.glb")), &glb).expect("model");
        records.push(serde_json::json!({"hash": hash, "name": m[k].0, "bytes": glb.len()}));
    }
    let mut rng = Rng::new(21);
    let objects: Vec<(String, [f32; 12])> = (0..n)
        .map(|i| {
            (
                hashes[i % 2].to_owned(),
                placement(&mut rng).to_cols_array(),
            )
        })
        .collect();
    let manifest = serde_json::json!({
        "format": 1, "name": "old", "seed": 5, "object_count": n, "model_count": 2,
        "models": records,
    });
    let list = serde_json::json!({
        "objects": objects.iter().enumerate().map(|(i, (model, transform))| {
            serde_json::json!({"id": i, "model": model, "transform": transform})
        }).collect::<Vec<_>>(),
    });
    std::fs::write(dir.join("world.json"), manifest.to_string()).expect("world.json");
    std::fs::write(dir.join("objects.json"), list.to_string()).expect("objects.json");
    objects
}

/// Every file under `dir` but the database and the blob folder, with its bytes.
fn legacy_files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, at: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(at).expect("read dir").flatten() {
            let p = e.path();
            let rel = p.strip_prefix(root).expect("under root").to_path_buf();
            let name = rel.to_string_lossy();
            // What the upgrade adds: the database, the blobs, the lock.
            if name.starts_with("world.db") || name.starts_with("blobs") || name == "world.lock" {
                continue;
            }
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.insert(rel, std::fs::read(&p).expect("read"));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

#[test]
fn a_format_1_world_is_upgraded_once_and_its_files_are_left_alone() {
    let dir = TempDir::new("legacy");
    let objects = write_legacy(dir.path(), 9);
    let files = legacy_files(dir.path());
    assert_eq!(files.len(), 4);

    let world = World::open(dir.path()).expect("upgrade");
    let s = world.status().expect("status");
    assert_eq!((s.objects, s.models, s.generation), (9, 2, 9));
    assert_eq!(world.identity().expect("identity"), ("old".to_owned(), 5));
    let models = world.models_page(None, 10).expect("models");
    let mut names: Vec<&str> = models.iter().map(|m| m.name.as_str()).collect();
    names.sort_unstable();
    assert_eq!(names, ["crate", "pillar"]);
    for m in &models {
        assert!(world.blob(&m.asset).expect("read").is_some());
    }
    let rows = world.all_objects().expect("objects");
    assert_eq!(rows.len(), 9);
    for (row, (_, transform)) in rows.iter().zip(&objects) {
        assert_eq!(row.transform.to_cols_array(), *transform);
        assert_eq!(row.owner, None);
    }
    // Objects of the same old model share one model.
    assert_eq!(rows[0].model, rows[2].model);
    assert_ne!(rows[0].model, rows[1].model);
    assert_eq!(
        legacy_files(dir.path()),
        files,
        "the old files are untouched"
    );
    drop(world);

    let world = World::open(dir.path()).expect("reopen");
    let s = world.status().expect("status");
    assert_eq!(
        (s.objects, s.models, s.generation),
        (9, 2, 9),
        "not upgraded twice"
    );
    assert_eq!(legacy_files(dir.path()), files);
    // It builds like any world.
    world.describe_models(&|_, _| {}).expect("describe");
    world.build_tree(DEFAULT_MU, DEFAULT_W).expect("tree");
    rebuild(&world);
    check_published(&world);
}

#[test]
fn an_upgraded_world_loads_its_tree_as_serve_does() {
    // `horizon serve` opens any format-1 folder, upgrading it, then loads the tree before
    // taking requests (`World::ensure_tree`, documented as "or, for a world never built, a
    // bulk build with the default weights").
    let dir = TempDir::new("legacy-serve");
    write_legacy(dir.path(), 6);
    let world = World::open(dir.path()).expect("upgrade");
    world
        .ensure_tree()
        .expect("the tree of an upgraded world loads");
    assert_eq!(world.with_tree(|t| t.bvh.len()).expect("tree"), 6);
}

#[test]
fn an_interrupted_upgrade_is_finished_by_the_next_open() {
    let dir = TempDir::new("legacy-interrupted");
    write_legacy(dir.path(), 8);
    // The second model's file is missing: the upgrade stops part of the way.
    let second = dir
        .path()
        .join("models")
        .join("fedcba9876543210fedcba9876543210.glb");
    let hidden = dir.path().join("hidden.glb");
    std::fs::rename(&second, &hidden).expect("hide");
    assert!(World::open(dir.path()).is_err(), "a model is missing");
    std::fs::rename(&hidden, &second).expect("restore");
    match World::open(dir.path()) {
        Ok(world) => {
            let s = world.status().expect("status");
            assert_eq!(
                (s.objects, s.models),
                (8, 2),
                "the open after a failed upgrade holds every object and model"
            );
        }
        Err(e) => panic!("the upgrade is not retried: {e}"),
    }
}

// -------------------------------------------------------------------------------------------
// Uploads
// -------------------------------------------------------------------------------------------

#[test]
fn the_same_upload_from_8_threads_is_one_model_stored_once() {
    let dir = TempDir::new("upload");
    let world = World::open_or_create(dir.path()).expect("empty world");
    let glb = export_glb(&models()[2].1, &ExportOptions::plain()).expect("glb");
    let results: Vec<(horizon_world::ModelRow, bool)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..8)
            .map(|_| s.spawn(|| world.upload_model(&glb, "tent", "ann").expect("upload")))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect()
    });
    let first = &results[0].0;
    assert!(results.iter().all(|(row, _)| row == first));
    assert_eq!(results.iter().filter(|(_, created)| *created).count(), 1);
    assert_eq!(first.id, horizon_world::content_hash(&glb));
    assert_eq!(first.number, 0);
    assert_eq!(first.owner.as_deref(), Some("ann"));
    assert_eq!(world.status().expect("status").models, 1);
    assert_eq!(world.models().len(), 1);
    assert_eq!(
        world.blobs().list().expect("list"),
        std::slice::from_ref(&first.asset)
    );
    assert!(world
        .meta()
        .descriptors(&first.asset)
        .expect("read")
        .is_some());
    // Uploaded again later: found.
    let (again, created) = world
        .upload_model(&glb, "other name", "bob")
        .expect("again");
    assert!(!created);
    assert_eq!(&again, first);
    // And it can be placed.
    world
        .apply(
            Some("ann"),
            &[Change::Create {
                model: first.id.clone(),
                transform: Affine3A::IDENTITY,
            }],
        )
        .expect("place");
}

#[test]
fn different_uploads_from_8_threads_all_arrive() {
    let dir = TempDir::new("uploads");
    let world = World::open_or_create(dir.path()).expect("empty world");
    let glbs: Vec<Vec<u8>> = (0..8)
        .map(|i| {
            let m = cuboid(
                Vec3::new(1.0 + i as f32 * 0.3, 1.0, 1.0),
                [0.1 * i as f32, 0.5, 0.5, 1.0],
            );
            export_glb(&m, &ExportOptions::plain()).expect("glb")
        })
        .collect();
    let rows: Vec<horizon_world::ModelRow> = std::thread::scope(|s| {
        let handles: Vec<_> = glbs
            .iter()
            .map(|glb| s.spawn(|| world.upload_model(glb, "box", "ann")))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread").expect("upload"))
            .map(|(row, created)| {
                assert!(created);
                row
            })
            .collect()
    });
    let numbers: BTreeSet<u64> = rows.iter().map(|r| r.number).collect();
    assert_eq!(numbers, (0..8).collect());
    assert_eq!(world.models().len(), 8);
    for row in &rows {
        assert_eq!(&world.models().row(row.number).expect("row"), row);
    }
}

#[test]
fn bad_bytes_are_refused_and_change_nothing() {
    let dir = TempDir::new("bad-upload");
    let world = World::open_or_create(dir.path()).expect("empty world");
    let glb = export_glb(&models()[0].1, &ExportOptions::plain()).expect("glb");
    let bad: Vec<Vec<u8>> = vec![
        Vec::new(),
        b"not a model".to_vec(),
        b"{\"asset\": {\"version\": \"2.0\"}, \"buffers\": [{\"uri\": \"file:///etc/passwd\", \"byteLength\": 4}]}".to_vec(),
        glb[..glb.len() / 2].to_vec(),
        {
            let mut g = glb.clone();
            g[0] = b'X';
            g
        },
    ];
    for bytes in &bad {
        match world.upload_model(bytes, "bad", "ann") {
            Err(WorldError::BadModel { kind, .. }) => assert_eq!(kind, BadModel::Malformed),
            other => panic!("{} bytes: expected BadModel, got {other:?}", bytes.len()),
        }
    }
    let s = world.status().expect("status");
    assert_eq!((s.models, s.objects, s.generation), (0, 0, 0));
    assert!(
        world.blobs().list().expect("list").is_empty(),
        "nothing stored"
    );
    assert!(world.models_page(None, 10).expect("models").is_empty());
    // The good bytes still go in afterwards.
    world.upload_model(&glb, "crate", "ann").expect("good");
}

#[test]
fn a_byte_quota_refuses_an_upload() {
    let dir = TempDir::new("quota");
    let world = World::open_or_create(dir.path()).expect("empty world");
    world
        .create_token(&User {
            name: "ann".into(),
            max_objects: Some(2),
            max_bytes: Some(10),
        })
        .expect("token");
    let glb = export_glb(&models()[0].1, &ExportOptions::plain()).expect("glb");
    assert!(matches!(
        world.upload_model(&glb, "crate", "ann"),
        Err(WorldError::QuotaExceeded(_))
    ));
    assert_eq!(world.status().expect("status").models, 0);
    // The world's objects quota holds through World::apply too.
    let (row, _) = world
        .upload_model(&glb, "crate", "bob")
        .expect("bob has none");
    let place = Change::Create {
        model: row.id.clone(),
        transform: Affine3A::IDENTITY,
    };
    world
        .apply(Some("ann"), &[place.clone(), place.clone()])
        .expect("two");
    assert!(matches!(
        world.apply(Some("ann"), &[place]),
        Err(WorldError::QuotaExceeded(_))
    ));
    let s = world.status().expect("status");
    assert_eq!((s.objects, s.generation), (2, 2));
    assert_eq!(world.with_tree(|t| t.bvh.len()).expect("tree"), 2);
}

#[test]
fn tokens_are_random_and_only_their_hash_is_kept() {
    let dir = TempDir::new("tokens");
    let world = World::open_or_create(dir.path()).expect("empty world");
    let a = world.create_token(&user("ann")).expect("token");
    let b = world.create_token(&user("ann")).expect("token");
    assert_ne!(a, b);
    assert_eq!(a.len(), 64);
    assert_eq!(world.user_of_token(&a).expect("lookup"), Some(user("ann")));
    assert_eq!(world.user_of_token(&b).expect("lookup"), Some(user("ann")));
    assert_eq!(world.user_of_token("nope").expect("lookup"), None);
    assert!(world.create_token(&user("")).is_err());
    assert!(world.create_token(&user("a\nb")).is_err());
    drop(world);
    let db = std::fs::read(dir.path().join("world.db")).expect("db");
    let text = String::from_utf8_lossy(&db);
    assert!(!text.contains(&a), "the token itself is not stored");
}

// -------------------------------------------------------------------------------------------
// Folders that hold no world
// -------------------------------------------------------------------------------------------

#[test]
fn open_or_create_starts_an_empty_world_in_a_missing_folder() {
    let dir = TempDir::new("missing");
    let path = dir.path().join("a").join("new-world");
    let world = World::open_or_create(&path).expect("an empty world");
    let s = world.status().expect("status");
    assert_eq!(
        (s.generation, s.published, s.objects, s.models),
        (0, 0, 0, 0)
    );
    assert_eq!(s.bounds, None);
    assert_eq!(world.identity().expect("identity").0, "new-world");
    world.ensure_tree().expect("an empty tree");
    assert_eq!(world.with_tree(|t| t.bvh.len()).expect("tree"), 0);
    assert!(path.join("world.db").is_file());
    drop(world);
    // And again: the same world, opened.
    let world = World::open_or_create(&path).expect("reopen");
    assert_eq!(world.identity().expect("identity").0, "new-world");
    // An empty existing folder is fine too.
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).expect("mkdir");
    World::open_or_create(&empty).expect("an empty folder");
}

#[test]
fn open_refuses_a_folder_that_is_not_a_world() {
    let dir = TempDir::new("not-a-world");
    std::fs::create_dir_all(dir.path()).expect("mkdir");
    std::fs::write(dir.path().join("notes.txt"), b"hello").expect("file");
    assert!(matches!(
        World::open(dir.path()),
        Err(WorldError::NotAWorld(_))
    ));
    assert!(matches!(
        World::open_or_create(dir.path()),
        Err(WorldError::NotAWorld(_))
    ));
    assert!(matches!(
        World::open(&dir.path().join("missing")),
        Err(WorldError::NotAWorld(_))
    ));
    // Nothing was written into it.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("dir")
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(names, ["notes.txt"]);
}
