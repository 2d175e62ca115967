//! `GET /v1/stream`: a standing query over WebSocket (`DESIGN.md`, "WebSocket messages").
//!
//! Each connection is two tasks:
//! - the **reader** parses the client's messages. A view replaces the one before it (the
//!   server keeps only the latest); an ack records how far the client has applied. A bad
//!   message gets an `error` message and the connection goes on. Going over a limit (message
//!   size, messages per second) closes the connection with 1009 or 1008.
//! - the **writer** waits until the view or the world changed, plans the cut at the latest
//!   view on the world as it is then (`cut.rs`), and sends the delta from the cut the client
//!   holds: one atomic, numbered message, or nothing when the cut did not change. While a
//!   message is going out, or while a client that acknowledges has `window` messages
//!   unacknowledged, later views and changes wait and coalesce into the next delta.
//!
//! So a connection holds its latest view, the cut its client holds, and at most a few small
//! messages: nothing grows with how far behind the client is, since however much changed
//! while it was behind comes as one delta (never larger than the cut plus the ids it
//! drops). A client that acknowledges a message it was never sent, or one before its last
//! acknowledgement, gets an error and then a `reset` with the whole cut. A client that stops
//! reading is dropped once one message has taken `send_timeout` to go out.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, FromRequestParts, State};
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use horizon_protocol::{ClientMessage, ErrorBody, ErrorCode, ErrorDetail, ServerMessage, View};
use tokio::sync::{mpsc, watch};

use super::cut::Plan;
use super::{AppError, AppState, StreamLimits};

/// Close code: the message was over the size limit.
const TOO_BIG: u16 = 1009;
/// Close code: a policy was broken (rate, connection limits, a slow consumer).
const POLICY: u16 = 1008;
/// Close code: the server is going away (shutting down).
const GOING_AWAY: u16 = 1001;

/// How long a closing connection waits for the client's close reply.
const LINGER: std::time::Duration = std::time::Duration::from_secs(1);

/// Open streams, in all and by client address.
#[derive(Debug, Default)]
pub struct Connections {
    total: AtomicUsize,
    by_ip: Mutex<HashMap<IpAddr, usize>>,
}

impl Connections {
    /// Streams open now.
    pub fn open(&self) -> usize {
        self.total.load(Ordering::SeqCst)
    }
}

/// One open stream's place in [`Connections`], given back when dropped.
struct Slot {
    state: AppState,
    ip: Option<IpAddr>,
}

impl Drop for Slot {
    fn drop(&mut self) {
        let c = self.state.streams();
        c.total.fetch_sub(1, Ordering::SeqCst);
        if let (Some(ip), Ok(mut by_ip)) = (self.ip, c.by_ip.lock()) {
            if let Some(n) = by_ip.get_mut(&ip) {
                *n -= 1;
                if *n == 0 {
                    by_ip.remove(&ip);
                }
            }
        }
        metrics::gauge!("horizon_standing_queries").decrement(1.0);
    }
}

/// Takes a place for a new stream, or says which limit is full.
fn admit(state: &AppState, ip: Option<IpAddr>) -> Result<Slot, (ErrorCode, String)> {
    let limits = state.config().stream;
    let c = state.streams();
    let total = c.total.fetch_add(1, Ordering::SeqCst) + 1;
    let mut slot = Slot {
        state: state.clone(),
        ip: None,
    };
    metrics::gauge!("horizon_standing_queries").increment(1.0);
    if total > limits.max_connections {
        return Err((
            ErrorCode::Overloaded,
            format!(
                "the server holds its limit of {} streams",
                limits.max_connections
            ),
        ));
    }
    if let Some(ip) = ip {
        let Ok(mut by_ip) = c.by_ip.lock() else {
            return Err((ErrorCode::Internal, "connection table lock poisoned".into()));
        };
        let n = by_ip.entry(ip).or_insert(0);
        if *n >= limits.max_connections_per_ip {
            return Err((
                ErrorCode::RateLimited,
                format!(
                    "{ip} holds its limit of {} streams",
                    limits.max_connections_per_ip
                ),
            ));
        }
        *n += 1;
        slot.ip = Some(ip);
    }
    Ok(slot)
}

/// The client's address, when the server was started with connection info (tests that call
/// the router directly have none, and are not limited per address).
#[derive(Debug)]
pub struct ClientIp(Option<IpAddr>);

impl<S: Send + Sync> FromRequestParts<S> for ClientIp {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, Self::Rejection> {
        Ok(Self(
            parts
                .extensions
                .get::<ConnectInfo<SocketAddr>>()
                .map(|c| c.0.ip()),
        ))
    }
}

/// Opens a standing query: send `view` messages, receive a `reset` and then deltas.
#[utoipa::path(get, path = "/v1/stream", tag = "cuts",
    responses(
        (status = 101, description = "Switching to the WebSocket protocol; messages in DESIGN.md"),
        (status = 400, description = "Not a WebSocket upgrade", body = ErrorBody),
    ))]
pub async fn stream(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    upgrade: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Response {
    let upgrade = match upgrade {
        Ok(upgrade) => upgrade,
        // Not a WebSocket handshake: the contract's JSON error, not axum's text.
        Err(rejection) => {
            return AppError::new(
                ErrorCode::BadQuery,
                format!(
                    "this route takes a WebSocket upgrade: {}",
                    rejection.body_text()
                ),
            )
            .into_response();
        }
    };
    let limits = state.config().stream;
    // Messages over the limit are read and refused with 1009 here, so that the socket stays
    // in step and the close frame reaches the client; only messages far over it are cut off
    // by the WebSocket layer itself.
    let hard_limit = limits.max_message_bytes.saturating_mul(4);
    upgrade
        .max_message_size(hard_limit)
        .max_frame_size(hard_limit)
        .on_upgrade(move |socket| async move {
            match admit(&state, ip) {
                Ok(slot) => serve(socket, state, slot).await,
                Err((code, message)) => {
                    let mut socket = socket;
                    if socket.send(close(POLICY, code, &message)).await.is_ok() {
                        // Wait for the client's close, so that the frame is read before the
                        // socket goes.
                        let _ = tokio::time::timeout(LINGER, socket.recv()).await;
                    }
                }
            }
        })
}

/// What the reader tells the writer besides views.
#[derive(Debug)]
enum Control {
    /// Send this error message.
    Error(ErrorDetail),
    /// Send the whole cut next.
    Reset,
    /// Close with this code and error.
    Close(u16, ErrorCode, String),
}

/// What the two halves share.
#[derive(Debug, Default)]
struct Shared {
    /// The last `seq` sent.
    sent: AtomicU64,
    /// The last `seq` acknowledged (0: none yet).
    acked: AtomicU64,
    /// The id of the last view the writer planned.
    planned: AtomicU64,
}

async fn serve(socket: WebSocket, state: AppState, slot: Slot) {
    let (sink, source) = socket.split();
    let (views, latest) = watch::channel::<Option<(u64, View)>>(None);
    let (control, controls) = mpsc::channel::<Control>(8);
    let shared = Arc::new(Shared::default());
    let (acks, acked) = watch::channel(0u64);
    let limits = state.config().stream;
    let reader = tokio::spawn(read(
        source,
        views,
        control.clone(),
        acks,
        shared.clone(),
        limits,
    ));
    write(sink, state, latest, controls, acked, shared).await;
    // The reader ends at the client's close reply; a client that sends none is cut off.
    let abort = reader.abort_handle();
    if tokio::time::timeout(LINGER, reader).await.is_err() {
        abort.abort();
    }
    drop(slot);
}

/// The reader (see the module docs).
async fn read(
    mut source: SplitStream<WebSocket>,
    views: watch::Sender<Option<(u64, View)>>,
    control: mpsc::Sender<Control>,
    acks: watch::Sender<u64>,
    shared: Arc<Shared>,
    limits: StreamLimits,
) {
    let rate = f64::from(limits.messages_per_second.max(1));
    let burst = 2.0 * rate;
    let mut tokens = burst;
    let mut last = Instant::now();
    let error = |code: ErrorCode, message: String| {
        Control::Error(ErrorDetail {
            code,
            message: message.replace(['\n', '\r'], " "),
        })
    };
    let mut closing = false;
    while let Some(message) = source.next().await {
        if closing {
            // Draining until the client's close reply.
            if matches!(message, Ok(Message::Close(_)) | Err(_)) {
                break;
            }
            continue;
        }
        let text = match message {
            Ok(Message::Text(text)) => text,
            Ok(Message::Binary(_)) => {
                let _ = control.try_send(error(
                    ErrorCode::MalformedJson,
                    "the stream takes JSON text frames".into(),
                ));
                continue;
            }
            Ok(Message::Close(_)) => break,
            Ok(Message::Ping(_) | Message::Pong(_)) => continue,
            Err(_) => break,
        };
        if text.len() > limits.max_message_bytes {
            metrics::counter!("horizon_stream_closed_total", "reason" => "too_large").increment(1);
            let _ = control
                .send(Control::Close(
                    TOO_BIG,
                    ErrorCode::TooLarge,
                    format!("a message is over {} bytes", limits.max_message_bytes),
                ))
                .await;
            closing = true;
            continue;
        }
        let now = Instant::now();
        tokens = (tokens + now.duration_since(last).as_secs_f64() * rate).min(burst);
        last = now;
        tokens -= 1.0;
        if tokens < 0.0 {
            metrics::counter!("horizon_stream_closed_total", "reason" => "rate_limited")
                .increment(1);
            let _ = control
                .send(Control::Close(
                    POLICY,
                    ErrorCode::RateLimited,
                    format!("more than {rate} messages per second"),
                ))
                .await;
            closing = true;
            continue;
        }
        match serde_json::from_str::<ClientMessage>(&text) {
            Ok(ClientMessage::View { id, view }) => match view.check() {
                Ok(()) => {
                    metrics::counter!("horizon_stream_views_total").increment(1);
                    let before = views.send_replace(Some((id, view)));
                    if before.is_some_and(|(b, _)| b > shared.planned.load(Ordering::SeqCst)) {
                        // Replaced before the writer planned it.
                        metrics::counter!("horizon_stream_coalesced_total").increment(1);
                    }
                }
                Err(m) => {
                    let _ = control.try_send(error(ErrorCode::BadQuery, m));
                }
            },
            Ok(ClientMessage::Ack { seq }) => {
                let sent = shared.sent.load(Ordering::SeqCst);
                let acked = shared.acked.load(Ordering::SeqCst);
                if seq > sent || seq < acked {
                    let _ = control.try_send(error(
                        ErrorCode::BadQuery,
                        format!("ack {seq} is not between the last ack {acked} and the last message {sent}; a reset follows"),
                    ));
                    let _ = control.try_send(Control::Reset);
                } else {
                    shared.acked.store(seq, Ordering::SeqCst);
                    acks.send_replace(seq);
                }
            }
            Err(e) => {
                let code = if e.is_data() {
                    ErrorCode::BadQuery
                } else {
                    ErrorCode::MalformedJson
                };
                let _ =
                    control.try_send(error(code, format!("not a message this stream takes: {e}")));
            }
        }
    }
}

/// The writer (see the module docs).
async fn write(
    mut sink: SplitSink<WebSocket, Message>,
    state: AppState,
    mut latest: watch::Receiver<Option<(u64, View)>>,
    mut controls: mpsc::Receiver<Control>,
    mut acked: watch::Receiver<u64>,
    shared: Arc<Shared>,
) {
    let limits = state.config().stream;
    let mut changes = state.changes();
    let mut closing = state.closing();
    let mut held: Option<Plan> = None;
    let mut seq = 0u64;
    let mut reset = true;
    // Whether the view or the world changed since the last plan, and the world alone.
    let mut stale = false;
    let mut world_changed = false;
    loop {
        let waiting_for_ack = {
            let a = shared.acked.load(Ordering::SeqCst);
            a > 0 && seq.saturating_sub(a) >= limits.window
        };
        let ready = stale && !waiting_for_ack && latest.borrow().is_some();
        if !ready {
            tokio::select! {
                r = latest.changed() => {
                    if r.is_err() { return; }
                    stale = true;
                }
                r = changes.changed() => {
                    if r.is_err() { return; }
                    stale = true;
                    world_changed = true;
                }
                r = acked.changed() => {
                    if r.is_err() { return; }
                }
                _ = closing.changed() => {
                    let _ = sink.send(close(GOING_AWAY, ErrorCode::Overloaded, "the server is shutting down")).await;
                    return;
                }
                c = controls.recv() => match c {
                    None => return,
                    Some(Control::Error(error)) => {
                        let message = ServerMessage::Error { error };
                        if !send(&mut sink, &message, &limits).await {
                            return;
                        }
                    }
                    Some(Control::Reset) => {
                        reset = true;
                        stale = true;
                    }
                    Some(Control::Close(code, error, message)) => {
                        let _ = sink.send(close(code, error, &message)).await;
                        return;
                    }
                },
            }
            continue;
        }
        stale = false;
        let Some((view_id, view)) = *latest.borrow_and_update() else {
            continue;
        };
        shared.planned.store(view_id, Ordering::SeqCst);
        // With the world and the rest of the view as they were, a plan that carries to the
        // new eye is the plan planning again would make: nothing to send.
        if let (false, false, Some(h)) = (reset, world_changed, &mut held) {
            let same_rest = View {
                eye: view.eye,
                ..h.view
            } == view;
            let holds = same_rest
                && state
                    .world()
                    .with_served(|served| {
                        served.tree.generation == h.generation
                            && served.published == h.published
                            && h.carry_to(served.tree, view.eye)
                    })
                    .unwrap_or(false);
            if holds {
                metrics::counter!("horizon_stream_decisions_held_total").increment(1);
                continue;
            }
        }
        world_changed = false;
        let before = held.take();
        let want_reset = reset || before.is_none();
        let planned = {
            let state = state.clone();
            tokio::task::spawn_blocking(move || {
                let world = state.world().clone();
                let held = before.as_ref().filter(|_| !want_reset);
                let started = std::time::Instant::now();
                let plan = state.plan_after(&view, held)?;
                let kind = if held.is_some() { "after" } else { "fresh" };
                metrics::histogram!("horizon_stream_plan_seconds", "held" => kind)
                    .record(started.elapsed().as_secs_f64());
                let delta = match (&before, want_reset) {
                    (Some(before), false) => {
                        Some(world.with_served(|served| plan.diff(before, served))?)
                    }
                    _ => None,
                };
                Ok::<_, horizon_world::WorldError>((plan, delta, before))
            })
            .await
        };
        let (plan, delta, before) = match planned {
            Ok(Ok(p)) => p,
            Ok(Err(e)) => {
                tracing::error!(error = %e, "a stream's cut failed");
                let _ = sink
                    .send(close(
                        1011,
                        ErrorCode::Internal,
                        "the server failed; see its log",
                    ))
                    .await;
                return;
            }
            Err(_) => return,
        };
        let message = match delta {
            Some((add, remove)) => {
                let same_stop = before.as_ref().map(|b| b.stopped_by) == Some(plan.stopped_by);
                if add.is_empty() && remove.is_empty() && same_stop {
                    // The cut did not change, nor what stopped it: nothing to send.
                    held = Some(plan);
                    metrics::counter!("horizon_stream_unchanged_total").increment(1);
                    continue;
                }
                seq += 1;
                ServerMessage::Delta {
                    seq,
                    view: view_id,
                    generation: plan.generation,
                    published: plan.published,
                    objects: plan.objects,
                    add,
                    remove,
                    stopped_by: plan.stopped_by,
                }
            }
            None => {
                seq += 1;
                ServerMessage::Reset {
                    seq,
                    view: view_id,
                    generation: plan.generation,
                    published: plan.published,
                    objects: plan.objects,
                    entries: plan.entries(),
                    stopped_by: plan.stopped_by,
                }
            }
        };
        drop(before);
        reset = false;
        held = Some(plan);
        shared.sent.store(seq, Ordering::SeqCst);
        if !send(&mut sink, &message, &limits).await {
            return;
        }
    }
}

/// Sends one message within the send timeout; false when the client is gone or too slow.
async fn send(
    sink: &mut SplitSink<WebSocket, Message>,
    message: &ServerMessage,
    limits: &StreamLimits,
) -> bool {
    let Ok(text) = serde_json::to_string(message) else {
        return false;
    };
    let bytes = text.len();
    match tokio::time::timeout(limits.send_timeout, sink.send(Message::Text(text.into()))).await {
        Ok(Ok(())) => {
            let kind = match message {
                ServerMessage::Reset { .. } => "reset",
                ServerMessage::Delta { .. } => "delta",
                ServerMessage::Error { .. } => "error",
            };
            metrics::counter!("horizon_stream_messages_total", "type" => kind).increment(1);
            metrics::counter!("horizon_stream_bytes_total").increment(bytes as u64);
            true
        }
        Ok(Err(_)) => false,
        Err(_) => {
            metrics::counter!("horizon_stream_closed_total", "reason" => "slow_consumer")
                .increment(1);
            false
        }
    }
}

/// A close frame whose reason is the error code (the message goes to the log); a shutdown
/// (1001) says `overloaded`, the code of "try again later".
fn close(code: u16, error: ErrorCode, message: &str) -> Message {
    tracing::info!(code, ?error, message, "closing a stream");
    let reason = serde_json::to_value(error)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| "internal".into());
    Message::Close(Some(CloseFrame {
        code,
        reason: reason.into(),
    }))
}
