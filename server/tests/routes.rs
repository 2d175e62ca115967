//! The service's routes against `DESIGN.md`, "Service contract (v1)": every route, and every
//! bad input with its exact status and error code, through `tower::ServiceExt::oneshot` on
//! `app(...)` (no socket, no rebuild worker). Each test builds its own world in a temporary
//! directory and removes it; after every bad input the server still serves and nothing
//! stored has changed.

// A test's `unwrap` on a request it built or a reply it checks is an assertion.
#![allow(clippy::unwrap_used)]

use std::convert::Infallible;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};

use axum::body::{Body, Bytes};
use axum::http::header::{
    ACCEPT_ENCODING, AUTHORIZATION, CACHE_CONTROL, CONTENT_ENCODING, CONTENT_LENGTH, CONTENT_RANGE,
    CONTENT_TYPE, ETAG, IF_NONE_MATCH, RANGE,
};
use axum::http::{HeaderMap, Method, Request, StatusCode};
use axum::Router;
use glam::{Affine3A, Vec2, Vec3};
use horizon_mesh::{
    export_glb, ExportOptions, Instance, InstancedMesh, Material, Submesh, Texture, TextureRef,
    Wrap,
};
use horizon_server::service::{app, AppState, Config};
use horizon_world::{UploadLimits, User, World};
use serde_json::{json, Value};
use tower::ServiceExt;

// ---------------------------------------------------------------------------------------------
// The harness
// ---------------------------------------------------------------------------------------------

/// A fresh world in its own temporary directory, the service over it, and two users' tokens.
struct Harness {
    dir: PathBuf,
    world: Arc<World>,
    app: Router,
    alice: String,
    bob: String,
}

impl Drop for Harness {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A directory under the system's temporary directory that no other test (or process) uses.
fn unique_dir(name: &str) -> PathBuf {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let dir =
        std::env::temp_dir().join(format!("horizon-routes-{name}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn test_config() -> Config {
    Config {
        rebuild: false,
        ..Config::default()
    }
}

/// The reply to one request, its body read whole.
#[derive(Debug)]
struct Reply {
    status: StatusCode,
    headers: HeaderMap,
    body: Bytes,
}

impl Reply {
    fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "{} with a body that is not JSON ({e}): {:?}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }

    fn header(&self, name: impl axum::http::header::AsHeaderName) -> Option<&str> {
        self.headers.get(name).and_then(|v| v.to_str().ok())
    }

    /// The reply is `status` with a body of exactly `{"error": {"code": code, "message"}}`,
    /// the message one non-empty line.
    #[track_caller]
    fn assert_error(&self, status: u16, code: &str) {
        if let Some(why) = self.error_mismatch(status, code) {
            panic!("{why}");
        }
    }

    /// Why the reply is not the error `status` `code` (see [`Reply::assert_error`]), if it
    /// is not.
    fn error_mismatch(&self, status: u16, code: &str) -> Option<String> {
        let text = String::from_utf8_lossy(&self.body);
        let expected = format!("expected {status} {code}");
        if self.status.as_u16() != status {
            return Some(format!("{expected}, got {} with {text}", self.status));
        }
        if !self
            .header(CONTENT_TYPE)
            .is_some_and(|t| t.starts_with("application/json"))
        {
            return Some(format!(
                "{expected}: an error is JSON, got content-type {:?} with {text:?}",
                self.header(CONTENT_TYPE)
            ));
        }
        let Ok(body) = serde_json::from_slice::<Value>(&self.body) else {
            return Some(format!("{expected}: the body is not JSON: {text:?}"));
        };
        let shape = body.as_object().is_some_and(|o| o.len() == 1)
            && body["error"].as_object().is_some_and(|e| e.len() == 2);
        if !shape {
            return Some(format!(
                "{expected}: the body is not {{\"error\": {{\"code\", \"message\"}}}}: {text}"
            ));
        }
        if body["error"]["code"] != code {
            return Some(format!(
                "{expected}, got code {}: {text}",
                body["error"]["code"]
            ));
        }
        match body["error"]["message"].as_str() {
            Some(m) if !m.trim().is_empty() && !m.contains(['\n', '\r']) => None,
            _ => Some(format!(
                "{expected}: the message is not one non-empty line: {text}"
            )),
        }
    }

    #[track_caller]
    fn assert_status(&self, status: u16) {
        assert_eq!(
            self.status.as_u16(),
            status,
            "body {}",
            String::from_utf8_lossy(&self.body)
        );
    }
}

/// What a bad input must leave as it was: the world's counters and every object and model.
#[derive(Debug, PartialEq)]
struct Stored {
    world: Value,
    objects: Value,
    models: Value,
    blobs: usize,
}

impl Harness {
    fn new(name: &str) -> Self {
        Self::with(name, test_config(), UploadLimits::default())
    }

    fn with(name: &str, config: Config, limits: UploadLimits) -> Self {
        let dir = unique_dir(name);
        let mut world = World::open_or_create(&dir).expect("a fresh world");
        world.set_upload_limits(limits);
        let token = |name: &str| {
            world
                .create_token(&user(name, None, None))
                .expect("a token")
        };
        let (alice, bob) = (token("alice"), token("bob"));
        let world = Arc::new(world);
        let app = app(AppState::new(world.clone(), config));
        Self {
            dir,
            world,
            app,
            alice,
            bob,
        }
    }

    async fn send(&self, request: Request<Body>) -> Reply {
        let response = self
            .app
            .clone()
            .oneshot(request)
            .await
            .expect("the router is infallible");
        let (parts, body) = response.into_parts();
        let body = axum::body::to_bytes(body, usize::MAX)
            .await
            .expect("the body reads");
        Reply {
            status: parts.status,
            headers: parts.headers,
            body,
        }
    }

    async fn get(&self, uri: &str) -> Reply {
        self.send(request(Method::GET, uri, None).body(Body::empty()).unwrap())
            .await
    }

    /// A JSON request with `token`, its body `body` as given (not necessarily valid JSON).
    async fn json_text(&self, method: Method, uri: &str, token: Option<&str>, body: &str) -> Reply {
        self.send(
            request(method, uri, token)
                .header(CONTENT_TYPE, "application/json")
                .body(Body::from(body.to_owned()))
                .unwrap(),
        )
        .await
    }

    async fn json(&self, method: Method, uri: &str, token: Option<&str>, body: &Value) -> Reply {
        self.json_text(method, uri, token, &body.to_string()).await
    }

    async fn delete(&self, uri: &str, token: Option<&str>) -> Reply {
        self.send(
            request(Method::DELETE, uri, token)
                .body(Body::empty())
                .unwrap(),
        )
        .await
    }

    async fn upload_as(&self, token: Option<&str>, media: &str, bytes: Vec<u8>) -> Reply {
        self.send(
            request(Method::POST, "/v1/models", token)
                .header(CONTENT_TYPE, media)
                .body(Body::from(bytes))
                .unwrap(),
        )
        .await
    }

    async fn upload(&self, bytes: Vec<u8>) -> Reply {
        self.upload_as(Some(&self.alice), "model/gltf-binary", bytes)
            .await
    }

    /// Uploads a model as alice; its id.
    async fn model(&self, bytes: Vec<u8>) -> String {
        let r = self.upload(bytes).await;
        r.assert_status(201);
        r.json()["id"].as_str().expect("an id").to_owned()
    }

    /// Places `model` at `translation` for `token`; the new object's id.
    async fn place(&self, token: &str, model: &str, translation: [f32; 3]) -> u64 {
        let r = self
            .json(
                Method::POST,
                "/v1/objects",
                Some(token),
                &json!({"model": model, "translation": translation}),
            )
            .await;
        r.assert_status(201);
        r.json()["id"].as_u64().expect("an id")
    }

    async fn world_info(&self) -> Value {
        let r = self.get("/v1/world").await;
        r.assert_status(200);
        r.json()
    }

    async fn stored(&self) -> Stored {
        let objects = self.get("/v1/objects?limit=10000").await;
        objects.assert_status(200);
        let models = self.get("/v1/models?limit=10000").await;
        models.assert_status(200);
        Stored {
            world: self.world_info().await,
            objects: objects.json(),
            models: models.json(),
            blobs: self.world.blobs().list().expect("blobs list").len(),
        }
    }

    /// The server still serves, and nothing stored changed since `before`.
    async fn assert_unchanged(&self, before: &Stored) {
        let health = self.get("/healthz").await;
        health.assert_status(200);
        assert_eq!(
            &self.stored().await,
            before,
            "a refused request changed the world"
        );
    }
}

fn user(name: &str, max_objects: Option<u64>, max_bytes: Option<u64>) -> User {
    User {
        name: name.into(),
        max_objects,
        max_bytes,
    }
}

fn request(method: Method, uri: &str, token: Option<&str>) -> axum::http::request::Builder {
    let b = Request::builder().method(method).uri(uri);
    match token {
        Some(t) => b.header(AUTHORIZATION, format!("Bearer {t}")),
        None => b,
    }
}

// ---------------------------------------------------------------------------------------------
// Models to upload
// ---------------------------------------------------------------------------------------------

/// A box of side `1 + seed / 10` (so that seeds give different bytes), 12 triangles, placed
/// `instances` times, with a `texture` of that size if asked.
fn cube(seed: u32, instances: usize, texture: Option<(u32, u32)>) -> InstancedMesh {
    let s = 1.0 + seed as f32 / 10.0;
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { 0.0 } else { s },
                if i & 2 == 0 { 0.0 } else { s },
                if i & 4 == 0 { 0.0 } else { s },
            )
        })
        .collect();
    // Corners by bits (x = 1, y = 2, z = 4); two triangles per face.
    let indices = vec![
        0, 2, 1, 1, 2, 3, // z = 0
        4, 5, 6, 5, 7, 6, // z = s
        0, 1, 4, 1, 5, 4, // y = 0
        2, 6, 3, 3, 6, 7, // y = s
        0, 4, 2, 2, 4, 6, // x = 0
        1, 3, 5, 3, 7, 5, // x = s
    ];
    let uvs = texture.map(|_| {
        positions
            .iter()
            .map(|p| Vec2::new(p.x, p.y + p.z))
            .collect()
    });
    let mut mesh = InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            uvs,
            indices,
            material: texture.map(|_| 0),
            ..Submesh::default()
        }],
        instances: (0..instances)
            .map(|i| Instance {
                submesh: 0,
                transform: Affine3A::from_translation(Vec3::new(3.0 * i as f32, 0.0, 0.0)),
            })
            .collect(),
        ..InstancedMesh::default()
    };
    if let Some((w, h)) = texture {
        mesh.textures.push(png(w, h, seed));
        mesh.materials.push(Material {
            base_color_texture: Some(TextureRef {
                texture: 0,
                transform: None,
            }),
            ..Material::default()
        });
    }
    mesh
}

/// A PNG of noise (it does not compress much), deterministic in `seed`.
fn png(w: u32, h: u32, seed: u32) -> Texture {
    let mut state = u64::from(seed).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let image = image::RgbaImage::from_fn(w, h, |_, _| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let [r, g, b, ..] = state.to_le_bytes();
        image::Rgba([r, g, b, 255])
    });
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgba8(image)
        .write_to(&mut Cursor::new(&mut bytes), image::ImageFormat::Png)
        .expect("PNG encodes");
    Texture {
        bytes,
        mime_type: "image/png".into(),
        size: (w, h),
        wrap_u: Wrap::Repeat,
        wrap_v: Wrap::Repeat,
    }
}

fn glb(mesh: &InstancedMesh) -> Vec<u8> {
    export_glb(mesh, &ExportOptions::plain()).expect("the test mesh exports")
}

/// A plain untextured cube's GLB, different per seed.
fn cube_glb(seed: u32) -> Vec<u8> {
    glb(&cube(seed, 1, None))
}

/// A GLB's JSON chunk and BIN chunk.
fn glb_parts(glb: &[u8]) -> (Value, Vec<u8>) {
    let u32_at = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&glb[..4], b"glTF");
    let json_len = u32_at(12);
    assert_eq!(&glb[16..20], b"JSON");
    let json = serde_json::from_slice(&glb[20..20 + json_len]).expect("the GLB's JSON parses");
    let at = 20 + json_len;
    let bin = if glb.len() > at {
        let bin_len = u32_at(at);
        assert_eq!(&glb[at + 4..at + 8], b"BIN\0");
        glb[at + 8..at + 8 + bin_len].to_vec()
    } else {
        Vec::new()
    };
    (json, bin)
}

/// A GLB of `json` and `bin`, each chunk padded to 4 bytes as the format asks.
fn glb_of(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = json.to_string().into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    out
}

/// Standard base64 with padding (a data URI's payload).
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// glTF JSON whose one buffer is at `uri`, the rest of the document `glb`'s.
fn gltf_json_with_uri(glb: &[u8], uri: &str) -> Vec<u8> {
    let (mut json, bin) = glb_parts(glb);
    json["buffers"] = json!([{"byteLength": bin.len(), "uri": uri}]);
    json.to_string().into_bytes()
}

/// A body that arrives in chunks, with no length known in advance (no `Content-Length`, no
/// size hint), as a chunked upload does.
struct Streamed {
    chunks: Vec<Bytes>,
}

impl Streamed {
    fn body(bytes: &[u8], chunk: usize) -> Body {
        let mut chunks: Vec<Bytes> = bytes.chunks(chunk).map(Bytes::copy_from_slice).collect();
        chunks.reverse();
        Body::new(Self { chunks })
    }
}

impl http_body::Body for Streamed {
    type Data = Bytes;
    type Error = Infallible;

    fn poll_frame(
        self: Pin<&mut Self>,
        _: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, Infallible>>> {
        Poll::Ready(
            self.get_mut()
                .chunks
                .pop()
                .map(|c| Ok(http_body::Frame::data(c))),
        )
    }
}

/// The number of files under `dir`, recursively.
fn files_under(dir: &Path) -> usize {
    std::fs::read_dir(dir).map_or(0, |entries| {
        entries
            .flatten()
            .map(|e| {
                let p = e.path();
                if p.is_dir() {
                    files_under(&p)
                } else {
                    1
                }
            })
            .sum()
    })
}

// ---------------------------------------------------------------------------------------------
// Every route
// ---------------------------------------------------------------------------------------------

#[tokio::test]
async fn service_routes_answer() {
    let h = Harness::new("meta");

    let r = h.get("/healthz").await;
    r.assert_status(200);
    assert_eq!(&r.body[..], b"ok");

    let r = h.get("/metrics").await;
    r.assert_status(200);
    assert!(r.header(CONTENT_TYPE).unwrap().starts_with("text/plain"));
    let text = String::from_utf8_lossy(&r.body);
    assert!(text.contains("horizon_requests_total"), "{text}");
    assert!(text.contains("horizon_generation"), "{text}");

    let r = h.get("/v1/openapi.json").await;
    r.assert_status(200);
    assert!(r
        .header(CONTENT_TYPE)
        .unwrap()
        .starts_with("application/json"));
    assert!(r.json()["openapi"].as_str().unwrap().starts_with("3.1"));

    let r = h.get("/").await;
    r.assert_status(200);
    assert!(r.header(CONTENT_TYPE).unwrap().starts_with("text/html"));
    assert!(String::from_utf8_lossy(&r.body).contains("Horizon"));

    let w = h.world_info().await;
    for key in [
        "generation",
        "published",
        "objects",
        "models",
        "dirty_nodes",
        "last_rebuild_ms",
        "bounds",
    ] {
        assert!(w.get(key).is_some(), "/v1/world has no {key}: {w}");
    }
    assert_eq!(w["generation"], 0);
    assert_eq!(w["objects"], 0);
    assert_eq!(w["models"], 0);
    assert_eq!(w["bounds"], Value::Null);

    let before = h.stored().await;
    for uri in ["/v1/nope", "/nope", "/v1/objects/1/extra", "/assets"] {
        h.get(uri).await.assert_error(404, "not_found");
    }
    h.assert_unchanged(&before).await;
}

#[tokio::test]
async fn openapi_lists_every_route() {
    let h = Harness::new("openapi");
    let r = h.get("/v1/openapi.json").await;
    r.assert_status(200);
    let doc = r.json();
    let paths = doc["paths"].as_object().expect("paths");
    let routes = [
        ("get", "/healthz"),
        ("get", "/metrics"),
        ("get", "/v1/openapi.json"),
        ("get", "/"),
        ("get", "/v1/world"),
        ("post", "/v1/models"),
        ("get", "/v1/models"),
        ("get", "/v1/models/{id}"),
        ("post", "/v1/objects"),
        ("get", "/v1/objects"),
        ("get", "/v1/objects/{id}"),
        ("patch", "/v1/objects/{id}"),
        ("delete", "/v1/objects/{id}"),
        ("post", "/v1/objects/batch"),
        ("get", "/assets/{hash}"),
    ];
    for (method, path) in routes {
        assert!(
            paths.get(path).and_then(|p| p.get(method)).is_some(),
            "the OpenAPI document has no {} {path}; it has {:?}",
            method.to_uppercase(),
            paths.keys().collect::<Vec<_>>()
        );
    }
}

#[tokio::test]
async fn wrong_method_is_a_json_error() {
    let h = Harness::new("method");
    let before = h.stored().await;
    let r = h
        .send(
            request(Method::PUT, "/v1/world", None)
                .body(Body::empty())
                .unwrap(),
        )
        .await;
    assert_eq!(r.status, StatusCode::METHOD_NOT_ALLOWED);
    // The contract: every error is `{"error": {"code", "message"}}`.
    let body = r.json();
    assert!(body["error"]["code"].is_string(), "{body}");
    assert!(body["error"]["message"].is_string(), "{body}");
    h.assert_unchanged(&before).await;
}

#[tokio::test]
async fn models_are_uploaded_read_and_paged() {
    let h = Harness::new("models");
    let bytes = cube_glb(1);
    let r = h.upload(bytes.clone()).await;
    r.assert_status(201);
    let info = r.json();
    let id = info["id"].as_str().unwrap().to_owned();
    assert_eq!(
        id,
        horizon_world::content_hash(&bytes),
        "the id is the bytes' hash"
    );
    assert!(horizon_world::is_content_hash(
        info["asset"].as_str().unwrap()
    ));
    assert_eq!(info["owner"], "alice");
    assert_eq!(info["triangles_unique"], 12);
    assert_eq!(info["instances"], 1);

    let r = h.get(&format!("/v1/models/{id}")).await;
    r.assert_status(200);
    assert_eq!(r.json(), info);

    let named = h
        .send(
            request(Method::POST, "/v1/models?name=crate", Some(&h.bob))
                .header(CONTENT_TYPE, "model/gltf-binary")
                .body(Body::from(cube_glb(2)))
                .unwrap(),
        )
        .await;
    named.assert_status(201);
    assert_eq!(named.json()["name"], "crate");
    assert_eq!(named.json()["owner"], "bob");
    let before = h.stored().await;
    for name in ["%0A", "a%00b", &"n".repeat(257)] {
        h.send(
            request(
                Method::POST,
                &format!("/v1/models?name={name}"),
                Some(&h.bob),
            )
            .header(CONTENT_TYPE, "model/gltf-binary")
            .body(Body::from(cube_glb(3)))
            .unwrap(),
        )
        .await
        .assert_error(400, "bad_query");
    }
    h.assert_unchanged(&before).await;
    h.model(cube_glb(3)).await;

    let mut seen = Vec::new();
    let mut uri = "/v1/models?limit=2".to_owned();
    for _ in 0..10 {
        let r = h.get(&uri).await;
        r.assert_status(200);
        let page = r.json();
        let models = page["models"].as_array().unwrap();
        assert!(models.len() <= 2);
        seen.extend(models.iter().map(|m| m["id"].as_str().unwrap().to_owned()));
        match page["next"].as_str() {
            Some(next) => uri = format!("/v1/models?limit=2&after={next}"),
            None => break,
        }
    }
    assert_eq!(seen.len(), 3, "{seen:?}");
    assert!(
        seen.windows(2).all(|w| w[0] < w[1]),
        "in id order: {seen:?}"
    );

    h.get(&format!("/v1/models/{}", "0".repeat(64)))
        .await
        .assert_error(404, "not_found");
    h.get("/v1/models/nope")
        .await
        .assert_error(404, "not_found");
    assert_eq!(h.world_info().await["models"], 3);
}

#[tokio::test]
async fn objects_are_placed_read_moved_and_deleted() {
    let h = Harness::new("objects");
    let model = h.model(cube_glb(1)).await;
    let r = h
        .json(
            Method::POST,
            "/v1/objects",
            Some(&h.alice),
            &json!({"model": model, "translation": [1, 2, 3], "rotation": [0, 0, 0, 1], "scale": 2}),
        )
        .await;
    r.assert_status(201);
    let created = r.json();
    let id = created["id"].as_u64().unwrap();
    assert_eq!(created["generation"], 1);

    let r = h.get(&format!("/v1/objects/{id}")).await;
    r.assert_status(200);
    let o = r.json();
    assert_eq!(o["model"], model.as_str());
    assert_eq!(o["owner"], "alice");
    assert_eq!(o["translation"], json!([1.0, 2.0, 3.0]));
    assert_eq!(o["scale"], json!([2.0, 2.0, 2.0]));
    assert_eq!(o["generation"], 1);

    let w = h.world_info().await;
    assert_eq!(
        (w["generation"].as_u64(), w["objects"].as_u64()),
        (Some(1), Some(1))
    );
    assert!(w["bounds"].is_object(), "{w}");

    let r = h
        .json(
            Method::PATCH,
            &format!("/v1/objects/{id}"),
            Some(&h.alice),
            &json!({"translation": [5, 5, 5]}),
        )
        .await;
    r.assert_status(200);
    assert_eq!(r.json()["generation"], 2);
    let o = h.get(&format!("/v1/objects/{id}")).await.json();
    assert_eq!(o["translation"], json!([5.0, 5.0, 5.0]));
    assert_eq!(
        o["scale"],
        json!([2.0, 2.0, 2.0]),
        "a move keeps what it does not name"
    );
    assert_eq!(o["generation"], 2);

    let r = h.delete(&format!("/v1/objects/{id}"), Some(&h.alice)).await;
    r.assert_status(200);
    assert_eq!(r.json(), json!({"id": id, "generation": 3}));
    h.get(&format!("/v1/objects/{id}"))
        .await
        .assert_error(404, "not_found");
    let w = h.world_info().await;
    assert_eq!(
        (w["generation"].as_u64(), w["objects"].as_u64()),
        (Some(3), Some(0))
    );

    let before = h.stored().await;
    h.delete(&format!("/v1/objects/{id}"), Some(&h.alice))
        .await
        .assert_error(404, "not_found");
    h.assert_unchanged(&before).await;
}

/// An object's id names one object for good (`o:<id>` in cuts never names two contents):
/// the id of a deleted object is not given to a new one.
#[tokio::test]
async fn object_ids_are_never_reused() {
    let h = Harness::new("reuse");
    let model = h.model(cube_glb(1)).await;
    let first = h.place(&h.alice, &model, [0.0, 0.0, 0.0]).await;
    let last = h.place(&h.alice, &model, [5.0, 0.0, 0.0]).await;
    h.delete(&format!("/v1/objects/{last}"), Some(&h.alice))
        .await
        .assert_status(200);
    let next = h.place(&h.alice, &model, [9.0, 0.0, 0.0]).await;
    assert!(
        next != last && next != first,
        "object {next} reuses the id of a deleted object ({last})"
    );
}

#[tokio::test]
async fn objects_page_follows_next_to_the_end() {
    let h = Harness::new("paging");
    let model = h.model(cube_glb(1)).await;
    let mut ids = Vec::new();
    for i in 0..5 {
        let token = if i % 2 == 0 { &h.alice } else { &h.bob };
        ids.push(h.place(token, &model, [i as f32 * 3.0, 0.0, 0.0]).await);
    }
    let mut seen = Vec::new();
    let mut pages = 0;
    let mut uri = "/v1/objects?limit=2".to_owned();
    loop {
        let r = h.get(&uri).await;
        r.assert_status(200);
        let page = r.json();
        pages += 1;
        assert!(pages <= 3, "5 objects in pages of 2 take 3 pages");
        let objects = page["objects"].as_array().unwrap();
        seen.extend(objects.iter().map(|o| o["id"].as_u64().unwrap()));
        match page["next"].as_u64() {
            Some(next) => {
                assert_eq!(objects.len(), 2);
                assert_eq!(Some(next), seen.last().copied());
                uri = format!("/v1/objects?limit=2&after={next}");
            }
            None => {
                assert_eq!(objects.len(), 1);
                break;
            }
        }
    }
    assert_eq!(pages, 3);
    assert_eq!(seen, ids);

    let r = h.get("/v1/objects?owner=bob").await;
    r.assert_status(200);
    let bobs: Vec<u64> = r.json()["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["id"].as_u64().unwrap())
        .collect();
    assert_eq!(bobs, vec![ids[1], ids[3]]);
    let all = h.get("/v1/objects").await.json();
    assert_eq!(all["objects"].as_array().unwrap().len(), 5);
    assert_eq!(all["next"], Value::Null);
    h.get("/v1/objects?limit=10000").await.assert_status(200);
    h.get("/v1/models?limit=10000").await.assert_status(200);
}

#[tokio::test]
async fn bad_page_queries_are_400() {
    let h = Harness::new("queries");
    let model = h.model(cube_glb(1)).await;
    h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    for route in ["/v1/objects", "/v1/models"] {
        for query in [
            "limit=0",
            "limit=10001",
            "limit=-1",
            "limit=abc",
            "limit=1e3",
        ] {
            h.get(&format!("{route}?{query}"))
                .await
                .assert_error(400, "bad_query");
        }
    }
    h.get("/v1/objects?after=abc")
        .await
        .assert_error(400, "bad_query");
    h.get("/v1/objects?after=-3")
        .await
        .assert_error(400, "bad_query");
    h.assert_unchanged(&before).await;
}

// ---------------------------------------------------------------------------------------------
// Uploads: bad glTF, limits, media types, repeats
// ---------------------------------------------------------------------------------------------

#[tokio::test]
async fn bytes_that_are_not_gltf_are_bad_gltf() {
    let h = Harness::new("notgltf");
    let before = h.stored().await;
    for bytes in [
        b"this is not a model at all".to_vec(),
        b"glTF".to_vec(),
        vec![0u8; 64],
        b"{\"asset\": ".to_vec(),
    ] {
        h.upload(bytes.clone()).await.assert_error(400, "bad_gltf");
        h.upload_as(Some(&h.alice), "model/gltf+json", bytes)
            .await
            .assert_error(400, "bad_gltf");
    }
    h.assert_unchanged(&before).await;
}

#[tokio::test]
async fn a_truncated_glb_is_bad_gltf() {
    let h = Harness::new("truncated");
    let bytes = cube_glb(1);
    let before = h.stored().await;
    for keep in [11, 12, 20, bytes.len() / 2, bytes.len() - 4] {
        h.upload(bytes[..keep].to_vec())
            .await
            .assert_error(400, "bad_gltf");
    }
    h.assert_unchanged(&before).await;
    // The whole file is fine: it is the truncation that is refused.
    h.upload(bytes).await.assert_status(201);
}

#[tokio::test]
async fn a_buffer_view_outside_the_file_is_bad_gltf() {
    let h = Harness::new("bufferview");
    let good = cube_glb(1);
    let (json, bin) = glb_parts(&good);
    // Repacking changes nothing that matters: the same document uploads.
    assert_eq!(glb_of(&json, &bin).len(), good.len());
    let before = h.stored().await;

    let mut far = json.clone();
    far["bufferViews"][0]["byteOffset"] = json!(bin.len() + 4096);
    h.upload(glb_of(&far, &bin))
        .await
        .assert_error(400, "bad_gltf");

    let mut long = json.clone();
    let views = long["bufferViews"].as_array().unwrap().len();
    long["bufferViews"][views - 1]["byteLength"] = json!(bin.len() * 4 + 1000);
    h.upload(glb_of(&long, &bin))
        .await
        .assert_error(400, "bad_gltf");

    let mut buffer = json.clone();
    buffer["buffers"][0]["byteLength"] = json!(bin.len() * 16);
    for v in buffer["bufferViews"].as_array_mut().unwrap() {
        v["byteOffset"] = json!(bin.len() * 8);
    }
    h.upload(glb_of(&buffer, &bin))
        .await
        .assert_error(400, "bad_gltf");

    h.assert_unchanged(&before).await;
    h.upload(glb_of(&json, &bin)).await.assert_status(201);
}

#[tokio::test]
async fn external_uris_are_bad_gltf_and_read_nothing() {
    let h = Harness::new("uris");
    let good = cube_glb(1);
    let (_, bin) = glb_parts(&good);
    // The buffer the URIs name exists, right next to the world and in it: a server that
    // followed a URI would find valid bytes there and store the model.
    let outside = Removed(unique_dir("uris-outside"));
    let outside = &outside.0;
    std::fs::create_dir_all(outside).unwrap();
    std::fs::write(outside.join("other.bin"), &bin).unwrap();
    std::fs::write(h.dir.join("other.bin"), &bin).unwrap();
    let before = h.stored().await;
    let file_uri = format!("file://{}", outside.join("other.bin").display());
    let absolute = outside.join("other.bin").display().to_string();
    for uri in [
        "other.bin",
        "./other.bin",
        "file:///etc/passwd",
        "/etc/passwd",
        file_uri.as_str(),
        absolute.as_str(),
        "http://127.0.0.1:9/other.bin",
    ] {
        let document = gltf_json_with_uri(&good, uri);
        h.upload_as(Some(&h.alice), "model/gltf+json", document.clone())
            .await
            .assert_error(400, "bad_gltf");
        // The same JSON inside a GLB container.
        let json: Value = serde_json::from_slice(&document).unwrap();
        h.upload(glb_of(&json, &[]))
            .await
            .assert_error(400, "bad_gltf");
    }
    h.assert_unchanged(&before).await;
    // The same document with its buffer embedded as a data URI is a model.
    let embedded = gltf_json_with_uri(
        &good,
        &format!("data:application/octet-stream;base64,{}", base64(&bin)),
    );
    h.upload_as(Some(&h.alice), "model/gltf+json", embedded)
        .await
        .assert_status(201);
}

/// A directory removed when the test ends, however it ends.
struct Removed(PathBuf);

impl Drop for Removed {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A world whose uploads are held to `limits`, where `refused` is over them (413 `code`) and
/// `accepted` is not.
async fn over_a_limit(
    name: &str,
    limits: UploadLimits,
    refused: Vec<u8>,
    code: &str,
    accepted: Vec<u8>,
) {
    let h = Harness::with(name, test_config(), limits);
    let before = h.stored().await;
    h.upload(refused).await.assert_error(413, code);
    h.assert_unchanged(&before).await;
    h.upload(accepted).await.assert_status(201);
}

#[tokio::test]
async fn over_the_triangle_limit_is_413() {
    let limits = UploadLimits {
        max_triangles: 12,
        ..UploadLimits::default()
    };
    // Two instances of 12 triangles: 24 drawn, though 12 stored.
    let refused = glb(&cube(1, 2, None));
    over_a_limit(
        "triangles",
        limits,
        refused,
        "too_many_triangles",
        cube_glb(1),
    )
    .await;
}

#[tokio::test]
async fn over_the_instance_limit_is_413() {
    let limits = UploadLimits {
        max_instances: 2,
        ..UploadLimits::default()
    };
    let refused = glb(&cube(1, 3, None));
    let accepted = glb(&cube(1, 2, None));
    over_a_limit("instances", limits, refused, "too_many_instances", accepted).await;
}

#[tokio::test]
async fn over_the_texture_side_limit_is_413() {
    let limits = UploadLimits {
        max_texture_side: 8,
        ..UploadLimits::default()
    };
    // 64 pixels, as many as the accepted one, but 16 across.
    let refused = glb(&cube(1, 1, Some((16, 4))));
    let accepted = glb(&cube(1, 1, Some((8, 8))));
    over_a_limit("side", limits, refused, "texture_too_large", accepted).await;
}

#[tokio::test]
async fn over_the_texture_pixel_limit_is_413() {
    let limits = UploadLimits {
        max_texture_pixels: 100,
        ..UploadLimits::default()
    };
    let refused = glb(&cube(1, 1, Some((8, 16))));
    let accepted = glb(&cube(1, 1, Some((8, 8))));
    over_a_limit("pixels", limits, refused, "texture_too_large", accepted).await;
}

#[tokio::test]
async fn uploads_need_a_model_media_type() {
    let h = Harness::new("media-models");
    let before = h.stored().await;
    for media in [
        "application/json",
        "image/png",
        "application/octet-stream",
        "",
    ] {
        h.upload_as(Some(&h.alice), media, cube_glb(1))
            .await
            .assert_error(415, "unsupported_media_type");
    }
    let r = h
        .send(
            request(Method::POST, "/v1/models", Some(&h.alice))
                .body(Body::from(cube_glb(1)))
                .unwrap(),
        )
        .await;
    r.assert_error(415, "unsupported_media_type");
    h.assert_unchanged(&before).await;
    h.upload_as(
        Some(&h.alice),
        "Model/GLTF-Binary; charset=binary",
        cube_glb(1),
    )
    .await
    .assert_status(201);
}

#[tokio::test]
async fn the_same_model_twice_is_one_model() {
    let h = Harness::new("twice");
    let bytes = cube_glb(1);
    let first = h.upload(bytes.clone()).await;
    first.assert_status(201);
    let again = h.upload(bytes.clone()).await;
    again.assert_status(200);
    assert_eq!(first.json()["id"], again.json()["id"]);
    assert_eq!(first.json(), again.json());
    // Bob uploading the same bytes gets the same model too.
    let bobs = h.upload_as(Some(&h.bob), "model/gltf-binary", bytes).await;
    bobs.assert_status(200);
    assert_eq!(bobs.json()["id"], first.json()["id"]);
    assert_eq!(h.world_info().await["models"], 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_same_model_uploaded_concurrently_is_stored_once() {
    let h = Harness::new("concurrent");
    let bytes = glb(&cube(1, 1, Some((16, 16))));
    let tasks: Vec<_> = (0..8)
        .map(|_| {
            let app = h.app.clone();
            let request = request(Method::POST, "/v1/models", Some(&h.alice))
                .header(CONTENT_TYPE, "model/gltf-binary")
                .body(Body::from(bytes.clone()))
                .unwrap();
            tokio::spawn(async move {
                let response = app.oneshot(request).await.unwrap();
                let status = response.status();
                let body = axum::body::to_bytes(response.into_body(), usize::MAX)
                    .await
                    .unwrap();
                (status, serde_json::from_slice::<Value>(&body).unwrap())
            })
        })
        .collect();
    let mut replies = Vec::new();
    for t in tasks {
        replies.push(t.await.expect("an upload task"));
    }
    let created = replies
        .iter()
        .filter(|(s, _)| *s == StatusCode::CREATED)
        .count();
    let existing = replies.iter().filter(|(s, _)| *s == StatusCode::OK).count();
    assert_eq!(
        (created, existing),
        (1, 7),
        "one 201 and seven 200: {replies:?}"
    );
    let id = &replies[0].1["id"];
    assert!(id.is_string());
    assert!(replies.iter().all(|(_, b)| &b["id"] == id), "{replies:?}");
    assert_eq!(h.world_info().await["models"], 1);
    let page = h.get("/v1/models").await.json();
    assert_eq!(page["models"].as_array().unwrap().len(), 1);
    // One stored GLB (and nothing else: no rebuild runs here).
    assert_eq!(h.world.blobs().list().unwrap().len(), 1);
}

// ---------------------------------------------------------------------------------------------
// Bodies over the limit
// ---------------------------------------------------------------------------------------------

#[tokio::test]
async fn bodies_over_the_limit_are_413() {
    let config = Config {
        body_limit: 1024,
        ..test_config()
    };
    let h = Harness::with("bodylimit", config, UploadLimits::default());
    // A model stored directly (its GLB is over the body limit) for the objects to place.
    let model = h
        .world
        .upload_model(&cube_glb(1), "cube", "alice")
        .expect("upload")
        .0
        .id;
    let small = json!({"model": model, "translation": [0, 0, 0]}).to_string();
    // The same JSON padded with whitespace: valid, and over the limit.
    let big = format!("{small}{}", " ".repeat(2048));
    let big_model = glb(&cube(2, 1, Some((16, 16))));
    assert!(big_model.len() > 1024 && big_model.len() < 64 << 20);
    let before = h.stored().await;

    // With a correct Content-Length.
    let r = h
        .send(
            request(Method::POST, "/v1/objects", Some(&h.alice))
                .header(CONTENT_TYPE, "application/json")
                .header(CONTENT_LENGTH, big.len())
                .body(Body::from(big.clone()))
                .unwrap(),
        )
        .await;
    r.assert_error(413, "too_large");
    let r = h
        .send(
            request(Method::POST, "/v1/models", Some(&h.alice))
                .header(CONTENT_TYPE, "model/gltf-binary")
                .header(CONTENT_LENGTH, big_model.len())
                .body(Body::from(big_model.clone()))
                .unwrap(),
        )
        .await;
    r.assert_error(413, "too_large");
    let batch = format!(
        "{{\"ops\": [{}]}}",
        vec![
            format!("{{\"op\": \"create\", \"model\": \"{model}\", \"translation\": [0, 0, 0]}}");
            20
        ]
        .join(",")
    );
    assert!(batch.len() > 1024);
    let r = h
        .send(
            request(Method::POST, "/v1/objects/batch", Some(&h.alice))
                .header(CONTENT_TYPE, "application/json")
                .header(CONTENT_LENGTH, batch.len())
                .body(Body::from(batch.clone()))
                .unwrap(),
        )
        .await;
    r.assert_error(413, "too_large");

    // Streamed, with no Content-Length.
    for (uri, media, bytes) in [
        ("/v1/objects", "application/json", big.as_bytes().to_vec()),
        ("/v1/models", "model/gltf-binary", big_model.clone()),
        ("/v1/objects/batch", "application/json", batch.into_bytes()),
    ] {
        let r = h
            .send(
                request(Method::POST, uri, Some(&h.alice))
                    .header(CONTENT_TYPE, media)
                    .body(Streamed::body(&bytes, 100))
                    .unwrap(),
            )
            .await;
        r.assert_error(413, "too_large");
    }
    h.assert_unchanged(&before).await;

    // Under the limit, both ways, the same request is served.
    let r = h
        .send(
            request(Method::POST, "/v1/objects", Some(&h.alice))
                .header(CONTENT_TYPE, "application/json")
                .header(CONTENT_LENGTH, small.len())
                .body(Body::from(small.clone()))
                .unwrap(),
        )
        .await;
    r.assert_status(201);
    let r = h
        .send(
            request(Method::POST, "/v1/objects", Some(&h.alice))
                .header(CONTENT_TYPE, "application/json")
                .body(Streamed::body(small.as_bytes(), 10))
                .unwrap(),
        )
        .await;
    r.assert_status(201);
    assert_eq!(h.world_info().await["objects"], 2);
}

// ---------------------------------------------------------------------------------------------
// Transforms
// ---------------------------------------------------------------------------------------------

/// JSON cannot carry NaN or infinity, but `1e999` is a well-formed JSON number that no float
/// holds: the contract calls that an invalid transform (422), not malformed JSON.
#[tokio::test]
async fn an_infinite_number_is_an_invalid_transform() {
    let h = Harness::new("infinite");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    let post = |body: String| (Method::POST, "/v1/objects".to_owned(), body);
    let cases = [
        post(format!(
            r#"{{"model": "{model}", "translation": [1e999, 0, 0]}}"#
        )),
        post(format!(
            r#"{{"model": "{model}", "translation": [0, 0, 0], "scale": -1e999}}"#
        )),
        post(format!(
            r#"{{"model": "{model}", "translation": [0, 0, 0], "rotation": [0, 0, 0, 1e999]}}"#
        )),
        (
            Method::PATCH,
            format!("/v1/objects/{id}"),
            r#"{"translation": [0, 1e999, 0]}"#.to_owned(),
        ),
        (
            Method::POST,
            "/v1/objects/batch".to_owned(),
            format!(
                r#"{{"ops": [{{"op": "create", "model": "{model}", "translation": [1e999, 0, 0]}}]}}"#
            ),
        ),
    ];
    let failures = expect_errors(&h, &cases, 422, "invalid_transform").await;
    assert!(failures.is_empty(), "{failures:#?}");
    h.assert_unchanged(&before).await;
}

/// A number a double holds but a float does not (`1e39`) becomes infinite: 422.
#[tokio::test]
async fn a_number_past_the_float_range_is_an_invalid_transform() {
    let h = Harness::new("overflow");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    for body in [
        format!(r#"{{"model": "{model}", "translation": [1e39, 0, 0]}}"#),
        format!(r#"{{"model": "{model}", "translation": [0, 0, 0], "scale": [1, 1e39, 1]}}"#),
    ] {
        h.json_text(Method::POST, "/v1/objects", Some(&h.alice), &body)
            .await
            .assert_error(422, "invalid_transform");
    }
    h.json_text(
        Method::PATCH,
        &format!("/v1/objects/{id}"),
        Some(&h.alice),
        r#"{"translation": [0, -1e39, 0]}"#,
    )
    .await
    .assert_error(422, "invalid_transform");
    let batch = format!(
        r#"{{"ops": [{{"op": "create", "model": "{model}", "translation": [0, 0, 0]}},
                     {{"op": "create", "model": "{model}", "translation": [0, 0, 1e39]}}]}}"#
    );
    h.json_text(Method::POST, "/v1/objects/batch", Some(&h.alice), &batch)
        .await
        .assert_error(422, "invalid_transform");
    h.assert_unchanged(&before).await;
}

#[tokio::test]
async fn bad_scales_and_rotations_are_invalid_transforms() {
    let h = Harness::new("transforms");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    let bad = [
        json!({"scale": 0}),
        json!({"scale": -1}),
        json!({"scale": [1, 0, 1]}),
        json!({"scale": [1, 1, -2]}),
        json!({"rotation": [0, 0, 0, 2]}),
        json!({"rotation": [0, 0, 0, 0]}),
        json!({"rotation": [1, 1, 0, 0]}),
    ];
    for fields in &bad {
        let mut body = json!({"model": model, "translation": [0, 0, 0]});
        for (k, v) in fields.as_object().unwrap() {
            body[k] = v.clone();
        }
        h.json(Method::POST, "/v1/objects", Some(&h.alice), &body)
            .await
            .assert_error(422, "invalid_transform");
        h.json(
            Method::PATCH,
            &format!("/v1/objects/{id}"),
            Some(&h.alice),
            fields,
        )
        .await
        .assert_error(422, "invalid_transform");
        let mut op = body.clone();
        op["op"] = json!("create");
        h.json(
            Method::POST,
            "/v1/objects/batch",
            Some(&h.alice),
            &json!({"ops": [op]}),
        )
        .await
        .assert_error(422, "invalid_transform");
        let mut op = fields.clone();
        op["op"] = json!("move");
        op["id"] = json!(id);
        h.json(
            Method::POST,
            "/v1/objects/batch",
            Some(&h.alice),
            &json!({"ops": [op]}),
        )
        .await
        .assert_error(422, "invalid_transform");
    }
    h.assert_unchanged(&before).await;
    // A unit rotation and positive scales are a placement.
    let r = h
        .json(
            Method::POST,
            "/v1/objects",
            Some(&h.alice),
            &json!({"model": model, "translation": [0, 0, 0],
                    "rotation": [0, 0.70710677, 0, 0.70710677], "scale": [1, 2, 3]}),
        )
        .await;
    r.assert_status(201);
}

#[tokio::test]
async fn an_unknown_model_is_422() {
    let h = Harness::new("unknownmodel");
    h.model(cube_glb(1)).await;
    let before = h.stored().await;
    for model in ["0".repeat(64), "nope".to_owned(), String::new()] {
        h.json(
            Method::POST,
            "/v1/objects",
            Some(&h.alice),
            &json!({"model": model, "translation": [0, 0, 0]}),
        )
        .await
        .assert_error(422, "unknown_model");
    }
    h.assert_unchanged(&before).await;
}

#[tokio::test]
async fn unknown_and_non_numeric_object_ids_are_404() {
    let h = Harness::new("unknownobject");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    for missing in [
        (id + 1000).to_string(),
        "abc".to_owned(),
        "-1".to_owned(),
        "1.5".to_owned(),
        "18446744073709551616".to_owned(),
    ] {
        let uri = format!("/v1/objects/{missing}");
        h.get(&uri).await.assert_error(404, "not_found");
        h.json(
            Method::PATCH,
            &uri,
            Some(&h.alice),
            &json!({"translation": [1, 1, 1]}),
        )
        .await
        .assert_error(404, "not_found");
        h.delete(&uri, Some(&h.alice))
            .await
            .assert_error(404, "not_found");
    }
    h.assert_unchanged(&before).await;
}

// ---------------------------------------------------------------------------------------------
// Tokens, owners, quotas
// ---------------------------------------------------------------------------------------------

#[tokio::test]
async fn writes_need_a_token_this_world_issued() {
    let h = Harness::new("auth");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    let unknown = "0123456789abcdef".repeat(4);
    let headers: [Option<String>; 7] = [
        None,
        Some("Basic YWxpY2U6c2VjcmV0".into()),
        Some("Bearer".into()),
        Some("Bearer ".into()),
        Some(h.alice.clone()),
        Some(format!("Bearer {unknown}")),
        Some(format!("Bearer {}", "x".repeat(300))),
    ];
    let object = json!({"model": model, "translation": [1, 1, 1]});
    for header in &headers {
        let with = |b: axum::http::request::Builder| match header {
            Some(v) => b.header(AUTHORIZATION, v.as_str()),
            None => b,
        };
        let requests = [
            with(Request::post("/v1/models"))
                .header(CONTENT_TYPE, "model/gltf-binary")
                .body(Body::from(cube_glb(2)))
                .unwrap(),
            with(Request::post("/v1/objects"))
                .header(CONTENT_TYPE, "application/json")
                .body(Body::from(object.to_string()))
                .unwrap(),
            with(Request::patch(format!("/v1/objects/{id}")))
                .header(CONTENT_TYPE, "application/json")
                .body(Body::from(r#"{"translation": [2, 2, 2]}"#))
                .unwrap(),
            with(Request::delete(format!("/v1/objects/{id}")))
                .body(Body::empty())
                .unwrap(),
            with(Request::post("/v1/objects/batch"))
                .header(CONTENT_TYPE, "application/json")
                .body(Body::from(r#"{"ops": []}"#))
                .unwrap(),
        ];
        for r in requests {
            let what = format!("{} {} with {header:?}", r.method(), r.uri());
            let reply = h.send(r).await;
            assert_eq!(reply.status, StatusCode::UNAUTHORIZED, "{what}");
            reply.assert_error(401, "unauthorized");
        }
    }
    h.assert_unchanged(&before).await;
    // Reads are public.
    h.get(&format!("/v1/objects/{id}")).await.assert_status(200);
}

#[tokio::test]
async fn only_the_owner_moves_or_deletes() {
    let h = Harness::new("owner");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let bobs = h.place(&h.bob, &model, [5.0, 0.0, 0.0]).await;
    let before = h.stored().await;
    let uri = format!("/v1/objects/{id}");
    h.json(
        Method::PATCH,
        &uri,
        Some(&h.bob),
        &json!({"translation": [9, 9, 9]}),
    )
    .await
    .assert_error(403, "forbidden");
    h.delete(&uri, Some(&h.bob))
        .await
        .assert_error(403, "forbidden");
    for op in [
        json!({"op": "move", "id": id, "translation": [9, 9, 9]}),
        json!({"op": "delete", "id": id}),
    ] {
        // Bob's own object first: the whole batch is refused, his part too.
        h.json(
            Method::POST,
            "/v1/objects/batch",
            Some(&h.bob),
            &json!({"ops": [{"op": "delete", "id": bobs}, op]}),
        )
        .await
        .assert_error(403, "forbidden");
    }
    h.assert_unchanged(&before).await;
    h.delete(&uri, Some(&h.alice)).await.assert_status(200);
}

#[tokio::test]
async fn the_object_past_the_quota_is_403() {
    let h = Harness::new("objectquota");
    let model = h.model(cube_glb(1)).await;
    let carol = h.world.create_token(&user("carol", Some(2), None)).unwrap();
    h.place(&carol, &model, [0.0; 3]).await;
    let second = h.place(&carol, &model, [3.0, 0.0, 0.0]).await;
    let before = h.stored().await;
    h.json(
        Method::POST,
        "/v1/objects",
        Some(&carol),
        &json!({"model": model, "translation": [6, 0, 0]}),
    )
    .await
    .assert_error(403, "quota_exceeded");
    // A batch that would pass the quota is refused whole.
    h.json(
        Method::POST,
        "/v1/objects/batch",
        Some(&carol),
        &json!({"ops": [
            {"op": "delete", "id": second},
            {"op": "create", "model": model, "translation": [6, 0, 0]},
            {"op": "create", "model": model, "translation": [9, 0, 0]},
        ]}),
    )
    .await
    .assert_error(403, "quota_exceeded");
    h.assert_unchanged(&before).await;
    // Others are not limited by carol's quota; a delete frees a place.
    h.place(&h.alice, &model, [6.0, 0.0, 0.0]).await;
    h.delete(&format!("/v1/objects/{second}"), Some(&carol))
        .await
        .assert_status(200);
    h.place(&carol, &model, [6.0, 0.0, 0.0]).await;
}

/// A world where alice has stored one cube and dave (who may store one and a half cubes'
/// bytes) another; dave's token.
async fn byte_quota(name: &str) -> (Harness, String) {
    let h = Harness::new(name);
    let stored_size = {
        let r = h.upload(cube_glb(1)).await;
        r.assert_status(201);
        r.json()["bytes"].as_u64().unwrap()
    };
    let dave = h
        .world
        .create_token(&user("dave", None, Some(stored_size + stored_size / 2)))
        .unwrap();
    h.upload_as(Some(&dave), "model/gltf-binary", cube_glb(2))
        .await
        .assert_status(201);
    (h, dave)
}

#[tokio::test]
async fn an_upload_past_the_byte_quota_is_403() {
    let (h, dave) = byte_quota("bytequota").await;
    let before = h.stored().await;
    h.upload_as(Some(&dave), "model/gltf-binary", cube_glb(3))
        .await
        .assert_error(403, "quota_exceeded");
    h.get("/healthz").await.assert_status(200);
    let after = h.stored().await;
    assert_eq!(
        (&after.world, &after.objects, &after.models),
        (&before.world, &before.objects, &before.models)
    );
    // An upload of a model already stored costs nothing; others are not held to dave's quota.
    h.upload_as(Some(&dave), "model/gltf-binary", cube_glb(1))
        .await
        .assert_status(200);
    h.upload(cube_glb(3)).await.assert_status(201);
}

/// A refused upload leaves no blob behind: otherwise a user over quota could fill the disk
/// with models that are never counted against them.
#[tokio::test]
async fn an_upload_refused_for_quota_stores_no_blob() {
    let (h, dave) = byte_quota("quotablob").await;
    let before = h.stored().await;
    let files = files_under(&h.dir.join("blobs"));
    for seed in 3..6 {
        h.upload_as(Some(&dave), "model/gltf-binary", cube_glb(seed))
            .await
            .assert_error(403, "quota_exceeded");
    }
    assert_eq!(
        files_under(&h.dir.join("blobs")),
        files,
        "files under blobs/"
    );
    h.assert_unchanged(&before).await;
}

/// A request that outlasts `request_timeout` (here: a body that never arrives) is answered
/// with the contract's 503, as JSON.
#[tokio::test]
async fn a_request_past_the_timeout_is_503() {
    let config = Config {
        request_timeout: std::time::Duration::from_millis(200),
        ..test_config()
    };
    let h = Harness::with("timeout", config, UploadLimits::default());
    let before = h.stored().await;
    for (uri, media) in [
        ("/v1/objects", "application/json"),
        ("/v1/models", "model/gltf-binary"),
    ] {
        let r = h
            .send(
                request(Method::POST, uri, Some(&h.alice))
                    .header(CONTENT_TYPE, media)
                    .body(Body::new(Stalled))
                    .unwrap(),
            )
            .await;
        r.assert_error(503, "overloaded");
    }
    h.assert_unchanged(&before).await;
}

/// A body whose first byte never comes.
struct Stalled;

impl http_body::Body for Stalled {
    type Data = Bytes;
    type Error = Infallible;

    fn poll_frame(
        self: Pin<&mut Self>,
        _: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, Infallible>>> {
        Poll::Pending
    }
}

// ---------------------------------------------------------------------------------------------
// JSON bodies
// ---------------------------------------------------------------------------------------------

/// Sends each `(method, uri, body)` as alice's JSON, and collects every reply that is not the
/// error `status` `code`.
async fn expect_errors(
    h: &Harness,
    cases: &[(Method, String, String)],
    status: u16,
    code: &str,
) -> Vec<String> {
    let mut failures = Vec::new();
    for (method, uri, body) in cases {
        let r = h.json_text(method.clone(), uri, Some(&h.alice), body).await;
        if let Some(why) = r.error_mismatch(status, code) {
            failures.push(format!("{method} {uri} {body}: {why}"));
        }
    }
    failures
}

#[tokio::test]
async fn malformed_json_and_unknown_fields_are_400() {
    let h = Harness::new("json");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    let post = |body: String| (Method::POST, "/v1/objects".to_owned(), body);
    let patch = |body: &str| (Method::PATCH, format!("/v1/objects/{id}"), body.to_owned());
    let cases = [
        post(String::new()),
        post("{".to_owned()),
        post(format!(
            r#"{{"model": "{model}", "translation": [0, 0, 0],}}"#
        )),
        post(format!(r#"{{"model": "{model}", "translation": [0, 0]}}"#)),
        post(format!(r#"{{"model": "{model}", "translation": "here"}}"#)),
        post(format!(r#"{{"model": "{model}"}}"#)),
        post(format!(
            r#"{{"model": "{model}", "translation": [0, 0, 0], "colour": "red"}}"#
        )),
        post(format!(
            r#"{{"model": "{model}", "translation": [0, 0, 0], "scale": {{"x": 1}}}}"#
        )),
        post("[]".to_owned()),
        post("null".to_owned()),
        patch("{"),
        patch(r#"{"translation": [1, 1, 1], "colour": "red"}"#),
        patch(r#"{"translation": [1, 1]}"#),
        patch(r#"{"id": 4}"#),
    ];
    let failures = expect_errors(&h, &cases, 400, "malformed_json").await;
    assert!(failures.is_empty(), "{failures:#?}");
    h.assert_unchanged(&before).await;
}

/// A batch is JSON too: an unknown field in any of its operations is refused, whichever the
/// operation.
#[tokio::test]
async fn batches_with_unknown_fields_are_400() {
    let h = Harness::new("batchjson");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    let batch = |body: String| (Method::POST, "/v1/objects/batch".to_owned(), body);
    let cases = [
        batch("{".to_owned()),
        batch(r#"{"ops": [], "atomic": true}"#.to_owned()),
        batch(r#"{"ops": [{"op": "teleport", "id": 1}]}"#.to_owned()),
        batch(r#"{"ops": [{"op": "delete"}]}"#.to_owned()),
        batch(format!(
            r#"{{"ops": [{{"op": "create", "model": "{model}", "translation": [0, 0, 0], "colour": 1}}]}}"#
        )),
        batch(format!(
            r#"{{"ops": [{{"op": "move", "id": {id}, "translation": [0, 0, 0], "colour": 1}}]}}"#
        )),
        batch(format!(
            r#"{{"ops": [{{"op": "move", "id": {id}, "translate": [5, 5, 5]}}]}}"#
        )),
        batch(format!(
            r#"{{"ops": [{{"op": "delete", "id": {id}, "colour": 1}}]}}"#
        )),
    ];
    let failures = expect_errors(&h, &cases, 400, "malformed_json").await;
    assert!(failures.is_empty(), "{failures:#?}");
    h.assert_unchanged(&before).await;
}

#[tokio::test]
async fn objects_need_json() {
    let h = Harness::new("media-objects");
    let model = h.model(cube_glb(1)).await;
    let id = h.place(&h.alice, &model, [0.0; 3]).await;
    let before = h.stored().await;
    let object = json!({"model": model, "translation": [1, 1, 1]}).to_string();
    let patch = r#"{"translation": [1, 1, 1]}"#;
    for media in [
        Some("text/plain"),
        Some("application/x-www-form-urlencoded"),
        None,
    ] {
        let with = |b: axum::http::request::Builder| match media {
            Some(m) => b.header(CONTENT_TYPE, m),
            None => b,
        };
        for (method, uri, body) in [
            (Method::POST, "/v1/objects".to_owned(), object.clone()),
            (Method::PATCH, format!("/v1/objects/{id}"), patch.to_owned()),
            (
                Method::POST,
                "/v1/objects/batch".to_owned(),
                r#"{"ops": []}"#.to_owned(),
            ),
        ] {
            h.send(
                with(request(method, &uri, Some(&h.alice)))
                    .body(Body::from(body))
                    .unwrap(),
            )
            .await
            .assert_error(415, "unsupported_media_type");
        }
    }
    h.assert_unchanged(&before).await;
    let r = h
        .send(
            request(Method::POST, "/v1/objects", Some(&h.alice))
                .header(CONTENT_TYPE, "application/json; charset=utf-8")
                .body(Body::from(object))
                .unwrap(),
        )
        .await;
    r.assert_status(201);
}

// ---------------------------------------------------------------------------------------------
// Batches
// ---------------------------------------------------------------------------------------------

#[tokio::test]
async fn a_batch_that_fails_in_its_last_op_applies_nothing() {
    let h = Harness::new("batchfail");
    let model = h.model(cube_glb(1)).await;
    let a = h.place(&h.alice, &model, [0.0; 3]).await;
    let b = h.place(&h.alice, &model, [3.0, 0.0, 0.0]).await;
    let before = h.stored().await;
    let good = [
        json!({"op": "create", "model": model, "translation": [6, 0, 0]}),
        json!({"op": "move", "id": a, "translation": [0, 5, 0]}),
        json!({"op": "delete", "id": b}),
    ];
    let cases = [
        (
            json!({"op": "create", "model": "0".repeat(64), "translation": [0, 0, 0]}),
            422,
            "unknown_model",
        ),
        (json!({"op": "delete", "id": b + 100}), 404, "not_found"),
        (
            json!({"op": "move", "id": b + 100, "translation": [1, 1, 1]}),
            404,
            "not_found",
        ),
        // Deleted earlier in the same batch.
        (json!({"op": "delete", "id": b}), 404, "not_found"),
    ];
    for (last, status, code) in cases {
        let mut ops = good.to_vec();
        ops.push(last);
        h.json(
            Method::POST,
            "/v1/objects/batch",
            Some(&h.alice),
            &json!({ "ops": ops }),
        )
        .await
        .assert_error(status, code);
        h.assert_unchanged(&before).await;
    }
}

#[tokio::test]
async fn a_good_batch_applies_every_op() {
    let h = Harness::new("batchgood");
    let model = h.model(cube_glb(1)).await;
    let a = h.place(&h.alice, &model, [0.0; 3]).await;
    let b = h.place(&h.alice, &model, [3.0, 0.0, 0.0]).await;
    let generation = h.world_info().await["generation"].as_u64().unwrap();
    let r = h
        .json(
            Method::POST,
            "/v1/objects/batch",
            Some(&h.alice),
            &json!({"ops": [
                {"op": "create", "model": model, "translation": [6, 0, 0], "scale": 2},
                {"op": "move", "id": a, "translation": [0, 5, 0]},
                {"op": "move", "id": a, "scale": 3},
                {"op": "delete", "id": b},
            ]}),
        )
        .await;
    r.assert_status(200);
    let reply = r.json();
    let ids: Vec<u64> = reply["ids"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(ids.len(), 4);
    let created = ids[0];
    assert_eq!(&ids[1..], &[a, a, b]);
    assert!(created != a && created != b);
    let w = h.world_info().await;
    assert!(reply["generation"].as_u64().unwrap() > generation);
    assert_eq!(w["generation"], reply["generation"]);
    assert_eq!(w["objects"], 2);

    let new = h.get(&format!("/v1/objects/{created}")).await;
    new.assert_status(200);
    assert_eq!(new.json()["translation"], json!([6.0, 0.0, 0.0]));
    assert_eq!(new.json()["scale"], json!([2.0, 2.0, 2.0]));
    let moved = h.get(&format!("/v1/objects/{a}")).await.json();
    // The second move started from where the first left the object.
    assert_eq!(moved["translation"], json!([0.0, 5.0, 0.0]));
    assert_eq!(moved["scale"], json!([3.0, 3.0, 3.0]));
    h.get(&format!("/v1/objects/{b}"))
        .await
        .assert_error(404, "not_found");

    // More than 10,000 operations are refused whole.
    let before = h.stored().await;
    let ops = vec![json!({"op": "delete", "id": created}); 10_001];
    h.json(
        Method::POST,
        "/v1/objects/batch",
        Some(&h.alice),
        &json!({ "ops": ops }),
    )
    .await
    .assert_error(413, "too_large");
    h.assert_unchanged(&before).await;

    // An empty batch applies nothing and answers the current generation.
    let r = h
        .json(
            Method::POST,
            "/v1/objects/batch",
            Some(&h.alice),
            &json!({"ops": []}),
        )
        .await;
    r.assert_status(200);
    assert_eq!(r.json(), json!({"generation": w["generation"], "ids": []}));
}

// ---------------------------------------------------------------------------------------------
// Assets
// ---------------------------------------------------------------------------------------------

#[tokio::test]
async fn assets_are_immutable_ranged_and_compressed() {
    let h = Harness::new("assets");
    let r = h.upload(glb(&cube(1, 2, Some((16, 16))))).await;
    r.assert_status(201);
    let info = r.json();
    let hash = info["asset"].as_str().unwrap().to_owned();
    let uri = format!("/assets/{hash}");
    let etag = format!("\"{hash}\"");

    let whole = h.get(&uri).await;
    whole.assert_status(200);
    assert_eq!(whole.header(ETAG), Some(etag.as_str()));
    assert_eq!(
        whole.header(CACHE_CONTROL),
        Some("public, max-age=31536000, immutable")
    );
    assert_eq!(whole.header(CONTENT_ENCODING), None);
    assert_eq!(whole.header(CONTENT_TYPE), Some("model/gltf-binary"));
    let bytes = whole.body.clone();
    assert_eq!(bytes.len() as u64, info["bytes"].as_u64().unwrap());
    assert_eq!(
        horizon_world::content_hash(&bytes),
        hash,
        "the name is the hash"
    );
    assert!(bytes.len() > 100);

    let send = |headers: Vec<(axum::http::HeaderName, String)>| {
        let mut b = Request::get(&uri);
        for (k, v) in headers {
            b = b.header(k, v);
        }
        h.send(b.body(Body::empty()).unwrap())
    };

    let r = send(vec![(IF_NONE_MATCH, etag.clone())]).await;
    r.assert_status(304);
    assert!(r.body.is_empty());
    assert_eq!(r.header(ETAG), Some(etag.as_str()));
    let r = send(vec![(
        IF_NONE_MATCH,
        format!("\"{}\", {etag}", "a".repeat(64)),
    )])
    .await;
    r.assert_status(304);
    let r = send(vec![(IF_NONE_MATCH, format!("\"{}\"", "a".repeat(64)))]).await;
    r.assert_status(200);
    assert_eq!(r.body, bytes);

    let r = send(vec![(RANGE, "bytes=0-9".into())]).await;
    r.assert_status(206);
    let len = bytes.len();
    assert_eq!(
        r.header(CONTENT_RANGE),
        Some(format!("bytes 0-9/{len}").as_str())
    );
    assert_eq!(&r.body[..], &bytes[..10]);
    assert_eq!(r.header(ETAG), Some(etag.as_str()));
    let r = send(vec![(RANGE, format!("bytes={}-", len - 5))]).await;
    r.assert_status(206);
    assert_eq!(&r.body[..], &bytes[len - 5..]);
    assert_eq!(
        r.header(CONTENT_RANGE),
        Some(format!("bytes {}-{}/{len}", len - 5, len - 1).as_str())
    );

    for range in [
        format!("bytes={len}-{}", len + 10),
        format!("bytes={}-", len + 100),
    ] {
        let r = send(vec![(RANGE, range.clone())]).await;
        assert_eq!(r.status, StatusCode::RANGE_NOT_SATISFIABLE, "{range}");
        assert_eq!(
            r.header(CONTENT_RANGE),
            Some(format!("bytes */{len}").as_str())
        );
    }

    let r = send(vec![(ACCEPT_ENCODING, "zstd".into())]).await;
    r.assert_status(200);
    assert_eq!(r.header(CONTENT_ENCODING), Some("zstd"));
    assert_eq!(r.header(ETAG), Some(etag.as_str()));
    let decoded = zstd::decode_all(&r.body[..]).expect("the body is zstd");
    assert_eq!(decoded, bytes);
    let r = send(vec![
        (ACCEPT_ENCODING, "zstd".into()),
        (RANGE, "bytes=0-9".into()),
    ])
    .await;
    r.assert_status(206);
    assert_eq!(
        r.header(CONTENT_ENCODING),
        None,
        "a range is never re-encoded"
    );
    assert_eq!(&r.body[..], &bytes[..10]);

    let before = h.stored().await;
    for bad in [
        "abc".to_owned(),
        hash[..63].to_owned(),
        format!("{hash}0"),
        hash.to_uppercase(),
        format!("{}g", &hash[..63]),
        "..%2F..%2Fworld.db".to_owned(),
    ] {
        h.get(&format!("/assets/{bad}"))
            .await
            .assert_error(404, "not_found");
    }
    h.get(&format!("/assets/{}", "0".repeat(64)))
        .await
        .assert_error(404, "not_found");
    // A hash of bytes that were never stored.
    h.get(&format!(
        "/assets/{}",
        horizon_world::content_hash(b"never stored")
    ))
    .await
    .assert_error(404, "not_found");
    h.assert_unchanged(&before).await;
}
