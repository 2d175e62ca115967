//! What the client's test files share: a small world of boxes with published aggregates, and
//! the real service over it on a port of 127.0.0.1.

#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use glam::{Affine3A, Vec3};
use horizon_mesh::{Instance, InstancedMesh, Submesh};
use horizon_server::service::{run, AppState, Config};
use horizon_world::{User, World};
use tokio::net::TcpListener;

/// Removes the directory however the test ends.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(name: &str) -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let dir = std::env::temp_dir().join(format!(
            "horizon-client-{name}-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A box of side `s` with its corner at the origin.
pub fn cube(s: f32) -> InstancedMesh {
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { 0.0 } else { s },
                if i & 2 == 0 { 0.0 } else { s },
                if i & 4 == 0 { 0.0 } else { s },
            )
        })
        .collect();
    let indices = vec![
        0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6,
        1, 3, 5, 3, 7, 5,
    ];
    InstancedMesh {
        submeshes: vec![Submesh {
            positions,
            indices,
            ..Submesh::default()
        }],
        instances: vec![Instance {
            submesh: 0,
            transform: Affine3A::IDENTITY,
        }],
        ..InstancedMesh::default()
    }
}

/// The side of the grid of boxes, `SPACING` metres apart.
pub const GRID: usize = 12;
pub const SPACING: f32 = 8.0;
pub const EXTENT: f64 = GRID as f64 * SPACING as f64;

/// A bound against hanging, not a timing assertion.
pub const PATIENCE: Duration = Duration::from_secs(60);

/// `GRID`^2 boxes of three sizes with their aggregates published, and alice's token.
pub fn world(dir: &TempDir) -> (Arc<World>, String) {
    let models: Vec<(String, InstancedMesh)> = [1.0, 1.5, 2.5]
        .iter()
        .enumerate()
        .map(|(i, &s)| (format!("box{i}"), cube(s)))
        .collect();
    let objects: Vec<(usize, Affine3A)> = (0..GRID * GRID)
        .map(|i| {
            let (x, z) = ((i % GRID) as f32, (i / GRID) as f32);
            (
                i % 3,
                Affine3A::from_translation(Vec3::new(x * SPACING, 0.0, z * SPACING)),
            )
        })
        .collect();
    let world = World::create(&dir.0, "client-test", 1, &models, &objects).expect("a world");
    world
        .rebuild_aggregates(Config::default().aggregates, &|_| {})
        .expect("the aggregates build");
    let token = world
        .create_token(&User {
            name: "alice".into(),
            max_objects: None,
            max_bytes: None,
        })
        .expect("a token");
    (Arc::new(world), token)
}

/// A server on a port of 127.0.0.1; dropped, it shuts down.
pub struct Server {
    pub base: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}

pub async fn serve(world: &Arc<World>, config: Config) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("an address");
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    tokio::spawn(run(
        listener,
        AppState::new(world.clone(), config),
        async move {
            let _ = stopped.await;
        },
    ));
    Server {
        base: format!("http://{addr}"),
        stop: Some(stop),
    }
}

/// A configuration whose rebuild worker publishes soon after changes.
pub fn quick_rebuilds() -> Config {
    Config {
        debounce_quiet: Duration::from_millis(100),
        debounce_max: Duration::from_millis(500),
        ..Config::default()
    }
}

pub fn http() -> reqwest::Client {
    reqwest::Client::builder()
        .no_proxy()
        .build()
        .expect("an HTTP client")
}
