//! The embedded stores through their traits: [`SqliteMeta`] as a [`MetaStore`] and [`BlobDir`]
//! as a [`BlobStore`], each on a temporary folder.

mod common;

use common::TempDir;

use std::path::Path;

use glam::{Affine3A, Vec3};
use horizon_world::store::{Mutation, NewModel, Snapshot};
use horizon_world::{
    content_hash, is_content_hash, Applied, BlobDir, BlobStore, MetaStore, ModelDescriptors,
    Published, SqliteMeta, User, WorldError,
};

fn meta(dir: &TempDir) -> SqliteMeta {
    SqliteMeta::open(&dir.path().join("world.db"), "test", 7).expect("open the database")
}

fn stats() -> serde_json::Value {
    serde_json::json!({"triangles": 12})
}

/// Adds a model with a made-up id (`tag` hashed) and `bytes`, for `owner`.
fn add(
    meta: &dyn MetaStore,
    tag: &str,
    owner: Option<&str>,
    bytes: u64,
) -> Result<(horizon_world::ModelRow, bool), WorldError> {
    let id = content_hash(tag.as_bytes());
    let asset = content_hash(format!("glb of {tag}").as_bytes());
    meta.add_model(NewModel {
        descriptors: None,
        levels: None,
        id: &id,
        asset: &asset,
        name: tag,
        owner,
        bytes,
        stats: &stats(),
    })
}

fn at(x: f32) -> Affine3A {
    Affine3A::from_translation(Vec3::new(x, 0.0, 0.0))
}

fn create(model: u64, x: f32) -> Mutation {
    Mutation::Create {
        model,
        transform: at(x),
    }
}

fn user(name: &str, max_objects: Option<u64>, max_bytes: Option<u64>) -> User {
    User {
        name: name.into(),
        max_objects,
        max_bytes,
    }
}

// -------------------------------------------------------------------------------------------
// SqliteMeta
// -------------------------------------------------------------------------------------------

#[test]
fn a_new_database_records_its_identity_at_generation_zero() {
    let dir = TempDir::created("identity");
    let m = meta(&dir);
    assert_eq!(m.identity().expect("identity"), ("test".to_owned(), 7));
    assert_eq!(m.generation().expect("generation"), 0);
    assert_eq!(m.model_count().expect("count"), 0);
    assert_eq!(m.object_count().expect("count"), 0);
    assert!(m.log_after(0).expect("log").is_empty());
    assert_eq!(m.published().expect("published"), Published::default());
    assert_eq!(m.snapshot().expect("snapshot"), None);
    drop(m);
    // Reopening keeps the identity it was created with, whatever the caller passes.
    let again = SqliteMeta::open(&dir.path().join("world.db"), "other", 99).expect("reopen");
    assert_eq!(again.identity().expect("identity"), ("test".to_owned(), 7));
}

#[test]
fn add_model_adds_once_and_numbers_densely_from_zero() {
    let dir = TempDir::created("models");
    let m = meta(&dir);
    let (a, added) = add(&m, "a", None, 100).expect("add a");
    assert!(added);
    assert_eq!(a.number, 0);
    assert_eq!(a.id, content_hash(b"a"));
    assert_eq!(a.name, "a");
    assert_eq!(a.bytes, 100);
    assert_eq!(a.stats, stats());
    let (again, added) = add(&m, "a", Some("someone"), 5).expect("add a again");
    assert!(!added, "the same id is found, not added");
    assert_eq!(again, a, "the row first added is returned unchanged");
    let (b, _) = add(&m, "b", Some("bob"), 10).expect("add b");
    let (c, _) = add(&m, "c", None, 10).expect("add c");
    assert_eq!((b.number, c.number), (1, 2));
    assert_eq!(b.owner.as_deref(), Some("bob"));
    assert_eq!(m.model_count().expect("count"), 3);
    let numbers: Vec<u64> = m
        .models()
        .expect("models")
        .iter()
        .map(|r| r.number)
        .collect();
    assert_eq!(numbers, [0, 1, 2]);
    assert_eq!(m.model(&b.id).expect("model"), Some(b.clone()));
    assert_eq!(m.model(&content_hash(b"nothing")).expect("model"), None);

    // Pages are in id order, after the given id.
    let mut ids = [a.id.clone(), b.id.clone(), c.id.clone()];
    ids.sort();
    let page: Vec<String> = m
        .models_page(None, 2)
        .expect("page")
        .into_iter()
        .map(|r| r.id)
        .collect();
    assert_eq!(page, ids[..2]);
    let rest: Vec<String> = m
        .models_page(Some(&ids[1]), 10)
        .expect("page")
        .into_iter()
        .map(|r| r.id)
        .collect();
    assert_eq!(rest, ids[2..]);
}

#[test]
fn descriptors_round_trip() {
    let dir = TempDir::created("descriptors");
    let m = meta(&dir);
    let d = ModelDescriptors {
        zernike: (0..121).map(|i| i as f32 * 0.5).collect(),
        csd: (0..32).map(|i| 1.0 / (i + 1) as f32).collect(),
        centre: [1.0, -2.5, 3.25],
        radius: 4.5,
    };
    let asset = content_hash(b"asset");
    assert_eq!(m.descriptors(&asset).expect("none yet"), None);
    m.put_descriptors(&asset, &d).expect("put");
    assert_eq!(m.descriptors(&asset).expect("read"), Some(d));
}

#[test]
fn max_bytes_is_checked_when_a_user_adds_a_model() {
    let dir = TempDir::created("max-bytes");
    let m = meta(&dir);
    m.add_token(&user("ann", None, Some(100)), &content_hash(b"t1"))
        .expect("token");
    add(&m, "a", Some("ann"), 60).expect("60 of 100 bytes");
    let over = add(&m, "b", Some("ann"), 50);
    assert!(
        matches!(over, Err(WorldError::QuotaExceeded(_))),
        "110 of 100 bytes: {over:?}"
    );
    assert_eq!(m.model_count().expect("count"), 1, "nothing was added");
    add(&m, "c", Some("ann"), 40).expect("exactly 100 of 100 bytes");
    // The world and users without a limit are not held to ann's.
    add(&m, "d", None, 1000).expect("the world has no quota");
    add(&m, "e", Some("nolimit"), 1000).expect("an unknown user has no quota");
    // A model already stored is found, not added, so it costs nothing.
    let (row, added) = add(&m, "d", Some("ann"), 1000).expect("found");
    assert!(!added);
    assert_eq!(row.owner, None);
    // The numbers stayed dense over the refusal.
    let numbers: Vec<u64> = m
        .models()
        .expect("models")
        .iter()
        .map(|r| r.number)
        .collect();
    assert_eq!(numbers, [0, 1, 2, 3]);
}

#[test]
fn check_model_quota_refuses_what_add_model_would() {
    let dir = TempDir::created("check-quota");
    let m = meta(&dir);
    m.add_token(&user("ann", None, Some(100)), &content_hash(b"t1"))
        .expect("token");
    m.check_model_quota("ann", 100).expect("100 of 100");
    add(&m, "a", Some("ann"), 70).expect("70 of 100");
    m.check_model_quota("ann", 30).expect("exactly 100");
    assert!(matches!(
        m.check_model_quota("ann", 31),
        Err(WorldError::QuotaExceeded(_))
    ));
    assert!(add(&m, "b", Some("ann"), 31).is_err(), "add_model agrees");
    m.check_model_quota("bob", u64::MAX / 2)
        .expect("an unknown user has no quota");
}

#[test]
fn apply_makes_one_generation_per_mutation_and_logs_them_in_order() {
    let dir = TempDir::created("apply");
    let m = meta(&dir);
    add(&m, "a", None, 1).expect("a");
    add(&m, "b", None, 1).expect("b");
    let applied = m
        .apply(None, &[create(0, 1.0), create(1, 2.0), create(0, 3.0)])
        .expect("three creates");
    assert_eq!(
        applied.iter().map(|a| a.generation).collect::<Vec<_>>(),
        [1, 2, 3]
    );
    assert_eq!(m.generation().expect("generation"), 3);
    let ids: Vec<u64> = applied.iter().map(|a| a.object).collect();
    assert!(ids.windows(2).all(|w| w[0] < w[1]), "ids rise: {ids:?}");
    assert_eq!(applied[1].state, Some((1, at(2.0))));

    let moved = m
        .apply(
            None,
            &[
                Mutation::Move {
                    id: ids[0],
                    transform: at(10.0),
                },
                Mutation::Delete { id: ids[1] },
            ],
        )
        .expect("move and delete");
    assert_eq!(
        moved,
        [
            Applied {
                generation: 4,
                object: ids[0],
                state: Some((0, at(10.0))),
            },
            Applied {
                generation: 5,
                object: ids[1],
                state: None,
            },
        ]
    );
    let log = m.log_after(0).expect("log");
    assert_eq!(log.len(), 5);
    assert_eq!(log[..3], applied[..]);
    assert_eq!(log[3..], moved[..]);
    assert_eq!(m.log_after(3).expect("log after 3"), moved);
    assert!(m.log_after(5).expect("log after 5").is_empty());

    let row = m.object(ids[0]).expect("object").expect("present");
    assert_eq!((row.model, row.transform, row.generation), (0, at(10.0), 4));
    assert_eq!(row.owner, None);
    assert_eq!(m.object(ids[1]).expect("object"), None);
    assert_eq!(m.object_count().expect("count"), 2);

    // Everything is durable: a reopened database holds the same.
    drop(m);
    let m = meta(&dir);
    assert_eq!(m.generation().expect("generation"), 5);
    assert_eq!(m.log_after(0).expect("log").len(), 5);
    assert_eq!(m.object_count().expect("count"), 2);
}

#[test]
fn objects_page_in_id_order_and_by_owner() {
    let dir = TempDir::created("pages");
    let m = meta(&dir);
    add(&m, "a", None, 1).expect("a");
    let mut all = Vec::new();
    for i in 0..5 {
        let who = if i % 2 == 0 { Some("ann") } else { None };
        all.push((
            m.apply(who, &[create(0, i as f32)]).expect("create")[0].object,
            who,
        ));
    }
    let page = m.objects_page(None, 3, None).expect("page");
    assert_eq!(
        page.iter().map(|o| o.id).collect::<Vec<_>>(),
        all[..3].iter().map(|a| a.0).collect::<Vec<_>>()
    );
    let rest = m.objects_page(Some(page[2].id), 10, None).expect("rest");
    assert_eq!(
        rest.iter().map(|o| o.id).collect::<Vec<_>>(),
        all[3..].iter().map(|a| a.0).collect::<Vec<_>>()
    );
    let anns = m.objects_page(None, 10, Some("ann")).expect("ann's");
    assert_eq!(
        anns.iter().map(|o| o.id).collect::<Vec<_>>(),
        all.iter()
            .filter(|a| a.1.is_some())
            .map(|a| a.0)
            .collect::<Vec<_>>()
    );
    assert!(anns.iter().all(|o| o.owner.as_deref() == Some("ann")));
    let anns_after = m
        .objects_page(Some(anns[0].id), 1, Some("ann"))
        .expect("ann's after");
    assert_eq!(anns_after.len(), 1);
    assert_eq!(anns_after[0].id, anns[1].id);
}

/// Asserts that `result` is the refusal `matches` accepts and that nothing changed.
fn refused(
    m: &SqliteMeta,
    result: Result<Vec<Applied>, WorldError>,
    matches: fn(&WorldError) -> bool,
    generation: u64,
    objects: u64,
) {
    match result {
        Err(e) if matches(&e) => {}
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert_eq!(m.generation().expect("generation"), generation);
    assert_eq!(m.object_count().expect("count"), objects);
    assert_eq!(m.log_after(0).expect("log").len() as u64, generation);
}

#[test]
fn a_refused_mutation_applies_nothing_of_its_batch() {
    let dir = TempDir::created("refused");
    let m = meta(&dir);
    add(&m, "a", None, 1).expect("a");
    m.add_token(&user("ann", Some(3), None), &content_hash(b"ann"))
        .expect("ann");
    m.add_token(&user("bob", None, None), &content_hash(b"bob"))
        .expect("bob");
    let anns: Vec<u64> = m
        .apply(Some("ann"), &[create(0, 0.0), create(0, 1.0)])
        .expect("ann places two")
        .iter()
        .map(|a| a.object)
        .collect();
    let bobs = m.apply(Some("bob"), &[create(0, 5.0)]).expect("bob")[0].object;
    let worlds = m.apply(None, &[create(0, 9.0)]).expect("world")[0].object;
    let (g, n) = (4, 4);

    // An unknown model, after a good create.
    refused(
        &m,
        m.apply(Some("ann"), &[create(0, 2.0), create(7, 2.0)]),
        |e| matches!(e, WorldError::UnknownModel(_)),
        g,
        n,
    );
    // Someone else's object, after a good move.
    refused(
        &m,
        m.apply(
            Some("ann"),
            &[
                Mutation::Move {
                    id: anns[0],
                    transform: at(3.0),
                },
                Mutation::Move {
                    id: bobs,
                    transform: at(3.0),
                },
            ],
        ),
        |e| matches!(e, WorldError::Forbidden(_)),
        g,
        n,
    );
    refused(
        &m,
        m.apply(
            Some("ann"),
            &[
                Mutation::Delete { id: anns[1] },
                Mutation::Delete { id: worlds },
            ],
        ),
        |e| matches!(e, WorldError::Forbidden(_)),
        g,
        n,
    );
    // A missing object.
    refused(
        &m,
        m.apply(None, &[create(0, 2.0), Mutation::Delete { id: 999_999 }]),
        |e| matches!(e, WorldError::NotFound(_)),
        g,
        n,
    );
    // Over max_objects: ann owns 2 of 3, so two more are refused together.
    refused(
        &m,
        m.apply(Some("ann"), &[create(0, 2.0), create(0, 3.0)]),
        |e| matches!(e, WorldError::QuotaExceeded(_)),
        g,
        n,
    );
    assert_eq!(
        m.object(anns[0]).expect("read").expect("there").transform,
        at(0.0),
        "the refused batch's first move did not stick"
    );
    assert!(m.object(anns[1]).expect("read").is_some());

    // Within the quota, and a delete frees a place in the same batch.
    m.apply(Some("ann"), &[create(0, 2.0)])
        .expect("ann's third object");
    refused(
        &m,
        m.apply(Some("ann"), &[create(0, 3.0)]),
        |e| matches!(e, WorldError::QuotaExceeded(_)),
        g + 1,
        n + 1,
    );
    m.apply(
        Some("ann"),
        &[Mutation::Delete { id: anns[0] }, create(0, 3.0)],
    )
    .expect("a delete makes room");
    // The world may change anyone's object.
    m.apply(
        None,
        &[
            Mutation::Move {
                id: bobs,
                transform: at(6.0),
            },
            Mutation::Delete { id: anns[1] },
        ],
    )
    .expect("the world owns every object");
    assert_eq!(m.generation().expect("generation"), g + 5);
}

#[test]
fn object_ids_are_never_reused() {
    // An object's id names it for good (DESIGN: the entry id `o:<id>` never names two
    // different contents): deleting the newest object must not hand its id to the next one.
    let dir = TempDir::created("ids");
    let m = meta(&dir);
    add(&m, "a", None, 1).expect("a");
    let ids: Vec<u64> = m
        .apply(None, &[create(0, 0.0), create(0, 1.0), create(0, 2.0)])
        .expect("three")
        .iter()
        .map(|a| a.object)
        .collect();
    m.apply(None, &[Mutation::Delete { id: ids[2] }])
        .expect("delete the newest");
    let next = m.apply(None, &[create(0, 3.0)]).expect("one more")[0].object;
    assert!(
        next > ids[2],
        "object {next} reuses the id of a deleted object (ids so far {ids:?})"
    );
    // Also across a reopen.
    m.apply(None, &[Mutation::Delete { id: next }])
        .expect("delete it");
    drop(m);
    let m = meta(&dir);
    let after = m.apply(None, &[create(0, 4.0)]).expect("after reopen")[0].object;
    assert!(after > next, "object {after} reuses the id {next}");
}

#[test]
fn tokens_name_their_users_and_limits() {
    let dir = TempDir::created("tokens");
    let m = meta(&dir);
    let (t1, t2, t3) = (content_hash(b"1"), content_hash(b"2"), content_hash(b"3"));
    assert_eq!(m.user_of_token(&t1).expect("lookup"), None);
    m.add_token(&user("ann", Some(5), None), &t1).expect("ann");
    m.add_token(&user("bob", None, Some(1000)), &t2)
        .expect("bob");
    assert_eq!(
        m.user_of_token(&t1).expect("lookup"),
        Some(user("ann", Some(5), None))
    );
    assert_eq!(
        m.user_of_token(&t2).expect("lookup"),
        Some(user("bob", None, Some(1000)))
    );
    // A second token for ann updates her limits; both tokens are hers.
    m.add_token(&user("ann", None, Some(10)), &t3)
        .expect("ann again");
    for t in [&t1, &t3] {
        assert_eq!(
            m.user_of_token(t).expect("lookup"),
            Some(user("ann", None, Some(10)))
        );
    }
    assert_eq!(m.user_of_token(&content_hash(b"4")).expect("lookup"), None);
    // A token hash is stored once: giving the same one to another user fails.
    assert!(m.add_token(&user("eve", None, None), &t1).is_err());
    assert_eq!(
        m.user_of_token(&t1).expect("lookup").map(|u| u.name),
        Some("ann".to_owned())
    );
}

#[test]
fn aggregate_entries_are_put_and_retained() {
    let dir = TempDir::created("entries");
    let m = meta(&dir);
    assert!(m.aggregate_entries().expect("none").is_empty());
    let entries: Vec<(String, String)> = (0..5)
        .map(|i| (format!("key{i}"), format!("{{\"n\":{i}}}")))
        .collect();
    m.put_aggregate_entries(&entries).expect("put");
    m.put_aggregate_entries(&[]).expect("put nothing");
    let mut got = m.aggregate_entries().expect("entries");
    got.sort();
    assert_eq!(got, entries);
    // Putting a key again replaces its entry.
    m.put_aggregate_entries(&[("key0".into(), "{\"n\":10}".into())])
        .expect("replace");
    m.retain_aggregate_entries(&["key0".into(), "key3".into(), "missing".into()])
        .expect("retain");
    let mut got = m.aggregate_entries().expect("entries");
    got.sort();
    assert_eq!(
        got,
        [
            ("key0".to_owned(), "{\"n\":10}".to_owned()),
            ("key3".to_owned(), "{\"n\":3}".to_owned())
        ]
    );
    // Retaining twice in a row works (the scratch table is reused).
    m.retain_aggregate_entries(&["key3".into()])
        .expect("retain again");
    assert_eq!(m.aggregate_entries().expect("entries").len(), 1);
    m.retain_aggregate_entries(&[]).expect("retain none");
    assert!(m.aggregate_entries().expect("entries").is_empty());
}

#[test]
fn publish_replaces_what_is_published_durably() {
    let dir = TempDir::created("publish");
    let m = meta(&dir);
    let first = Published {
        generation: 3,
        manifest: Some(content_hash(b"m1")),
        previous_manifest: None,
        rebuild_ms: Some(12),
    };
    m.publish(&first).expect("publish");
    assert_eq!(m.published().expect("published"), first);
    let second = Published {
        generation: 9,
        manifest: Some(content_hash(b"m2")),
        previous_manifest: first.manifest.clone(),
        rebuild_ms: Some(40),
    };
    m.publish(&second).expect("publish");
    drop(m);
    assert_eq!(meta(&dir).published().expect("published"), second);
}

#[test]
fn put_snapshot_trims_the_log_up_to_its_generation() {
    let dir = TempDir::created("snapshot");
    let m = meta(&dir);
    add(&m, "a", None, 1).expect("a");
    let applied = m
        .apply(
            None,
            &(0..6).map(|i| create(0, i as f32)).collect::<Vec<_>>(),
        )
        .expect("six");
    let snapshot = Snapshot {
        generation: 4,
        blob: content_hash(b"tree"),
    };
    m.put_snapshot(&snapshot).expect("snapshot");
    assert_eq!(m.snapshot().expect("snapshot"), Some(snapshot));
    assert_eq!(m.log_after(0).expect("log"), applied[4..]);
    assert_eq!(m.log_after(4).expect("log"), applied[4..]);
    assert_eq!(m.generation().expect("generation"), 6, "unchanged");
    // Later changes are logged after it.
    let later = m.apply(None, &[create(0, 9.0)]).expect("one more");
    assert_eq!(later[0].generation, 7);
    assert_eq!(m.log_after(4).expect("log").len(), 3);
}

// -------------------------------------------------------------------------------------------
// BlobDir
// -------------------------------------------------------------------------------------------

/// Every file under `root`, as paths relative to it, sorted.
fn files(root: &Path) -> Vec<String> {
    fn walk(root: &Path, at: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(at) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.push(
                    p.strip_prefix(root)
                        .expect("under root")
                        .display()
                        .to_string(),
                );
            }
        }
    }
    let mut out = Vec::new();
    walk(root, root, &mut out);
    out.sort();
    out
}

#[test]
fn blobs_put_get_size_delete_list() {
    let dir = TempDir::created("blobs");
    let blobs = BlobDir::new(&dir.path().join("blobs"));
    assert!(blobs.list().expect("list of nothing").is_empty());
    let a = blobs.put(b"alpha").expect("put");
    assert_eq!(a, content_hash(b"alpha"));
    assert!(is_content_hash(&a));
    assert_eq!(blobs.put(b"alpha").expect("put again"), a);
    let b = blobs.put(b"beta, longer").expect("put");
    let empty = blobs.put(b"").expect("put nothing");
    assert_eq!(blobs.get(&a).expect("get"), Some(b"alpha".to_vec()));
    assert_eq!(blobs.size(&b).expect("size"), Some(12));
    assert_eq!(blobs.get(&empty).expect("get"), Some(Vec::new()));
    let mut all = vec![a.clone(), b.clone(), empty.clone()];
    all.sort();
    assert_eq!(blobs.list().expect("list"), all);
    // Stored fanned out by the first two digits, one file per blob.
    assert!(dir.path().join("blobs").join(&a[..2]).join(&a).is_file());
    assert_eq!(files(&dir.path().join("blobs")).len(), 3);

    blobs.delete(&a).expect("delete");
    blobs.delete(&a).expect("deleting twice is nothing");
    assert_eq!(blobs.get(&a).expect("get"), None);
    assert_eq!(blobs.size(&a).expect("size"), None);
    let missing = content_hash(b"never stored");
    assert_eq!(blobs.get(&missing).expect("get"), None);
    assert_eq!(blobs.size(&missing).expect("size"), None);
    blobs
        .delete(&missing)
        .expect("deleting a missing blob is nothing");
    let mut left = vec![b, empty];
    left.sort();
    assert_eq!(blobs.list().expect("list"), left);
}

#[test]
fn staged_blobs_appear_only_when_committed() {
    let dir = TempDir::created("stage");
    let root = dir.path().join("blobs");
    let blobs = BlobDir::new(&root);
    let kept = blobs.put(b"already stored").expect("put");
    let a = blobs.stage(b"staged a").expect("stage");
    let b = blobs.stage(b"staged b").expect("stage");
    assert_eq!(blobs.stage(b"staged a").expect("stage twice"), a);
    assert_eq!(blobs.stage(b"already stored").expect("stored"), kept);
    assert_eq!(a, content_hash(b"staged a"));
    for h in [&a, &b] {
        assert_eq!(blobs.get(h).expect("get"), None, "staged, not committed");
        assert_eq!(blobs.size(h).expect("size"), None);
    }
    assert_eq!(blobs.list().expect("list"), std::slice::from_ref(&kept));
    blobs.commit_staged().expect("commit");
    assert_eq!(blobs.get(&a).expect("get"), Some(b"staged a".to_vec()));
    assert_eq!(blobs.size(&b).expect("size"), Some(8));
    let mut all = vec![kept, a, b];
    all.sort();
    assert_eq!(blobs.list().expect("list"), all);
    blobs.commit_staged().expect("committing nothing");
    // Nothing but the blobs is left in the folder.
    assert_eq!(files(&root).len(), 3, "{:?}", files(&root));
    // Staged blobs never committed are dropped with the store.
    let c = blobs.stage(b"never committed").expect("stage");
    drop(blobs);
    assert_eq!(files(&root).len(), 3, "{:?}", files(&root));
    let blobs = BlobDir::new(&root);
    assert_eq!(blobs.get(&c).expect("get"), None);
}

#[test]
fn a_name_that_is_not_a_content_hash_finds_nothing_and_stays_inside() {
    let dir = TempDir::created("names");
    let root = dir.path().join("blobs");
    let blobs = BlobDir::new(&root);
    let a = blobs.put(b"inside").expect("put");
    // Files outside the blob folder, and one inside it under a non-hash name.
    std::fs::write(dir.path().join("secret"), b"outside").expect("secret");
    std::fs::write(dir.path().join("world.db"), b"not yours").expect("db");
    std::fs::write(root.join(&a[..2]).join("notes"), b"stray").expect("stray");
    let outside_fan = format!("../{}", &a[..2]);
    let bad = [
        "../secret".to_owned(),
        "../world.db".to_owned(),
        "/etc/passwd".to_owned(),
        "..".to_owned(),
        String::new(),
        "notes".to_owned(),
        a.to_uppercase(),
        format!("{a}0"),
        a[..63].to_owned(),
        format!("{}/../{}", &a[..2], a),
        format!("{outside_fan}/{a}"),
        format!("{}g", &a[..63]),
    ];
    for name in &bad {
        assert_eq!(blobs.get(name).expect("get"), None, "{name:?}");
        assert_eq!(blobs.size(name).expect("size"), None, "{name:?}");
        // Deleting it removes nothing, whether it says so or not.
        match blobs.delete(name) {
            Ok(()) | Err(WorldError::NotFound(_)) => {}
            Err(e) => panic!("delete {name:?}: {e}"),
        }
    }
    assert_eq!(
        std::fs::read(dir.path().join("secret")).expect("secret"),
        b"outside"
    );
    assert!(dir.path().join("world.db").is_file());
    assert!(root.join(&a[..2]).join("notes").is_file());
    assert_eq!(blobs.get(&a).expect("get"), Some(b"inside".to_vec()));
    // A stray file is not a blob.
    assert_eq!(blobs.list().expect("list"), [a]);
}

#[test]
fn sweep_removes_temporary_files_and_nothing_else() {
    let dir = TempDir::created("sweep");
    let root = dir.path().join("blobs");
    let blobs = BlobDir::new(&root);
    assert_eq!(blobs.sweep().expect("sweep of nothing"), 0);
    let a = blobs.put(b"keep me").expect("put");
    let fan = root.join(&a[..2]);
    // What an interrupted write leaves: `.NAME.PID.N.tmp` beside the blob.
    let tmp1 = fan.join(format!(".{a}.4242.0.tmp"));
    let tmp2 = root.join("ff").join(format!(".{}.1.7.tmp", "f".repeat(64)));
    std::fs::write(&tmp1, b"half a blo").expect("tmp1");
    std::fs::create_dir_all(tmp2.parent().expect("fan")).expect("fan");
    std::fs::write(&tmp2, b"").expect("tmp2");
    assert_eq!(
        blobs.list().expect("list"),
        std::slice::from_ref(&a),
        "temporaries are not blobs"
    );
    assert_eq!(blobs.sweep().expect("sweep"), 2);
    assert!(!tmp1.exists() && !tmp2.exists());
    assert_eq!(blobs.get(&a).expect("get"), Some(b"keep me".to_vec()));
    assert_eq!(blobs.sweep().expect("sweep again"), 0);
}

#[test]
fn concurrent_puts_of_the_same_bytes_store_one_blob() {
    let dir = TempDir::created("concurrent");
    let root = dir.path().join("blobs");
    let blobs = BlobDir::new(&root);
    let bytes: Vec<u8> = (0..200_000u32).map(|i| (i % 251) as u8).collect();
    let hashes: Vec<String> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..8)
            .map(|_| s.spawn(|| blobs.put(&bytes).expect("put")))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect()
    });
    assert!(hashes.iter().all(|h| *h == hashes[0]));
    assert_eq!(blobs.get(&hashes[0]).expect("get"), Some(bytes));
    assert_eq!(files(&root), [format!("{}/{}", &hashes[0][..2], hashes[0])]);
}
