//! The service over a real socket (`service::run`), with the rebuild worker on: a client
//! uploads a model, places objects, waits for the rebuild to publish their generation, and
//! fetches the published aggregates as a browser would (conditional, ranged, compressed).
//! Then the server shuts down cleanly.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use horizon_server::service::{run, AppState, Config};
use horizon_world::{User, World};
use reqwest::header::{
    ACCEPT_ENCODING, CACHE_CONTROL, CONTENT_ENCODING, CONTENT_RANGE, CONTENT_TYPE, ETAG,
    IF_NONE_MATCH, RANGE,
};
use reqwest::StatusCode;
use serde_json::{json, Value};
use tokio::net::TcpListener;

/// Removes the world directory however the test ends.
struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A bound against hanging, not a timing assertion.
const PATIENCE: Duration = Duration::from_secs(60);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_places_objects_and_fetches_the_published_aggregates() {
    let dir = TempDir(std::env::temp_dir().join(format!(
        "horizon-http-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    )));
    let _ = std::fs::remove_dir_all(&dir.0);
    let world = World::open_or_create(&dir.0).expect("a fresh world");
    let token = world
        .create_token(&User {
            name: "alice".into(),
            max_objects: None,
            max_bytes: None,
        })
        .expect("a token");
    let world = Arc::new(world);

    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let base = format!("http://{}", listener.local_addr().expect("address"));
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(run(
        listener,
        AppState::new(world.clone(), Config::default()),
        async move {
            let _ = stopped.await;
        },
    ));

    let client = reqwest::Client::builder()
        .no_proxy()
        .build()
        .expect("a client");
    let health = client
        .get(format!("{base}/healthz"))
        .send()
        .await
        .expect("healthz");
    assert_eq!(health.status(), StatusCode::OK);

    // Upload a model.
    let glb = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../assets/models/BoxTextured/BoxTextured.glb"
    ))
    .expect("the repository's BoxTextured.glb");
    let r = client
        .post(format!("{base}/v1/models?name=box"))
        .bearer_auth(&token)
        .header(CONTENT_TYPE, "model/gltf-binary")
        .body(glb.clone())
        .send()
        .await
        .expect("upload");
    assert_eq!(r.status(), StatusCode::CREATED);
    let model: Value = r.json().await.expect("model JSON");
    let model_id = model["id"].as_str().expect("an id").to_owned();
    assert_eq!(model["name"], "box");
    assert!(model["textures"].as_u64() >= Some(1), "{model}");

    // Without a token, nothing is placed.
    let r = client
        .post(format!("{base}/v1/objects"))
        .json(&json!({"model": model_id, "translation": [0, 0, 0]}))
        .send()
        .await
        .expect("unauthorised placement");
    assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    let body: Value = r.json().await.expect("error JSON");
    assert_eq!(body["error"]["code"], "unauthorized");

    // Place three objects.
    let mut last_generation = 0;
    for (i, x) in [0.0f32, 4.0, 8.0].into_iter().enumerate() {
        let r = client
            .post(format!("{base}/v1/objects"))
            .bearer_auth(&token)
            .json(&json!({"model": model_id, "translation": [x, 0, i as f32], "scale": 1.5}))
            .send()
            .await
            .expect("placement");
        assert_eq!(r.status(), StatusCode::CREATED);
        let created: Value = r.json().await.expect("created JSON");
        last_generation = created["generation"].as_u64().expect("a generation");
    }
    assert_eq!(last_generation, 3);

    // Wait for the rebuild worker to publish that generation.
    let started = Instant::now();
    let info = loop {
        let info: Value = client
            .get(format!("{base}/v1/world"))
            .send()
            .await
            .expect("world")
            .json()
            .await
            .expect("world JSON");
        if info["published"] == info["generation"] && info["published"] == last_generation {
            break info;
        }
        assert!(
            started.elapsed() < PATIENCE,
            "the rebuild did not publish generation {last_generation}: {info}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(info["objects"], 3);
    assert_eq!(info["models"], 1);
    assert_eq!(info["dirty_nodes"], 0, "{info}");
    assert!(info["last_rebuild_ms"].is_u64(), "{info}");

    // The published manifest, and one of its aggregates.
    let published = world.meta().published().expect("the published record");
    assert_eq!(published.generation, last_generation);
    let manifest_hash = published.manifest.expect("a published manifest");
    let r = client
        .get(format!("{base}/assets/{manifest_hash}"))
        .send()
        .await
        .expect("manifest");
    assert_eq!(r.status(), StatusCode::OK);
    let manifest: Value = r.json().await.expect("the manifest is JSON");
    let nodes = manifest["nodes"].as_object().expect("nodes");
    assert!(!nodes.is_empty(), "{manifest}");
    let aggregate = nodes
        .values()
        .find_map(|n| n["glb"].as_str())
        .expect("a node with a glb")
        .to_owned();
    let uri = format!("{base}/assets/{aggregate}");
    let etag = format!("\"{aggregate}\"");

    let r = client.get(&uri).send().await.expect("aggregate");
    assert_eq!(r.status(), StatusCode::OK);
    assert_eq!(r.headers()[ETAG], etag.as_str());
    assert_eq!(
        r.headers()[CACHE_CONTROL],
        "public, max-age=31536000, immutable"
    );
    assert!(r.headers().get(CONTENT_ENCODING).is_none());
    let bytes = r.bytes().await.expect("aggregate bytes");
    assert!(bytes.starts_with(b"glTF"), "an aggregate is a GLB");
    assert_eq!(horizon_world::content_hash(&bytes), aggregate);

    let r = client
        .get(&uri)
        .header(IF_NONE_MATCH, &etag)
        .send()
        .await
        .expect("conditional");
    assert_eq!(r.status(), StatusCode::NOT_MODIFIED);
    assert!(r.bytes().await.expect("no body").is_empty());

    let r = client
        .get(&uri)
        .header(RANGE, "bytes=0-9")
        .send()
        .await
        .expect("range");
    assert_eq!(r.status(), StatusCode::PARTIAL_CONTENT);
    assert_eq!(
        r.headers()[CONTENT_RANGE],
        format!("bytes 0-9/{}", bytes.len()).as_str()
    );
    assert_eq!(&r.bytes().await.expect("range bytes")[..], &bytes[..10]);

    let r = client
        .get(&uri)
        .header(ACCEPT_ENCODING, "zstd")
        .send()
        .await
        .expect("compressed");
    assert_eq!(r.status(), StatusCode::OK);
    assert_eq!(r.headers()[CONTENT_ENCODING], "zstd");
    let compressed = r.bytes().await.expect("compressed bytes");
    let decoded = zstd::decode_all(&compressed[..]).expect("the body decodes as zstd");
    assert_eq!(decoded, &bytes[..]);

    // The metrics saw the requests and the rebuild.
    let metrics = client
        .get(format!("{base}/metrics"))
        .send()
        .await
        .expect("metrics")
        .text()
        .await
        .expect("metrics text");
    assert!(metrics.contains("horizon_requests_total"), "{metrics}");
    assert!(metrics.contains("horizon_rebuild_seconds"), "{metrics}");

    // Shut down: `run` returns Ok once the server and the worker have stopped.
    drop(client);
    stop.send(()).expect("the server is still running");
    let result = tokio::time::timeout(PATIENCE, server)
        .await
        .expect("the server stops after the shutdown signal")
        .expect("the server task did not panic");
    assert!(result.is_ok(), "run returned {result:?}");
    drop(world);
}
