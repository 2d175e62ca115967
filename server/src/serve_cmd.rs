//! `horizon serve`, `horizon token create` and `horizon demo`: the world service on a
//! directory, its tokens, and the village served on first run.

use std::io::Write;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use horizon_aggregate::ImpostorPolicy;
use horizon_bvh::{DEFAULT_MU, DEFAULT_W};
use horizon_server::outln;
use horizon_server::service::{self, AppState, Config};
use horizon_server::terminal::{note, ProgressBar};
use horizon_world::{User, World};
use serde::Serialize;

/// Serves the world in `dir` (an empty world if `dir` is missing or empty) on `listen` until
/// SIGTERM or Ctrl-C. The first line on stdout is `listening on http://ADDR`, the address
/// actually bound.
pub fn serve(dir: &Path, listen: SocketAddr, impostors: ImpostorPolicy) -> anyhow::Result<()> {
    init_logging();
    let world = World::open_or_create(dir)?;
    world.set_impostors(impostors);
    serve_world(world, listen)
}

/// Runs the service over an opened world.
fn serve_world(world: World, listen: SocketAddr) -> anyhow::Result<()> {
    anyhow::ensure!(
        world.is_exclusive(),
        "another process serves or builds {}",
        world.root().display()
    );
    let world = Arc::new(world);
    // Load (or replay) the tree before taking requests, so the first cut does not wait.
    world.ensure_tree()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .with_context(|| format!("cannot listen on {listen}"))?;
        let bound = listener.local_addr()?;
        outln!("listening on http://{bound}")?;
        std::io::stdout().flush()?;
        eprintln!("horizon: open http://{bound}/ in a browser to fly the world");
        tracing::info!(%bound, dir = %world.root().display(), "serving");
        let state = AppState::new(world, Config::default());
        service::run(listener, state, service::shutdown_signal()).await?;
        Ok(())
    })
}

/// What `horizon token create --json` prints.
#[derive(Serialize)]
struct TokenReport<'a> {
    token: &'a str,
    user: &'a str,
}

/// Creates a token for `user` in the world in `dir` (an empty world if `dir` is missing or
/// empty) and prints it (once; only its hash is kept). Works while a server runs on the same
/// directory.
pub fn create_token(
    dir: &Path,
    user: &str,
    max_objects: Option<u64>,
    max_bytes: Option<u64>,
    json: bool,
) -> anyhow::Result<()> {
    let world = World::open_or_create(dir)?;
    let token = world.create_token(&User {
        name: user.to_owned(),
        max_objects,
        max_bytes,
    })?;
    if json {
        outln!(
            "{}",
            serde_json::to_string(&TokenReport {
                token: &token,
                user
            })?
        )?;
    } else {
        outln!("{token}")?;
    }
    Ok(())
}

/// `horizon demo`: the village, generated and built into `data/village` on first run, then
/// served on `listen`.
pub fn demo(data: &Path, listen: SocketAddr) -> anyhow::Result<()> {
    init_logging();
    let dir = data.join("village");
    let world = if dir.join("world.db").exists() {
        World::open(&dir)?
    } else {
        build_village(&dir)?
    };
    serve_world(world, listen)
}

/// Generates the village into `dir` and builds it: descriptors, tree, aggregates. Progress
/// goes to stderr; stdout keeps the listening line first.
fn build_village(dir: &Path) -> anyhow::Result<World> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).with_context(|| format!("cannot clear {}", dir.display()))?;
    }
    eprintln!(
        "horizon: building the village into {} (first run only)",
        dir.display()
    );
    let world = horizon_server::generated::write_world("village", dir, 1, &[])?.world;
    let bar = ProgressBar::new("describing models");
    world.describe_models(&|done, total| bar.show(done, total))?;
    bar.finish();
    let bar = ProgressBar::new("levels of detail");
    world.level_models(&|done, total| bar.show(done, total))?;
    bar.finish();
    note("building the BVH");
    world.build_tree(DEFAULT_MU, DEFAULT_W)?;
    let bar = ProgressBar::new("aggregates");
    let report =
        world.rebuild_aggregates(Config::default().aggregates, &|p| bar.show(p.done, p.total))?;
    bar.finish();
    eprintln!(
        "horizon: {} aggregates built in {:.1} s",
        report.build.built, report.build.seconds
    );
    Ok(world)
}

/// Structured logs on stderr, `info` unless `RUST_LOG` says otherwise.
fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}
