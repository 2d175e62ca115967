//! The world service (`DESIGN.md`, "Service contract (v1)"): [`app`] builds the router over a
//! shared [`AppState`], and [`run`] serves it on a listener, with the rebuild worker beside
//! it, until a shutdown signal.
//!
//! # Layout
//! - `mod.rs`: [`Config`], [`AppState`], [`app`], [`run`], the middleware stack (request ids,
//!   tracing, compression, timeouts and panics as the contract's errors, metrics).
//! - `error.rs`: [`AppError`], every failure as the contract's JSON error.
//! - `auth.rs`: bearer tokens.
//! - `routes/`: one file per resource: `world.rs`, `models.rs`, `objects.rs`, `assets.rs`,
//!   `meta.rs` (health, metrics, OpenAPI, the index page).
//! - `cut.rs`: the served cut, planned under a view's budgets, and the delta between two.
//! - `stream.rs`: `GET /v1/stream`, standing queries over WebSocket.
//! - `rebuild.rs`: the background worker that debounces changes and publishes generations.

mod auth;
pub mod cut;
mod error;
mod rebuild;
mod routes;
mod stream;

use std::future::Future;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use axum::extract::{MatchedPath, Request, State};
use axum::http::{HeaderName, HeaderValue};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::Router;
use horizon_aggregate::AggregateOptions;
use horizon_world::World;
use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle};
use tokio::net::TcpListener;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::predicate::{DefaultPredicate, Predicate};
use tower_http::compression::CompressionLayer;
use tower_http::request_id::{
    MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer,
};
use tower_http::trace::TraceLayer;
use utoipa::OpenApi;

pub use error::{AppError, AppResult};
pub use rebuild::Rebuilder;

/// How the service runs. Start from [`Config::default`].
#[derive(Clone, Debug)]
pub struct Config {
    /// Largest request body, bytes. Default 64 MiB (a model upload).
    pub body_limit: usize,
    /// Longest a request may take before it is answered with 503. Default 60 s.
    pub request_timeout: Duration,
    /// Quiet time after the last change before a rebuild starts. Default 250 ms.
    pub debounce_quiet: Duration,
    /// Longest a change waits for its rebuild. Default 2 s.
    pub debounce_max: Duration,
    /// The options every aggregate is built with.
    pub aggregates: AggregateOptions,
    /// Whether `run` starts the rebuild worker. Default true.
    pub rebuild: bool,
    /// The stream's limits.
    pub stream: StreamLimits,
}

/// The limits of `GET /v1/stream`. Going over one closes the connection with 1008 (policy)
/// or 1009 (too big), the reason being the error code.
#[derive(Clone, Copy, Debug)]
pub struct StreamLimits {
    /// Largest client message, bytes. Default 64 KiB.
    pub max_message_bytes: usize,
    /// Messages per second a connection may send, on average over a burst of twice as many.
    /// Default 100.
    pub messages_per_second: u32,
    /// Open streams in all. Default 10,000.
    pub max_connections: usize,
    /// Open streams from one IP address. Default 2,000.
    pub max_connections_per_ip: usize,
    /// Unacknowledged messages a client that acknowledges may have outstanding before
    /// further changes wait (and coalesce) for its next ack. Default 8.
    pub window: u64,
    /// Longest one message may take to go out before the client counts as gone. Default
    /// 30 s.
    pub send_timeout: Duration,
}

impl Default for StreamLimits {
    fn default() -> Self {
        Self {
            max_message_bytes: 64 << 10,
            messages_per_second: 100,
            max_connections: 10_000,
            max_connections_per_ip: 2_000,
            window: 8,
            send_timeout: Duration::from_secs(30),
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Self {
            body_limit: 64 << 20,
            request_timeout: Duration::from_secs(60),
            debounce_quiet: Duration::from_millis(250),
            debounce_max: Duration::from_secs(2),
            aggregates: AggregateOptions::default(),
            rebuild: true,
            stream: StreamLimits::default(),
        }
    }
}

/// What every handler shares: the world, the configuration, the metrics.
#[derive(Clone, Debug)]
pub struct AppState {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    world: Arc<World>,
    config: Config,
    metrics: PrometheusHandle,
    /// Every model's asset, for cuts.
    models: cut::AssetTable,
    /// Counts commits and publishes: streams wait on it.
    changes: tokio::sync::watch::Sender<u64>,
    /// Set when the server shuts down: streams close with 1001.
    closing: tokio::sync::watch::Sender<bool>,
    /// Open streams, in all and by address.
    streams: stream::Connections,
}

impl AppState {
    /// The state of a service over `world`.
    pub fn new(world: Arc<World>, config: Config) -> Self {
        let models = cut::AssetTable::default();
        if let Err(e) = models.refresh(&world) {
            tracing::warn!(error = %e, "the model table is read on the first cut instead");
        }
        let (changes, _) = tokio::sync::watch::channel(0);
        {
            let changes = changes.clone();
            world.on_change(move || changes.send_modify(|n| *n += 1));
        }
        Self {
            inner: Arc::new(Inner {
                world,
                config,
                metrics: prometheus(),
                models,
                changes,
                closing: tokio::sync::watch::channel(false).0,
                streams: stream::Connections::default(),
            }),
        }
    }

    /// Plans the cut for `view` on the world as it is now (see `cut.rs`), reading new
    /// models first if the plan met one.
    pub fn plan(
        &self,
        view: &horizon_protocol::View,
    ) -> Result<cut::Plan, horizon_world::WorldError> {
        self.plan_after(view, None)
    }

    /// [`AppState::plan`] for a client holding `held` (its objects keep their levels of
    /// detail within the margin, `cut::plan_after`).
    pub fn plan_after(
        &self,
        view: &horizon_protocol::View,
        held: Option<&cut::Plan>,
    ) -> Result<cut::Plan, horizon_world::WorldError> {
        self.plan_with(view, held, cut::Coarsening::AsAsked)
    }

    /// [`AppState::plan_after`] with the coarsening of levels under a binding budget given
    /// (`cut::plan_with`): what the lab and the tests compare the service's plans with.
    pub fn plan_with(
        &self,
        view: &horizon_protocol::View,
        held: Option<&cut::Plan>,
        coarsening: cut::Coarsening,
    ) -> Result<cut::Plan, horizon_world::WorldError> {
        let world = &self.inner.world;
        let models = &self.inner.models;
        let plan_now =
            || world.with_served(|served| cut::plan_with(served, models, view, held, coarsening));
        let plan = plan_now()?;
        if plan.missing_models == 0 {
            return Ok(plan);
        }
        models.refresh(world)?;
        plan_now()
    }

    /// One cut at `view`, off the async runtime.
    pub async fn cut(
        &self,
        view: horizon_protocol::View,
    ) -> AppResult<horizon_protocol::CutResponse> {
        let state = self.clone();
        let plan = tokio::task::spawn_blocking(move || state.plan(&view)).await??;
        Ok(horizon_protocol::CutResponse {
            generation: plan.generation,
            published: plan.published,
            objects: plan.objects,
            entries: plan.entries(),
            stopped_by: plan.stopped_by,
        })
    }

    /// The world.
    pub fn world(&self) -> &Arc<World> {
        &self.inner.world
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.inner.config
    }

    /// Open streams.
    fn streams(&self) -> &stream::Connections {
        &self.inner.streams
    }

    /// A receiver that sees every commit and publish from now on.
    fn closing(&self) -> tokio::sync::watch::Receiver<bool> {
        self.inner.closing.subscribe()
    }

    fn changes(&self) -> tokio::sync::watch::Receiver<u64> {
        self.inner.changes.subscribe()
    }

    /// Runs blocking work (the database, ingest, the tree) off the async runtime.
    pub async fn blocking<T, F>(&self, f: F) -> AppResult<T>
    where
        T: Send + 'static,
        F: FnOnce(&World) -> Result<T, horizon_world::WorldError> + Send + 'static,
    {
        let world = self.inner.world.clone();
        Ok(tokio::task::spawn_blocking(move || f(&world)).await??)
    }
}

/// The process's one Prometheus recorder (metrics are process-global).
fn prometheus() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            let recorder = PrometheusBuilder::new().build_recorder();
            let handle = recorder.handle();
            // Another recorder installed first (a test harness) keeps its place; this one
            // then renders what it records itself, which is nothing.
            let _ = metrics::set_global_recorder(recorder);
            handle
        })
        .clone()
}

/// The OpenAPI document's root; the routes add their paths (`routes::meta::document`).
#[derive(OpenApi)]
#[openapi(info(
    title = "Horizon",
    description = "A world server for large user-generated 3D worlds: upload models, place \
                   objects, and fetch immutable, content-addressed assets."
))]
pub(crate) struct ApiDoc;

/// The service's router over `state` (see the module docs for the middleware).
pub fn app(state: AppState) -> Router {
    let (router, _) = routes::router().split_for_parts();
    let timeout = state.config().request_timeout;
    router
        .route("/web/{*path}", axum::routing::get(routes::web::file))
        .fallback(routes::meta::not_found)
        .method_not_allowed_fallback(routes::meta::method_not_allowed)
        .with_state(state.clone())
        .layer(middleware::from_fn_with_state(state, record_metrics))
        .layer(
            CompressionLayer::new()
                .zstd(true)
                .gzip(true)
                .compress_when(DefaultPredicate::new().and(NotPartial)),
        )
        .layer(middleware::from_fn(move |request: Request, next: Next| {
            time_limited(timeout, request, next)
        }))
        .layer(CatchPanicLayer::custom(
            |panic: Box<dyn std::any::Any + Send>| {
                let detail = panic
                    .downcast_ref::<&str>()
                    .map(|s| (*s).to_owned())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                AppError::internal(format!("a handler panicked: {detail}")).into_response()
            },
        ))
        .layer(PropagateRequestIdLayer::new(REQUEST_ID.clone()))
        .layer(
            TraceLayer::new_for_http().make_span_with(|request: &Request| {
                let id = request
                    .headers()
                    .get(&REQUEST_ID)
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("-");
                tracing::info_span!("request", id, method = %request.method(), uri = %request.uri())
            }),
        )
        .layer(SetRequestIdLayer::new(
            REQUEST_ID.clone(),
            Counter::default(),
        ))
}

/// The header that carries a request's id, set when the client sent none.
static REQUEST_ID: HeaderName = HeaderName::from_static("x-request-id");

/// Request ids: a process-unique counter, so that log lines and responses can be matched.
#[derive(Clone, Debug, Default)]
struct Counter(Arc<AtomicU64>);

impl MakeRequestId for Counter {
    fn make_request_id<B>(&mut self, _: &axum::http::Request<B>) -> Option<RequestId> {
        let n = self.0.fetch_add(1, Ordering::Relaxed) + 1;
        HeaderValue::from_str(&n.to_string())
            .ok()
            .map(RequestId::new)
    }
}

/// Partial responses are sent as the bytes they name, never re-encoded.
#[derive(Clone, Copy, Debug)]
struct NotPartial;

impl Predicate for NotPartial {
    fn should_compress<B>(&self, response: &axum::http::Response<B>) -> bool
    where
        B: axum::body::HttpBody,
    {
        response.status() != axum::http::StatusCode::PARTIAL_CONTENT
    }
}

/// Answers a request that outlasts `limit` with the contract's 503 `overloaded`.
async fn time_limited(limit: Duration, request: Request, next: Next) -> Response {
    match tokio::time::timeout(limit, next.run(request)).await {
        Ok(response) => response,
        Err(_) => AppError::new(
            horizon_protocol::ErrorCode::Overloaded,
            format!("the request took longer than {} s", limit.as_secs_f64()),
        )
        .into_response(),
    }
}

/// Counts requests and times them by route and status.
async fn record_metrics(State(_): State<AppState>, request: Request, next: Next) -> Response {
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched".to_owned(), |m| m.as_str().to_owned());
    let method = request.method().to_string();
    let started = Instant::now();
    let response = next.run(request).await;
    let status = response.status().as_u16().to_string();
    let labels = [("route", route), ("method", method), ("status", status)];
    metrics::counter!("horizon_requests_total", &labels).increment(1);
    metrics::histogram!("horizon_request_seconds", &labels).record(started.elapsed().as_secs_f64());
    response
}

/// Serves `state` on `listener` until `shutdown` completes: the rebuild worker runs beside
/// the server (if the configuration asks for it); on shutdown the server stops accepting,
/// finishes the requests in flight, and the worker stops at its next safe point.
pub async fn run(
    listener: TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let rebuilder = state
        .config()
        .rebuild
        .then(|| Rebuilder::spawn(state.world().clone(), state.config().clone()));
    let closing = state.inner.closing.clone();
    let streams = state.clone();
    let app = app(state).into_make_service_with_connect_info::<std::net::SocketAddr>();
    let served = axum::serve(listener, app)
        .with_graceful_shutdown(async move {
            shutdown.await;
            // Open streams say goodbye (1001) rather than being cut off.
            closing.send_replace(true);
        })
        .await;
    // Give the streams a moment to send their close frames.
    let deadline = Instant::now() + Duration::from_secs(1);
    while streams.streams().open() > 0 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    if let Some(r) = rebuilder {
        tokio::task::spawn_blocking(move || r.stop())
            .await
            .map_err(std::io::Error::other)?;
    }
    served
}

/// Completes on SIGTERM or Ctrl-C.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = terminate => {},
    }
    tracing::info!("shutting down");
}
