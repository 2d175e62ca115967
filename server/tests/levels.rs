//! Levels of detail through the service (issue 28): a world of generated textured buildings
//! in a row running 3 km away from the origin, levelled by `World::level_models`, with its
//! aggregates published:
//! - every model lists its levels (level 0 its stored GLB), each served, coarser down the chain;
//! - an object entry's level rises with distance, is 0 everywhere with `max_pixel_error=0`, and
//!   its bytes, triangles and asset are the chosen level's; cuts stay complete on random views;
//! - over a real socket, a stream's level changes arrive as replacements (`refined` or
//!   `coarsened`, the addition naming the entry it replaces), and its cut stays complete;
//! - an instances entry whose models moved level is sent reusing the held entry's assets and
//!   placements, which filled in give the entry exactly;
//! - on a row of distinct buildings, the search that coarsens levels where a byte budget binds
//!   (`Coarsening::Search`, measured in the lab, not the service's default) keeps every object
//!   the plan at the view's own levels draws at its level, draws more, and takes the least step
//!   that does.

// A test's `unwrap` on a request it built or a reply it checks is an assertion.
#![allow(clippy::unwrap_used)]

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use futures_util::{SinkExt, StreamExt};
use glam::{Affine3A, Vec3};
use horizon_aggregate::AggregateOptions;
use horizon_mesh::rng::Rng;
use horizon_protocol::{
    ClientMessage, CutResponse, EntryKind, ModelInfo, RemoveReason, ServerMessage, StoppedBy, View,
};
use horizon_server::service::cut::{
    coarsening_step, plan_stopping, AssetTable, Coarsening, Drawn, Key, Plan, COARSENING_STEPS,
};
use horizon_server::service::{app, run, AppState, Config};
use horizon_world::World;
use tokio::net::TcpListener;
use tokio_tungstenite::tungstenite::Message;
use tower::ServiceExt;

struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Buildings per model and models.
const ROW: usize = 40;
const MODELS: usize = 3;

/// `MODELS` distinct buildings, each placed `ROW` times along +x from 20 m to about 3 km
/// (spacing growing by 13% a step), levelled and aggregated.
fn world(name: &str) -> (TempDir, Arc<World>) {
    let mut objects = Vec::new();
    for m in 0..MODELS {
        for k in 0..ROW {
            let x = 20.0 * 1.13f32.powi(k as i32);
            let z = 40.0 * m as f32;
            objects.push((m, Affine3A::from_translation(Vec3::new(x, 0.0, z))));
        }
    }
    built(name, 1, MODELS, &objects)
}

/// `n` distinct buildings, one of each, along +x from 20 m (spacing growing by 25% a step):
/// a world whose cut's bytes are its objects' own, levelled and aggregated.
fn distinct_row(name: &str, n: usize) -> (TempDir, Arc<World>) {
    let objects: Vec<(usize, Affine3A)> = (0..n)
        .map(|k| {
            let x = 20.0 * 1.25f32.powi(k as i32);
            (k, Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)))
        })
        .collect();
    built(name, 3, n, &objects)
}

/// A world of `models` distinct buildings (`distinct_building(seed, i)`) placed as `objects`
/// say, every model levelled (asserted) and the aggregates published.
fn built(
    name: &str,
    seed: u64,
    models: usize,
    objects: &[(usize, Affine3A)],
) -> (TempDir, Arc<World>) {
    let dir = std::env::temp_dir().join(format!("horizon-levels-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let dir = TempDir(dir);
    let buildings: Vec<(String, horizon_mesh::InstancedMesh)> = (0..models)
        .map(|i| {
            (
                format!("building-{i}"),
                horizon_worldgen::distinct_building(seed, i).unwrap(),
            )
        })
        .collect();
    let world = World::create(&dir.0, name, 1, &buildings, objects).unwrap();
    let (levelled, failures) = world.level_models(&|_, _| {}).unwrap();
    assert_eq!(levelled, models);
    assert!(failures.is_empty(), "{failures:?}");
    world
        .rebuild_aggregates(AggregateOptions::default(), &|_| {})
        .unwrap();
    (dir, Arc::new(world))
}

/// A seeded view over the row: from 100 m before its start to 500 m along it, 2 to 42 m up,
/// from 60 m to one side to 140 m to the other.
fn over_the_row(rng: &mut Rng) -> View {
    View::at([
        -100.0 + 600.0 * rng.unit_f64(),
        2.0 + 40.0 * rng.unit_f64(),
        -60.0 + 200.0 * rng.unit_f64(),
    ])
}

/// Moves `eye` a seeded step in a seeded direction, `shortest` to `shortest * range` long
/// (spread evenly in its logarithm), and never below 1 m up.
fn step(rng: &mut Rng, eye: &mut [f64; 3], shortest: f64, range: f64) {
    let dir = rng.unit_vector();
    let length = shortest * range.powf(rng.unit_f64());
    for i in 0..3 {
        eye[i] += f64::from(dir[i]) * length;
    }
    eye[1] = eye[1].max(1.0);
}

fn state(world: &Arc<World>) -> AppState {
    AppState::new(
        world.clone(),
        Config {
            rebuild: false,
            ..Config::default()
        },
    )
}

async fn get(app: &axum::Router, uri: &str) -> (StatusCode, Vec<u8>) {
    let r = app
        .clone()
        .oneshot(Request::get(uri).body(Body::empty()).unwrap())
        .await
        .unwrap();
    let status = r.status();
    let bytes = axum::body::to_bytes(r.into_body(), usize::MAX)
        .await
        .unwrap();
    (status, bytes.to_vec())
}

async fn cut(app: &axum::Router, query: &str) -> CutResponse {
    let (status, body) = get(app, &format!("/v1/cut?{query}")).await;
    assert_eq!(status, StatusCode::OK, "{query}");
    serde_json::from_slice(&body).unwrap()
}

async fn models(app: &axum::Router) -> HashMap<String, ModelInfo> {
    let (status, body) = get(app, "/v1/models").await;
    assert_eq!(status, StatusCode::OK);
    let page: horizon_protocol::ModelPage = serde_json::from_slice(&body).unwrap();
    page.models
        .into_iter()
        .map(|m| (m.asset.clone(), m))
        .collect()
}

/// A placement's translation, bit for bit.
fn translation(m: &[f32; 12]) -> [u32; 3] {
    [m[9].to_bits(), m[10].to_bits(), m[11].to_bits()]
}

/// `o:<id>@<placed>[/<level>]` -> id.
fn object_of(id: &str) -> u64 {
    id[2..id.find('@').unwrap()].parse().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn models_list_their_levels_and_every_level_is_served() {
    let (_dir, world) = world("list");
    let app = app(state(&world));
    let models = models(&app).await;
    assert_eq!(models.len(), MODELS);
    for m in models.values() {
        assert!(m.levels.len() >= 2, "{}: {} levels", m.name, m.levels.len());
        assert_eq!(m.levels[0].asset, m.asset);
        assert_eq!(m.levels[0].bytes, m.bytes);
        assert_eq!(m.levels[0].error, 0.0);
        for (k, pair) in m.levels.windows(2).enumerate() {
            let (a, b) = (&pair[0], &pair[1]);
            assert_eq!(b.level as usize, k + 1);
            assert!(b.error >= a.error && b.triangles <= a.triangles && b.bytes < a.bytes);
        }
        for l in &m.levels {
            let (status, body) = get(&app, &format!("/assets/{}", l.asset)).await;
            assert_eq!(status, StatusCode::OK);
            assert_eq!(body.len() as u64, l.bytes);
        }
        // The model's own page says the same.
        let (status, body) = get(&app, &format!("/v1/models/{}", m.id)).await;
        assert_eq!(status, StatusCode::OK);
        let one: ModelInfo = serde_json::from_slice(&body).unwrap();
        assert_eq!(&one, m);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn levels_rise_with_distance_and_cuts_stay_complete() {
    let (_dir, world) = world("choice");
    let app = app(state(&world));
    let models = models(&app).await;
    // Every object as itself: the levels alone decide what is sent. Under a triangle budget
    // each object is at its own level.
    let all = "min_solid_angle=1e-9&max_entries=100000&instances=false";
    let c = cut(&app, &format!("eye=0,2,0&{all}&max_triangles=1000000000")).await;
    assert_eq!(c.entries.len(), MODELS * ROW);
    // Drawn as instances, every object keeps the level its own entry has.
    let own: HashMap<[u32; 3], &str> = c
        .entries
        .iter()
        .map(|e| {
            (
                translation(&e.placements[0].matrix),
                e.assets[0].hash.as_str(),
            )
        })
        .collect();
    let grouped = cut(
        &app,
        "eye=0,2,0&min_solid_angle=1e-9&max_entries=100000&max_triangles=1000000000",
    )
    .await;
    let placed: Vec<&horizon_protocol::Placement> = grouped
        .entries
        .iter()
        .filter(|e| e.kind == EntryKind::Instances)
        .flat_map(|e| &e.placements)
        .collect();
    assert!(
        !placed.is_empty(),
        "no object of this cut is drawn as an instance"
    );
    for p in placed {
        assert_eq!(own[&translation(&p.matrix)], p.asset.as_str());
    }
    let mut by_model: HashMap<u64, Vec<(f32, u32)>> = HashMap::new();
    for e in &c.entries {
        assert_eq!(e.kind, EntryKind::Object);
        // The entry is its level: asset, bytes and triangles.
        let m = &models
            .values()
            .find(|m| m.levels.iter().any(|l| l.asset == e.assets[0].hash))
            .expect("an asset of some model's levels");
        let l = &m.levels[e.level as usize];
        assert_eq!(e.assets[0].hash, l.asset, "{}", e.id);
        assert_eq!((e.bytes, e.triangles), (l.bytes, l.triangles), "{}", e.id);
        assert_eq!(e.id.ends_with(&format!("/{}", e.level)), e.level > 0);
        let distance = Vec3::from_array(e.center).length();
        by_model
            .entry(m.levels.len() as u64 * 1000 + m.bytes)
            .or_default()
            .push((distance, e.level));
    }
    let mut levels_seen = HashSet::new();
    for row in by_model.values_mut() {
        row.sort_by(|a, b| a.0.total_cmp(&b.0));
        for pair in row.windows(2) {
            assert!(pair[1].1 >= pair[0].1, "level falls with distance: {row:?}");
        }
        levels_seen.extend(row.iter().map(|r| r.1));
    }
    assert!(levels_seen.contains(&0), "the nearest are at full detail");
    assert!(levels_seen.len() >= 3, "levels used: {levels_seen:?}");
    // No error allowed: full detail throughout.
    let full = cut(&app, &format!("eye=0,2,0&{all}&max_pixel_error=0")).await;
    assert!(full.entries.iter().all(|e| e.level == 0));
    // Without a triangle budget, the objects of a model share the finest level any of them
    // needs: one asset per model, never more bytes than without levels, and fewer from afar.
    let bytes = |c: &CutResponse| {
        let unique: HashMap<&str, u64> = c
            .entries
            .iter()
            .map(|e| (e.assets[0].hash.as_str(), e.bytes))
            .collect();
        assert_eq!(unique.len(), MODELS);
        unique.values().sum::<u64>()
    };
    for x in [0.0, -500.0, -5000.0] {
        let shared = cut(&app, &format!("eye={x},2,0&{all}")).await;
        let full = cut(&app, &format!("eye={x},2,0&{all}&max_pixel_error=0")).await;
        let own = cut(&app, &format!("eye={x},2,0&{all}&max_triangles=1000000000")).await;
        let finest: HashMap<String, u32> = own.entries.iter().fold(HashMap::new(), |mut f, e| {
            let m = models
                .values()
                .find(|m| m.levels.iter().any(|l| l.asset == e.assets[0].hash))
                .unwrap();
            let slot = f.entry(m.id.clone()).or_insert(e.level);
            *slot = (*slot).min(e.level);
            f
        });
        assert!(bytes(&shared) <= bytes(&full));
        let mut levels: Vec<u32> = shared.entries.iter().map(|e| e.level).collect();
        levels.sort_unstable();
        let mut expected: Vec<u32> = finest.values().flat_map(|&l| [l; ROW]).collect();
        expected.sort_unstable();
        assert_eq!(levels, expected, "from x = {x}");
        if x < -1000.0 {
            assert!(bytes(&shared) < bytes(&full), "from x = {x}");
        }
    }
    // Random views at the default solid angle: complete, every asset stored.
    let mut rng = Rng::new(3);
    for _ in 0..30 {
        let eye = [
            -200.0 + 3400.0 * rng.unit_f64(),
            1.0 + 300.0 * rng.unit_f64(),
            -300.0 + 600.0 * rng.unit_f64(),
        ];
        let c = cut(&app, &format!("eye={},{},{}", eye[0], eye[1], eye[2])).await;
        let ids: HashSet<&str> = c.entries.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids.len(), c.entries.len());
        assert_eq!(c.entries.iter().map(|e| e.covers).sum::<u64>(), c.objects);
        assert_eq!(c.objects, (MODELS * ROW) as u64);
        for e in &c.entries {
            let (status, _) = get(&app, &format!("/assets/{}", e.assets[0].hash)).await;
            assert_eq!(status, StatusCode::OK, "{}", e.id);
        }
    }
}

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// The next message, or none if the server sends nothing for `wait` (it had nothing to say).
async fn next(ws: &mut Ws, wait: Duration) -> Option<ServerMessage> {
    loop {
        let m = tokio::time::timeout(wait, ws.next()).await.ok()?;
        if let Message::Text(t) = m.expect("the stream is open").expect("a frame") {
            return Some(serde_json::from_str(&t).unwrap());
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_sends_level_changes_as_replacements() {
    let (_dir, world) = world("stream");
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(run(listener, state(&world), async move {
        let _ = stopped.await;
    }));
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/v1/stream"))
        .await
        .unwrap();
    let mut view = View::at([0.0, 2.0, 40.0]);
    view.min_solid_angle = 1e-9;
    view.budgets.max_entries = Some(100_000);
    let mut held: HashMap<String, horizon_protocol::Entry> = HashMap::new();
    let mut changes: HashMap<RemoveReason, usize> = HashMap::new();
    // Out along the row and back again.
    let path: Vec<f64> = (0..12)
        .map(|i| -100.0 * 1.5f64.powi(i))
        .chain((0..12).rev().map(|i| -100.0 * 1.5f64.powi(i)))
        .collect();
    for (id, x) in path.into_iter().enumerate() {
        view.eye[0] = x;
        let message = ClientMessage::View {
            id: id as u64 + 1,
            view,
        };
        ws.send(Message::Text(
            serde_json::to_string(&message).unwrap().into(),
        ))
        .await
        .unwrap();
        // Whatever the server says until it falls quiet (a bound against hanging, not a
        // timing assertion: a late message is applied with the next view's).
        let wait = if id == 0 { 30_000 } else { 700 };
        while let Some(m) = next(&mut ws, Duration::from_millis(wait)).await {
            match m {
                ServerMessage::Reset { entries, .. } => {
                    held = entries.into_iter().map(|e| (e.id.clone(), e)).collect();
                }
                ServerMessage::Delta { add, remove, .. } => {
                    let mut gone: HashMap<String, horizon_protocol::Entry> = HashMap::new();
                    for r in &remove {
                        let e = held.remove(&r.id).expect("removes what it sent");
                        gone.insert(r.id.clone(), e);
                    }
                    for a in add {
                        for r in &a.replaces {
                            let old = gone.get(r).expect("replaces what it removed");
                            let reason = remove.iter().find(|x| &x.id == r).unwrap().reason;
                            if old.kind == EntryKind::Object
                                && a.entry.kind == EntryKind::Object
                                && object_of(&old.id) == object_of(&a.entry.id)
                            {
                                // One object at another level: the reason says which way.
                                assert_ne!(old.level, a.entry.level);
                                let expected = if a.entry.level > old.level {
                                    RemoveReason::Coarsened
                                } else {
                                    RemoveReason::Refined
                                };
                                assert_eq!(reason, expected, "{} -> {}", old.id, a.entry.id);
                                *changes.entry(reason).or_default() += 1;
                            }
                        }
                        held.insert(a.entry.id.clone(), a.entry);
                    }
                    let covers: u64 = held.values().map(|e| e.covers).sum();
                    assert_eq!(covers, (MODELS * ROW) as u64, "the held cut is complete");
                }
                ServerMessage::Error { error } => panic!("{error:?}"),
            }
        }
    }
    assert!(
        changes.get(&RemoveReason::Coarsened).copied().unwrap_or(0) > 0
            && changes.get(&RemoveReason::Refined).copied().unwrap_or(0) > 0,
        "level changes: {changes:?}"
    );
    let _ = stop.send(());
}

/// An entry as a stream compares it (key, covers, pending), and each of its objects' (world
/// id, own level, level drawn).
type DrawnEntry = (Key, u64, bool, Vec<(u64, u8, u8)>);

/// What a plan draws, and each object's own level (what the next step's hysteresis starts
/// from), in a fixed order.
fn drawn(plan: &Plan) -> Vec<DrawnEntry> {
    let mut out: Vec<_> = plan
        .items
        .iter()
        .map(|p| {
            let levels = match &p.what {
                Drawn::Object { needed, .. } => vec![(0, *needed, 0)],
                Drawn::Instances(instances) => instances
                    .iter()
                    .map(|i| (i.object, i.needed, i.level))
                    .collect(),
                Drawn::Aggregate | Drawn::Impostor => Vec::new(),
            };
            (p.key, p.covers, p.pending, levels)
        })
        .collect();
    out.sort_by_key(|e| e.0);
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plan_carried_to_a_new_eye_is_the_plan_planning_again_makes() {
    let (_dir, world) = world("carry");
    let state = state(&world);
    let mut rng = Rng::new(11);
    // Walks along the row, instances on and off, under each kind of budget.
    let (mut carried, mut relevelled, mut missed, mut changed) = (0, 0, 0, 0);
    let mut swapped = 0;
    for walk in 0..16 {
        let mut view = over_the_row(&mut rng);
        view.min_solid_angle = [0.001, 0.0001][walk % 2];
        view.instances = (walk / 2) % 2 == 0;
        match walk / 4 {
            1 => view.budgets.max_entries = Some(30),
            2 => view.budgets.max_bytes = Some(2_000_000),
            3 => view.budgets.max_triangles = Some(200_000),
            _ => {}
        }
        let mut held = state.plan(&view).unwrap();
        for _ in 0..40 {
            // A step of 5 cm to 20 m.
            step(&mut rng, &mut view.eye, 0.05, 400.0);
            let again = state.plan_after(&view, Some(&held)).unwrap();
            let mut moved = held.clone();
            let carries = world
                .with_served(|served| moved.carry_to(served.tree, view.eye))
                .unwrap();
            if carries {
                assert_eq!(
                    drawn(&moved),
                    drawn(&again),
                    "walk {walk}: carried, not the same"
                );
                assert_eq!(moved.stopped_by, again.stopped_by);
                // The node the budget refuses is planning again's too, also where another
                // grew past the one refused before.
                let refused = moved.decisions.refused();
                assert_eq!(refused, again.decisions.refused(), "walk {walk}");
                if refused != held.decisions.refused() {
                    swapped += 1;
                }
                carried += 1;
                if drawn(&moved) != drawn(&held) {
                    relevelled += 1;
                }
            } else {
                let ids = |p: &Plan| -> Vec<Key> {
                    let mut k: Vec<Key> = p.items.iter().map(|p| p.key).collect();
                    k.sort();
                    k
                };
                if ids(&again) == ids(&held) {
                    missed += 1;
                } else {
                    changed += 1;
                }
            }
            // The stream goes on from the plan it carried: carry that one further.
            held = if carries { moved } else { again };
        }
    }
    // Carrying happens, also where objects' own levels move under a kept cut, and a cut
    // that changes is never carried (asserted above); most unchanged cuts are carried.
    let counts = format!(
        "carried {carried} ({relevelled} with new levels, {swapped} refusing another node), \
         missed {missed}, changed {changed}"
    );
    assert!(
        carried > 100 && relevelled > 3 && swapped > 0 && changed > 10,
        "{counts}"
    );
    eprintln!("{counts}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_instances_entry_whose_models_moved_level_reuses_the_placements_held() {
    let (_dir, world) = world("reuse");
    let state = state(&world);
    let mut rng = Rng::new(5);
    let (mut reused, mut renamed, mut sent_whole) = (0, 0, 0);
    for walk in 0..8 {
        let mut view = over_the_row(&mut rng);
        view.min_solid_angle = [0.001, 0.0001][walk % 2];
        let mut held = state.plan(&view).unwrap();
        for _ in 0..30 {
            step(&mut rng, &mut view.eye, 0.5, 100.0);
            let again = state.plan_after(&view, Some(&held)).unwrap();
            let (add, _) = world
                .with_served(|served| again.diff(&held, served))
                .unwrap();
            let before: HashMap<String, horizon_protocol::Entry> = held
                .entries()
                .into_iter()
                .map(|e| (e.id.clone(), e))
                .collect();
            let after: HashMap<String, horizon_protocol::Entry> = again
                .entries()
                .into_iter()
                .map(|e| (e.id.clone(), e))
                .collect();
            for a in add {
                let whole = &after[&a.entry.id];
                let Some(reuse) = &a.reuses else {
                    if whole.kind == EntryKind::Instances {
                        sent_whole += 1;
                    }
                    assert_eq!(&a.entry, whole, "walk {walk}");
                    continue;
                };
                // What a client makes of it: the held entry's assets and placements, renamed.
                assert!(a.entry.assets.is_empty() && a.entry.placements.is_empty());
                assert!(a.replaces.contains(&reuse.entry));
                let mut made = a.entry.clone();
                reuse.fill(&before[&reuse.entry], &mut made);
                assert_eq!(
                    &made, whole,
                    "walk {walk}: {} reusing {}",
                    whole.id, reuse.entry
                );
                reused += 1;
                renamed += usize::from(!reuse.assets.is_empty());
            }
            held = again;
        }
    }
    let counts = format!("reused {reused} ({renamed} renaming), sent whole {sent_whole}");
    assert!(reused > 5 && renamed > 5, "{counts}");
    eprintln!("{counts}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plan_at_the_edge_of_a_budget_is_never_carried_into_another_cut() {
    let (_dir, world) = world("edge");
    let state = state(&world);
    let keys = |p: &Plan| -> Vec<Key> {
        let mut k: Vec<Key> = p.items.iter().map(|p| p.key).collect();
        k.sort();
        k
    };
    let check = |held: &Plan, view: &View| -> bool {
        let again = state.plan_after(view, Some(held)).unwrap();
        let mut moved = held.clone();
        let carries = world
            .with_served(|served| moved.carry_to(served.tree, view.eye))
            .unwrap();
        if carries {
            assert_eq!(drawn(&moved), drawn(&again), "carried at {:?}", view.eye);
            assert_eq!(moved.stopped_by, again.stopped_by);
        }
        carries
    };
    // A step that changes only the level of an object charged for the refinement the byte
    // budget refused: the refusal's totals change, and so does the cut.
    let mut view = View::at([
        -50.551_721_177_376_14,
        39.644_614_594_724_565,
        10.606_241_231_824_129,
    ]);
    view.min_solid_angle = 1e-6;
    view.instances = false;
    view.budgets.max_bytes = Some(1_127_903);
    let held = state.plan(&view).unwrap();
    view.eye = [
        -41.691_671_350_926_754,
        33.339_533_335_938_02,
        8.454_204_118_019_058,
    ];
    check(&held, &view);
    // Budgets found, by bisection, where one more unit changes the cut; small steps from
    // there, with and without instances, under bytes and triangles.
    let mut rng = Rng::new(777);
    let (mut carried, mut steps) = (0, 0);
    for walk in 0..24 {
        let mut start = over_the_row(&mut rng);
        start.min_solid_angle = [1e-4, 1e-5, 1e-6][walk % 3];
        start.instances = (walk / 3) % 2 == 0;
        let triangles = (walk / 6) % 2 == 0;
        let with = |v: &View, b: u64| {
            let mut v = *v;
            if triangles {
                v.budgets.max_triangles = Some(b);
            } else {
                v.budgets.max_bytes = Some(b);
            }
            v
        };
        let b0 = (if triangles { 2e3 } else { 2e4 } * 10f64.powf(3.0 * rng.unit_f64())) as u64;
        let base = keys(&state.plan(&with(&start, b0)).unwrap());
        let (mut lo, mut hi) = (b0, b0 * 8);
        if keys(&state.plan(&with(&start, hi)).unwrap()) == base {
            continue;
        }
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if keys(&state.plan(&with(&start, mid)).unwrap()) == base {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let start = with(&start, lo);
        let held = state.plan(&start).unwrap();
        for _ in 0..12 {
            let mut v = start;
            step(&mut rng, &mut v.eye, 0.05, 400.0);
            steps += 1;
            if check(&held, &v) {
                carried += 1;
            }
        }
    }
    assert!(carried > 10 && steps > 100, "carried {carried} of {steps}");
}

/// The cut's download as budgets count it: each distinct asset once, previews aside.
fn download(plan: &Plan) -> u64 {
    let mut seen = HashSet::new();
    plan.entries()
        .iter()
        .flat_map(|e| &e.assets)
        .filter(|a| a.role != horizon_protocol::AssetRole::Preview)
        .filter(|a| seen.insert(a.hash.clone()))
        .map(|a| a.bytes)
        .sum()
}

/// Each object entry's level, by object.
fn object_levels(plan: &Plan) -> HashMap<u64, u32> {
    plan.entries()
        .iter()
        .filter(|e| e.kind == EntryKind::Object)
        .map(|e| (object_of(&e.id), e.level))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn coarsening_under_a_binding_budget_keeps_drawn_levels_and_takes_the_least_step() {
    const N: usize = 12;
    let (_dir, world) = distinct_row("coarsen", N);
    let state = state(&world);
    let mut view = View::at([0.0, 2.0, 0.0]);
    // Every building subtends it: without a budget each is its own entry, at its level.
    view.min_solid_angle = 1e-7;
    view.instances = false;
    let free = state.plan(&view).unwrap();
    assert_eq!(free.stopped_by, None);
    assert_eq!(object_levels(&free).len(), N);
    let free_levels = object_levels(&free);
    let mut coarsened = 0;
    let mut kept = 0;
    for share in [0.95, 0.85, 0.7, 0.5, 0.35] {
        let budget = (download(&free) as f64 * share) as u64;
        view.budgets.max_bytes = Some(budget);
        // The service plans at the view's own levels (`Coarsening::AsAsked`); the search is
        // what the lab measures against it (`lab/results/levels.md`).
        let as_asked = state.plan(&view).unwrap();
        assert_eq!(as_asked.coarsened, None);
        let searched = state.plan_with(&view, None, Coarsening::Search).unwrap();
        let context = format!(
            "budget {budget} ({share} of the free cut): as asked {} objects, searched {} at {:?}",
            object_levels(&as_asked).len(),
            object_levels(&searched).len(),
            searched.coarsened
        );
        // Both within the budget and complete.
        for p in [&as_asked, &searched] {
            assert!(download(p) <= budget, "{context}");
            assert_eq!(
                p.entries().iter().map(|e| e.covers).sum::<u64>(),
                N as u64,
                "{context}"
            );
        }
        // The budget binds at the asked levels, so the search ran.
        assert_eq!(as_asked.stopped_by, Some(StoppedBy::MaxBytes), "{context}");
        let Some(factor) = searched.coarsened else {
            panic!("{context}: not searched");
        };
        if factor == 1.0 {
            // Coarser levels went no further: the plan is the one as asked.
            assert_eq!(drawn(&searched), drawn(&as_asked), "{context}");
            continue;
        }
        coarsened += 1;
        eprintln!("{context}");
        // Every object drawn as itself at the asked levels still is, at the same level; more
        // are, each at its free level or a coarser one.
        let levels = object_levels(&searched);
        for (o, level) in &object_levels(&as_asked) {
            assert_eq!(levels.get(o), Some(level), "{context}: object {o}");
            kept += 1;
        }
        assert!(levels.len() > object_levels(&as_asked).len(), "{context}");
        for (o, level) in &levels {
            assert!(
                *level >= free_levels[o],
                "{context}: object {o} finer than free"
            );
        }
        // The least coarsening that goes as far: one step less falls short.
        let k = (1..=COARSENING_STEPS)
            .find(|&k| coarsening_step(k) == factor)
            .unwrap();
        let less = state
            .plan_with(&view, None, Coarsening::Fixed(coarsening_step(k - 1)))
            .unwrap();
        assert!(
            less.stopped_by == Some(StoppedBy::MaxBytes)
                && object_levels(&less).len() < levels.len(),
            "{context}: a step less is {} objects, {:?}",
            object_levels(&less).len(),
            less.stopped_by
        );
        // Never carried: its levels came from comparing plans.
        let mut moved = searched.clone();
        let carries = world
            .with_served(|served| moved.carry_to(served.tree, view.eye))
            .unwrap();
        assert!(!carries, "{context}");
    }
    assert!(
        coarsened >= 3 && kept > 0,
        "coarsened at {coarsened} of 5 budgets, {kept} objects kept"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refining_on_past_a_refusal_stays_within_the_budget_and_complete() {
    const N: usize = 12;
    let (_dir, row) = distinct_row("skip", N);
    let row_state = state(&row);
    let table = AssetTable::default();
    table.refresh(&row).unwrap();
    let mut view = View::at([0.0, 2.0, 0.0]);
    view.min_solid_angle = 1e-7;
    let free = row_state.plan(&view).unwrap();
    let mut skipped = 0;
    for share in [0.9, 0.7, 0.5, 0.35, 0.2] {
        let budget = (download(&free) as f64 * share) as u64;
        view.budgets.max_bytes = Some(budget);
        let skips = row_state.plan(&view).unwrap();
        let stops = row
            .with_served(|s| plan_stopping(s, &table, &view))
            .unwrap();
        let context = format!(
            "budget {budget} ({share} of the free cut): stops at {} objects, skips {} refusals to {}",
            object_levels(&stops).len(),
            skips.skipped,
            object_levels(&skips).len()
        );
        assert!(download(&skips) <= budget, "{context}");
        assert_eq!(
            skips.entries().iter().map(|e| e.covers).sum::<u64>(),
            N as u64,
            "{context}"
        );
        assert_eq!(skips.stopped_by, stops.stopped_by, "{context}");
        // Everything refinement took before its first refusal it still takes: every object
        // drawn as itself there still is.
        let drawn = object_levels(&skips);
        for o in object_levels(&stops).keys() {
            assert!(drawn.contains_key(o), "{context}: object {o}");
        }
        if skips.skipped > 0 {
            skipped += 1;
            // Never carried: its decisions do not describe the refinements after a refusal.
            let mut moved = skips.clone();
            let carries = row
                .with_served(|served| moved.carry_to(served.tree, view.eye))
                .unwrap();
            assert!(!carries, "{context}");
        }
        eprintln!("{context}");
    }
    assert!(
        skipped >= 3,
        "skipped past a refusal at {skipped} of 5 budgets"
    );
    // Random eyes and budgets over the 120 buildings of three models, with and without
    // instances: within every budget, and every object counted once.
    let (_many_dir, many) = world("skip-many");
    let many_state = state(&many);
    let table = AssetTable::default();
    table.refresh(&many).unwrap();
    let mut rng = Rng::new(5);
    let (mut skips_seen, mut entry_stops) = (0, 0);
    for round in 0..40 {
        let mut view = over_the_row(&mut rng);
        view.min_solid_angle = [1e-4, 1e-5, 1e-6][round % 3];
        view.instances = round % 2 == 0;
        let scale = 10f64.powf(2.0 * rng.unit_f64());
        match round % 3 {
            0 => view.budgets.max_triangles = Some((2e3 * scale) as u64),
            1 => view.budgets.max_bytes = Some((2e5 * scale) as u64),
            _ => view.budgets.max_draw_calls = Some((3.0 * scale) as u64),
        }
        // Sometimes the entry budget stops refinement after refusals were skipped.
        if round % 5 == 0 {
            view.budgets.max_entries = Some(60);
        }
        let p = many_state.plan(&view).unwrap();
        let entries = p.entries();
        let context = format!("round {round}: {:?}, {} skipped", view.budgets, p.skipped);
        assert_eq!(
            entries.iter().map(|e| e.covers).sum::<u64>(),
            (MODELS * ROW) as u64,
            "{context}"
        );
        let within = |p: &Plan| {
            let triangles: u64 = p.entries().iter().map(|e| e.triangles).sum();
            triangles <= view.budgets.max_triangles.unwrap_or(u64::MAX)
                && download(p) <= view.budgets.max_bytes.unwrap_or(u64::MAX)
                && p.items.len() as u64 <= view.budgets.max_entries.unwrap_or(u64::MAX)
        };
        // Over only where even the coarsest cut is, which the plan that stops says too.
        let stops = many
            .with_served(|s| plan_stopping(s, &table, &view))
            .unwrap();
        assert!(within(&p) || !within(&stops), "{context}");
        // A plan that skipped a refusal names a budget: the one that refused first, or the
        // entry budget where that stopped refinement afterwards.
        assert!(p.skipped == 0 || p.stopped_by.is_some(), "{context}");
        skips_seen += usize::from(p.skipped > 1);
        entry_stops += usize::from(p.skipped > 0 && p.stopped_by == Some(StoppedBy::MaxEntries));
    }
    assert!(
        skips_seen > 5 && entry_stops > 0,
        "{skips_seen} plans skipped more than one refusal, {entry_stops} then stopped by entries"
    );
}
