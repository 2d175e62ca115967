//! The client against the real service, in process (`horizon_server::service::run` on a port
//! of 127.0.0.1), over a small world of boxes with published aggregates and the rebuild
//! worker on:
//! - seeded walks over the world while another task places, moves and deletes objects: after
//!   every stream message the delta-applied cut must apply cleanly, count every object once,
//!   and equal a fresh `GET /v1/cut` at the same view whenever both are of the same generation
//!   and published generation; once the mutations stop and the world is published, every
//!   comparison must be made and equal;
//! - a `walk` with the asset cache under a bandwidth limit loads every asset of its cut, and
//!   the cache then answers from disk after a 304;
//! - errors come back typed: a bad view is the server's 400 `bad_query`, a stream over its
//!   message rate is closed with 1008 `rate_limited`.

mod common;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{quick_rebuilds, serve, world, TempDir, EXTENT, PATIENCE};
use horizon_client::{
    check_cut, walk, AssetCache, AssetError, Client, ClientError, LocalCut, Polyline, Stream,
    StreamError, WalkOptions,
};
use horizon_mesh::rng::Rng;
use horizon_protocol::{
    Created, ErrorCode, ModelPage, NewObject, ObjectPatch, Scale, ServerMessage, View, WorldInfo,
};
use horizon_server::service::{Config, StreamLimits};

async fn model_ids(base: &str) -> Vec<String> {
    let page: ModelPage = common::http()
        .get(format!("{base}/v1/models"))
        .send()
        .await
        .expect("models")
        .json()
        .await
        .expect("a model page");
    page.models.into_iter().map(|m| m.id).collect()
}

async fn world_info(base: &str) -> WorldInfo {
    common::http()
        .get(format!("{base}/v1/world"))
        .send()
        .await
        .expect("world")
        .json()
        .await
        .expect("world JSON")
}

/// Waits until the world's every change is published.
async fn wait_published(base: &str) -> WorldInfo {
    let started = Instant::now();
    loop {
        let info = world_info(base).await;
        if info.published == info.generation && info.dirty_nodes == 0 {
            return info;
        }
        assert!(
            started.elapsed() < PATIENCE,
            "generation {} was never published: {info:?}",
            info.generation
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

// ---------------------------------------------------------------------------------------------
// Mutations
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Default)]
struct Mutations {
    created: u64,
    moved: u64,
    deleted: u64,
}

/// Places, moves and deletes alice's objects over the grid until `stop`, a mutation every
/// 20 to 120 ms.
async fn mutate(
    base: String,
    token: String,
    models: Vec<String>,
    seed: u64,
    stop: Arc<AtomicBool>,
) -> Mutations {
    let http = common::http();
    let mut rng = Rng::new(seed);
    let mut mine: Vec<u64> = Vec::new();
    let mut done = Mutations::default();
    let place = |rng: &mut Rng| {
        [
            rng.range(-8.0, EXTENT as f32 + 8.0),
            0.0,
            rng.range(-8.0, EXTENT as f32 + 8.0),
        ]
    };
    while !stop.load(Ordering::SeqCst) {
        let op = rng.below(10);
        if mine.len() < 3 || op < 5 {
            let body = NewObject {
                model: models[rng.below(models.len())].clone(),
                translation: place(&mut rng),
                rotation: [0.0, 0.0, 0.0, 1.0],
                scale: Scale::Uniform(rng.range(0.5, 3.0)),
            };
            let r = http
                .post(format!("{base}/v1/objects"))
                .bearer_auth(&token)
                .json(&body)
                .send()
                .await
                .expect("a placement");
            assert_eq!(r.status().as_u16(), 201, "placing {body:?}");
            let created: Created = r.json().await.expect("created JSON");
            mine.push(created.id);
            done.created += 1;
        } else if op < 8 {
            let id = mine[rng.below(mine.len())];
            let patch = ObjectPatch {
                translation: Some(place(&mut rng)),
                ..ObjectPatch::default()
            };
            let r = http
                .patch(format!("{base}/v1/objects/{id}"))
                .bearer_auth(&token)
                .json(&patch)
                .send()
                .await
                .expect("a move");
            assert_eq!(r.status().as_u16(), 200, "moving {id}");
            done.moved += 1;
        } else {
            let id = mine.swap_remove(rng.below(mine.len()));
            let r = http
                .delete(format!("{base}/v1/objects/{id}"))
                .bearer_auth(&token)
                .send()
                .await
                .expect("a deletion");
            assert!(r.status().is_success(), "deleting {id}: {}", r.status());
            done.deleted += 1;
        }
        let pause = 20 + rng.below(100) as u64;
        tokio::time::sleep(Duration::from_millis(pause)).await;
    }
    done
}

// ---------------------------------------------------------------------------------------------
// Checked walks
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Default)]
struct Checked {
    messages: u64,
    resets: u64,
    deltas: u64,
    /// Messages whose cut was compared with a fresh one of the same generation.
    compared: u64,
    /// Messages whose fresh cut was of a later generation or publish.
    skipped: u64,
    /// Deltas that named an entry they replace.
    replacing: u64,
    pending: u64,
}

/// One line about a message, for failures.
fn summary(m: &ServerMessage) -> String {
    match m {
        ServerMessage::Reset {
            seq,
            view,
            generation,
            published,
            objects,
            entries,
            stopped_by,
        } => format!(
            "reset seq {seq} view {view} generation {generation} published {published} \
             objects {objects}, {} entries, stopped by {stopped_by:?}",
            entries.len()
        ),
        ServerMessage::Delta {
            seq,
            view,
            generation,
            published,
            objects,
            add,
            remove,
            stopped_by,
        } => format!(
            "delta seq {seq} view {view} generation {generation} published {published} \
             objects {objects}, stopped by {stopped_by:?}, add {:?}, remove {:?}",
            add.iter()
                .map(|a| (a.entry.id.as_str(), a.entry.covers, &a.replaces))
                .collect::<Vec<_>>(),
            remove
                .iter()
                .map(|r| (r.id.as_str(), r.reason))
                .collect::<Vec<_>>()
        ),
        ServerMessage::Error { error } => format!("error {error:?}"),
    }
}

/// Applies `m`, checks the kept cut, and compares it with a fresh cut at the view it answers.
async fn check(
    client: &Client,
    walk: &str,
    cut: &mut LocalCut,
    views: &HashMap<u64, View>,
    m: &ServerMessage,
    checked: &mut Checked,
) {
    match m {
        ServerMessage::Error { error } => panic!("{walk}: the server refused a view: {error:?}"),
        ServerMessage::Reset { .. } => checked.resets += 1,
        ServerMessage::Delta { add, .. } => {
            checked.deltas += 1;
            if add.iter().any(|a| !a.replaces.is_empty()) {
                checked.replacing += 1;
            }
        }
    }
    checked.messages += 1;
    let before = cut.clone();
    if let Err(e) = cut.apply(m) {
        panic!(
            "{walk}: {} does not apply to the kept cut (seq {}, {} entries): {e}",
            summary(m),
            before.seq(),
            before.len()
        );
    }
    if let Err(e) = cut.check_complete() {
        panic!(
            "{walk}: after {} the kept cut is incomplete: {e}",
            summary(m)
        );
    }
    checked.pending += cut.entries().values().filter(|e| e.pending).count() as u64;
    let view = views
        .get(&cut.view())
        .unwrap_or_else(|| panic!("{walk}: {} answers a view never sent", summary(m)));
    let fresh = client.cut(view).await.expect("a fresh cut");
    if let Err(e) = check_cut(&fresh) {
        panic!("{walk}: the fresh cut at {view:?} is incomplete: {e}");
    }
    assert!(
        fresh.generation >= cut.generation(),
        "{walk}: a fresh cut at generation {} after a message at {}",
        fresh.generation,
        cut.generation()
    );
    if (fresh.generation, fresh.published) != (cut.generation(), cut.published()) {
        checked.skipped += 1;
        return;
    }
    if let Err(e) = cut.same_as(&fresh) {
        panic!(
            "{walk}: after {} at view {} {view:?}: {e}\nthe message before it left seq {} with {} entries",
            summary(m),
            cut.view(),
            before.seq(),
            before.len()
        );
    }
    checked.compared += 1;
}

/// A seeded walk of `steps` views over the grid (some outside it, some high above), with a
/// seeded solid angle and sometimes an entry budget; every message is checked.
async fn checked_walk(base: &str, seed: u64, steps: usize, checked: &mut Checked) {
    let client = Client::new(base).expect("a client");
    let mut rng = Rng::new(seed);
    let points: Vec<[f64; 3]> = (0..5)
        .map(|_| {
            [
                f64::from(rng.range(-60.0, EXTENT as f32 + 60.0)),
                f64::from(rng.range(1.5, 40.0)),
                f64::from(rng.range(-60.0, EXTENT as f32 + 60.0)),
            ]
        })
        .collect();
    let path = Polyline::new(&points).expect("a path");
    let mut view = View::at(points[0]);
    view.min_solid_angle = [1e-3, 3e-3, 1e-2][rng.below(3)];
    // Even seeds with instances entries: on this grid of three reused boxes they draw nearly
    // the whole world in two entries, so odd seeds keep every node as its aggregate, which
    // walking refines and coarsens.
    view.instances = seed.is_multiple_of(2);
    if rng.chance(0.4) {
        view.budgets.max_entries = Some(10 + rng.below(60) as u64);
    }
    let name = format!("walk {seed} over {points:?} with {view:?}");
    let mut stream = Stream::connect(base).await.expect("the stream connects");
    let mut cut = LocalCut::new();
    let mut views = HashMap::new();
    for step in 0..=steps {
        let id = step as u64 + 1;
        view.eye = path.at(path.length() * step as f64 / steps as f64);
        // Now and then a budget changes on the way.
        if rng.chance(0.1) {
            let b = &mut view.budgets;
            match rng.below(5) {
                0 => b.max_triangles = Some(200 + rng.below(2_000) as u64),
                1 => b.max_bytes = Some(2_000 + rng.below(20_000) as u64),
                2 => b.max_draw_calls = Some(1 + rng.below(8) as u64),
                3 => b.max_entries = Some(5 + rng.below(100) as u64),
                _ => *b = horizon_protocol::Budgets::default(),
            }
        }
        stream.send_view(id, &view).await.expect("a view is sent");
        views.insert(id, view);
        // Messages until this view is answered and a little after, or the stream is quiet.
        let mut answered = false;
        for _ in 0..20 {
            let quiet = if answered {
                Duration::from_millis(30)
            } else {
                Duration::from_millis(300)
            };
            let m = match tokio::time::timeout(quiet, stream.next()).await {
                Err(_) => break,
                Ok(m) => m.unwrap_or_else(|e| panic!("{name}: the stream failed: {e}")),
            };
            check(&client, &name, &mut cut, &views, &m, checked).await;
            if let Some(seq) = m.seq() {
                stream.ack(seq).await.expect("an ack is sent");
            }
            answered |= cut.view() >= id;
        }
    }
    assert!(cut.started(), "{name}: no reset came");
    stream.close().await.expect("the stream closes");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn seeded_walks_under_mutations_keep_the_stream_equal_to_fresh_cuts() {
    let dir = TempDir::new("walks");
    let (world, token) = world(&dir);
    let server = serve(&world, quick_rebuilds()).await;
    let models = model_ids(&server.base).await;
    assert_eq!(models.len(), 3);

    let stop = Arc::new(AtomicBool::new(false));
    let mutator = tokio::spawn(mutate(server.base.clone(), token, models, 7, stop.clone()));
    // `HORIZON_CLIENT_WALKS=N` walks N seeds instead of 4 (a longer hunt).
    let walks = std::env::var("HORIZON_CLIENT_WALKS")
        .ok()
        .and_then(|n| n.parse::<u64>().ok())
        .unwrap_or(4)
        .max(1);
    let mut checked = Checked::default();
    for seed in 1..=walks {
        checked_walk(&server.base, seed, 30, &mut checked).await;
    }
    stop.store(true, Ordering::SeqCst);
    let mutations = tokio::time::timeout(PATIENCE, mutator)
        .await
        .expect("the mutator stops")
        .expect("the mutator did not panic");

    // Quiet and published: every message compares, and equals.
    let info = wait_published(&server.base).await;
    let mut quiet = Checked::default();
    checked_walk(&server.base, 99, 12, &mut quiet).await;
    eprintln!("under mutations: {checked:?}; {mutations:?}; quiet: {quiet:?}; world {info:?}");
    assert!(mutations.created >= 10, "{mutations:?}");
    assert!(mutations.moved + mutations.deleted > 0, "{mutations:?}");
    assert_eq!(checked.resets, walks, "{checked:?}");
    assert!(checked.deltas >= 20, "{checked:?}");
    assert!(checked.compared >= 20, "too few comparisons: {checked:?}");
    assert!(
        checked.pending > 0,
        "no pending object was ever seen: {checked:?}"
    );
    assert_eq!(quiet.skipped, 0, "{quiet:?}");
    assert!(quiet.compared >= 2, "{quiet:?}");
}

// ---------------------------------------------------------------------------------------------
// The walk and the asset cache
// ---------------------------------------------------------------------------------------------

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_walk_loads_its_cut_within_the_bandwidth_and_the_cache_revalidates() {
    let dir = TempDir::new("walk-world");
    let cache_dir = TempDir::new("walk-cache");
    let (world, _) = world(&dir);
    let server = serve(&world, quick_rebuilds()).await;
    let client = Client::new(&server.base).expect("a client");
    let cache = AssetCache::with_client(&cache_dir.0, &client).expect("a cache");

    let bandwidth = 400_000.0;
    let options = WalkOptions {
        speed: 40.0,
        bandwidth: Some(bandwidth),
        duration: Duration::from_secs(4),
        view: View {
            min_solid_angle: 3e-3,
            // Aggregates, which walking refines into deltas (with instances this grid is two
            // entries from anywhere).
            instances: false,
            ..View::at([0.0; 3])
        },
        ..WalkOptions::new(vec![
            [-40.0, 5.0, -40.0],
            [EXTENT / 2.0, 3.0, EXTENT / 2.0],
            [EXTENT + 40.0, 30.0, EXTENT / 2.0],
        ])
    };
    let report = walk(&server.base, &options, &cache)
        .await
        .expect("the walk");
    eprintln!("{}", serde_json::to_string(&report).expect("JSON"));
    assert_eq!(report.resets, 1, "{report:?}");
    assert!(report.views_sent >= 20, "{report:?}");
    assert!(report.deltas > 0, "{report:?}");
    assert!(report.frames > 0, "{report:?}");
    assert!(
        report.assets_fetched > 0 && report.bytes_fetched > 0,
        "{report:?}"
    );
    assert!(report.first_complete_ms.is_some(), "{report:?}");
    assert!(report.view_latency_ms.count > 0, "{report:?}");
    assert!(report.incomplete_frames <= report.frames, "{report:?}");
    // An entry with nothing to draw is missing an asset; every entry drawn comes no later
    // than every asset loaded.
    assert!(report.hole_frames <= report.incomplete_frames, "{report:?}");
    assert!(report.first_drawn_ms.is_some(), "{report:?}");
    assert!(
        report.first_drawn_ms <= report.first_complete_ms,
        "{report:?}"
    );
    // The bucket never lets more through than its burst and its rate.
    let burst = (bandwidth * 0.1).max(16_384.0);
    assert!(
        (report.bytes_fetched as f64) <= burst + bandwidth * report.seconds,
        "{report:?}"
    );

    // The same walk again through the same cache: what it loads comes back as 304s.
    let options_again = WalkOptions {
        bandwidth: None,
        ..options.clone()
    };
    let again = walk(&server.base, &options_again, &cache)
        .await
        .expect("the walk again");
    assert!(again.assets_cached > 0, "{again:?}");
    assert!(again.bytes_fetched < report.bytes_fetched, "{again:?}");

    // A slow link: a fresh cache at 8 kB/s gets no more than its burst and its rate.
    let slow_dir = TempDir::new("walk-slow-cache");
    let slow_cache = AssetCache::with_client(&slow_dir.0, &client).expect("a cache");
    let slow = WalkOptions {
        bandwidth: Some(8_000.0),
        duration: Duration::from_secs(3),
        ..options.clone()
    };
    let throttled = walk(&server.base, &slow, &slow_cache)
        .await
        .expect("the slow walk");
    eprintln!("{}", serde_json::to_string(&throttled).expect("JSON"));
    assert!(throttled.bytes_fetched > 0, "{throttled:?}");
    assert!(
        (throttled.bytes_fetched as f64) <= 16_384.0 + 8_000.0 * throttled.seconds,
        "{throttled:?}"
    );

    // Every asset of a cut comes through the cache: downloaded and kept once, then a 304.
    let cut = client
        .cut(&View::at([EXTENT / 2.0, 3.0, EXTENT / 2.0]))
        .await
        .expect("a cut");
    let hash = cut.entries[0].assets[0].hash.clone();
    let first = cache.get(&hash).await.expect("the asset");
    assert_eq!(blake3::hash(&first.bytes).to_hex().as_str(), hash);
    let again = cache.get(&hash).await.expect("the asset again");
    assert!(!again.fetched, "a cached asset is revalidated, not fetched");
    assert_eq!(again.downloaded, 0);
    assert_eq!(again.bytes, first.bytes);
    assert!(cache.path(&hash).is_file());
    // A damaged file is fetched again.
    std::fs::write(cache.path(&hash), b"not the asset").expect("damage");
    let mended = cache.get(&hash).await.expect("the asset mended");
    assert!(mended.fetched);
    assert_eq!(mended.bytes, first.bytes);
    // An unknown asset is the server's 404, typed.
    let unknown = "0".repeat(64);
    match cache.get(&unknown).await {
        Err(AssetError::Client(ClientError::Server { status: 404, body })) => {
            assert_eq!(body.error.code, ErrorCode::NotFound);
        }
        other => panic!("expected the server's 404, got {other:?}"),
    }
    assert!(!cache.path(&unknown).exists());
}

// ---------------------------------------------------------------------------------------------
// Typed errors
// ---------------------------------------------------------------------------------------------

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn errors_come_back_typed() {
    let dir = TempDir::new("errors");
    let (world, _) = world(&dir);
    let server = serve(
        &world,
        Config {
            rebuild: false,
            stream: StreamLimits {
                messages_per_second: 5,
                ..StreamLimits::default()
            },
            ..Config::default()
        },
    )
    .await;
    let client = Client::new(&server.base).expect("a client");
    let mut bad = View::at([0.0, 0.0, 0.0]);
    bad.min_solid_angle = 20.0;
    match client.cut(&bad).await {
        Err(e @ ClientError::Server { status: 400, .. }) => {
            assert_eq!(e.code(), Some(ErrorCode::BadQuery), "{e}");
        }
        other => panic!("expected a 400 bad_query, got {other:?}"),
    }

    // Over the message rate (5 a second, bursts of 10), the stream is closed with 1008.
    let mut stream = Stream::connect(&server.base).await.expect("a stream");
    let view = View::at([EXTENT / 2.0, 3.0, EXTENT / 2.0]);
    for id in 1..=30 {
        if stream.send_view(id, &view).await.is_err() {
            break;
        }
    }
    let started = Instant::now();
    let closed = loop {
        match tokio::time::timeout(PATIENCE, stream.next())
            .await
            .expect("a message or a close in time")
        {
            Ok(_) => assert!(started.elapsed() < PATIENCE),
            Err(e) => break e,
        }
    };
    match closed {
        StreamError::Closed { code, reason } => {
            assert_eq!((code, reason.as_str()), (1008, "rate_limited"));
        }
        other => panic!("expected a 1008 close, got {other}"),
    }
}
