//! `horizon-lab load`: the query API under load. N simulated viewers hold standing queries
//! on `GET /v1/stream` and walk seeded paths through the world, sending a view H times a
//! second; a mutation client places, moves and deletes objects R times a second. Reported:
//! camera-update-to-delta latency (p50, p99, p999), deltas per second, bytes per second per
//! viewer, views the server coalesced, carried without planning or planned to no change,
//! errors, and the server's CPU and memory (from `/proc`, when it runs on this machine).
//!
//! Latency is the time from sending a view to receiving the first message that names it
//! (`view` in a reset or delta). A view that does not change the cut gets no message and no
//! sample; a view the server coalesced into a later one gets none either (it is counted as
//! coalesced). Messages sent for a new generation name a view already answered and are not
//! latency samples.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use futures_util::{SinkExt, StreamExt};
use hdrhistogram::Histogram;
use horizon_mesh::rng::Rng;
use horizon_protocol::{Budgets, ClientMessage, ServerMessage, View, WorldInfo};
use horizon_server::outln;
use serde::Serialize;
use tokio_tungstenite::tungstenite::Message;

/// What `horizon-lab load` takes (its command-line arguments).
#[derive(Clone, Debug, clap::Args)]
pub struct Args {
    /// The server, `http://HOST:PORT`.
    pub url: String,
    /// Simulated viewers.
    #[arg(long, default_value_t = 100)]
    pub viewers: usize,
    /// View updates per second per viewer.
    #[arg(long, default_value_t = 10.0)]
    pub hz: f64,
    /// Seconds measured after every viewer has its first cut.
    #[arg(long, default_value_t = 30.0)]
    pub duration: f64,
    /// Mutations per second (places, moves, deletes); needs --token.
    #[arg(long, default_value_t = 0.0)]
    pub mutations: f64,
    /// Seed of the paths and mutations.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A bearer token for the mutations.
    #[arg(long)]
    pub token: Option<String>,
    /// The server's process id (default: the one `horizon serve` on this machine).
    #[arg(long)]
    pub pid: Option<u32>,
    /// Walking speed, m/s.
    #[arg(long, default_value_t = 1.4)]
    pub speed: f64,
    /// Eye height (y), metres.
    #[arg(long, default_value_t = 2.0)]
    pub height: f64,
    /// The views' min_solid_angle.
    #[arg(long, default_value_t = horizon_protocol::DEFAULT_MIN_SOLID_ANGLE)]
    pub min_solid_angle: f64,
    /// The views' max_entries.
    #[arg(long, default_value_t = horizon_protocol::DEFAULT_MAX_ENTRIES)]
    pub max_entries: u64,
    /// Views without instances entries (every node as its aggregate).
    #[arg(long)]
    pub no_instances: bool,
}

/// The report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Viewers connected.
    pub viewers: usize,
    /// View rate per viewer.
    pub hz: f64,
    /// Mutations per second asked.
    pub mutations_per_second: f64,
    /// Seconds measured.
    pub seconds: f64,
    /// Latency samples.
    pub samples: u64,
    /// Camera update to delta, milliseconds.
    pub latency_ms: Percentiles,
    /// Time from connecting to the first complete cut (the reset), milliseconds.
    pub first_cut_ms: Percentiles,
    /// Views sent.
    pub views_sent: u64,
    /// Resets and deltas received per second, all viewers.
    pub deltas_per_second: f64,
    /// Bytes received per second per viewer.
    pub bytes_per_second_per_viewer: f64,
    /// Placements received per second per viewer, in the entries resets and deltas added (one
    /// per object or aggregate, one per object of an instances entry). An instances entry
    /// whose levels change is resent whole, so this counts what level changes cost.
    pub placements_per_second_per_viewer: f64,
    /// Views the server replaced by a later one before planning them (from `/metrics`).
    pub coalesced: Option<u64>,
    /// Views the server answered by carrying the held plan to the new eye, without
    /// planning (`horizon_stream_decisions_held_total`).
    pub carried: Option<u64>,
    /// Views the server planned again to find the cut unchanged
    /// (`horizon_stream_unchanged_total`).
    pub planned_unchanged: Option<u64>,
    /// Mutations that got a 2xx.
    pub mutations_ok: u64,
    /// Errors: failed mutations, error messages, closed or failed streams.
    pub errors: u64,
    /// What the errors were (first few).
    pub error_samples: Vec<String>,
    /// The server's CPU use over the measured time, in cores.
    pub server_cpu_cores: Option<f64>,
    /// This load generator's own CPU use over the measured time, in cores (it shares the
    /// machine with the server).
    pub load_cpu_cores: Option<f64>,
    /// Its resident memory at the end, bytes.
    pub server_rss_bytes: Option<u64>,
    /// Its resident memory growth from before the viewers connected, per viewer, bytes.
    pub rss_per_viewer_bytes: Option<f64>,
}

/// p50, p99, p999 and max.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest.
    pub max: f64,
}

impl Percentiles {
    fn of(h: &Histogram<u64>) -> Self {
        let ms = |v: u64| v as f64 / 1000.0;
        Self {
            p50: ms(h.value_at_quantile(0.5)),
            p99: ms(h.value_at_quantile(0.99)),
            p999: ms(h.value_at_quantile(0.999)),
            max: ms(h.max()),
        }
    }
}

/// Counters every viewer adds to.
#[derive(Debug, Default)]
struct Tally {
    views: AtomicU64,
    messages: AtomicU64,
    bytes: AtomicU64,
    placements: AtomicU64,
    errors: AtomicU64,
    mutations_ok: AtomicU64,
    samples: Mutex<Vec<String>>,
}

impl Tally {
    fn error(&self, what: String) {
        self.errors.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut s) = self.samples.lock() {
            if s.len() < 10 {
                s.push(what);
            }
        }
    }
}

/// Prints `r` as JSON or as a few lines of text.
pub fn print(r: &Report, json: bool) -> anyhow::Result<()> {
    if json {
        outln!("{}", serde_json::to_string_pretty(r)?)?;
        return Ok(());
    }
    let mb = |b: Option<u64>| b.map_or("-".into(), |b| format!("{:.0} MB", b as f64 / 1e6));
    outln!(
        "{} viewers at {} Hz, {} mutations/s, {:.1} s measured",
        r.viewers,
        r.hz,
        r.mutations_per_second,
        r.seconds
    )?;
    outln!(
        "camera-update-to-delta: p50 {:.2} ms, p99 {:.2} ms, p999 {:.2} ms, max {:.2} ms ({} samples of {} views; {} coalesced)",
        r.latency_ms.p50,
        r.latency_ms.p99,
        r.latency_ms.p999,
        r.latency_ms.max,
        r.samples,
        r.views_sent,
        r.coalesced.map_or("?".into(), |c| c.to_string())
    )?;
    let count = |c: Option<u64>| c.map_or("?".into(), |c| c.to_string());
    outln!(
        "views the server carried without planning: {}; planned to no change: {}",
        count(r.carried),
        count(r.planned_unchanged)
    )?;
    outln!(
        "first cut: p50 {:.0} ms, p99 {:.0} ms; {:.0} deltas/s; {:.0} B/s and {:.0} placements/s per viewer; {} mutations; {} errors {:?}",
        r.first_cut_ms.p50,
        r.first_cut_ms.p99,
        r.deltas_per_second,
        r.bytes_per_second_per_viewer,
        r.placements_per_second_per_viewer,
        r.mutations_ok,
        r.errors,
        r.error_samples
    )?;
    outln!(
        "server: {} cores (the load generator {}), RSS {}, {} per viewer",
        r.server_cpu_cores.map_or("-".into(), |c| format!("{c:.2}")),
        r.load_cpu_cores.map_or("-".into(), |c| format!("{c:.2}")),
        mb(r.server_rss_bytes),
        r.rss_per_viewer_bytes
            .map_or("-".into(), |b| format!("{:.0} KB", b / 1e3))
    )?;
    Ok(())
}

/// `GET /v1/cut` at `rate` requests a second for `seconds`, open loop, at `views` seeded
/// street-level eyes: (requests, errors, latency percentiles in ms).
#[allow(clippy::too_many_arguments)]
pub fn bench_cut(
    url: &str,
    rate: u64,
    seconds: u64,
    views: usize,
    seed: u64,
    height: f64,
    instances: bool,
    accept_encoding: Option<&str>,
) -> anyhow::Result<serde_json::Value> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let info: WorldInfo = reqwest::get(format!("{url}/v1/world"))
            .await?
            .error_for_status()?
            .json()
            .await?;
        let b = info.bounds.context("the world is empty")?;
        let mut rng = Rng::new(seed ^ 0xC07);
        let urls: Vec<String> = (0..views.max(1))
            .map(|_| {
                let x = f64::from(b.min[0]) + rng.unit_f64() * f64::from(b.max[0] - b.min[0]);
                let z = f64::from(b.min[2]) + rng.unit_f64() * f64::from(b.max[2] - b.min[2]);
                format!("{url}/v1/cut?eye={x:.2},{height},{z:.2}&instances={instances}")
            })
            .collect();
        let pid = find_server();
        let cpu_before = pid.and_then(cpu_seconds);
        let started = Instant::now();
        let (requests, errors, p) =
            crate::bench_service::open_loop(urls, rate, seconds, seed, accept_encoding).await?;
        let wall = started.elapsed().as_secs_f64();
        let cpu = pid
            .and_then(cpu_seconds)
            .zip(cpu_before)
            .map(|(b, a)| (b - a) / wall);
        Ok(serde_json::json!({
            "objects": info.objects,
            "rate": rate,
            "instances": instances,
            "accept_encoding": accept_encoding,
            "seconds": seconds,
            "requests": requests,
            "errors": errors,
            "p50_ms": p.p50,
            "p99_ms": p.p99,
            "max_ms": p.max,
            "server_cpu_cores": cpu,
            "server_rss_bytes": pid.and_then(rss),
        }))
    })
}

/// Runs the load (see the module docs).
pub fn run(args: &Args) -> anyhow::Result<Report> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    runtime.block_on(load(args))
}

async fn load(args: &Args) -> anyhow::Result<Report> {
    let http = reqwest::Client::builder().no_proxy().build()?;
    let info: WorldInfo = http
        .get(format!("{}/v1/world", args.url))
        .send()
        .await?
        .error_for_status()?
        .json()
        .await
        .context("GET /v1/world")?;
    let bounds = info.bounds.context("the world is empty")?;
    let pid = args.pid.or_else(find_server);
    let rss_before = pid.and_then(rss);
    let ws_url = format!(
        "{}/v1/stream",
        args.url
            .replacen("http://", "ws://", 1)
            .replacen("https://", "wss://", 1)
    );
    let tally = Arc::new(Tally::default());
    let latency = Arc::new(Mutex::new(Histogram::<u64>::new_with_bounds(
        1,
        600_000_000,
        3,
    )?));
    let first = Arc::new(Mutex::new(Histogram::<u64>::new_with_bounds(
        1,
        600_000_000,
        3,
    )?));
    let started_measuring = Arc::new(Mutex::new(None::<Instant>));
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let connected = Arc::new(tokio::sync::Barrier::new(args.viewers + 1));

    let mut tasks = Vec::new();
    for v in 0..args.viewers {
        let walker = Walker::new(args.seed, v as u64, &bounds, args);
        let view = View {
            min_solid_angle: args.min_solid_angle,
            budgets: Budgets {
                max_entries: Some(args.max_entries),
                ..Budgets::default()
            },
            instances: !args.no_instances,
            ..View::at(walker.eye())
        };
        tasks.push(tokio::spawn(viewer(
            ws_url.clone(),
            walker,
            view,
            args.hz,
            tally.clone(),
            latency.clone(),
            first.clone(),
            started_measuring.clone(),
            connected.clone(),
            stopped.clone(),
        )));
    }
    // Every viewer has its first cut: measure from here.
    connected.wait().await;
    let metrics_before = stream_counters(&http, &args.url).await;
    let cpu_before = pid.and_then(cpu_seconds);
    let own_before = cpu_seconds(std::process::id());
    let t0 = Instant::now();
    if let Ok(mut s) = started_measuring.lock() {
        *s = Some(t0);
    }
    let rss_connected = pid.and_then(rss);
    let mutator = (args.mutations > 0.0).then(|| {
        tokio::spawn(mutate(
            http.clone(),
            args.clone(),
            bounds,
            tally.clone(),
            stopped.clone(),
        ))
    });
    tokio::time::sleep(Duration::from_secs_f64(args.duration)).await;
    let seconds = t0.elapsed().as_secs_f64();
    let cpu_after = pid.and_then(cpu_seconds);
    let own_after = cpu_seconds(std::process::id());
    let rss_end = pid.and_then(rss);
    let metrics_after = stream_counters(&http, &args.url).await;
    let _ = stop.send(true);
    for t in tasks {
        let _ = t.await;
    }
    if let Some(m) = mutator {
        let _ = m.await;
    }
    let latency = latency.lock().map_err(|_| anyhow::anyhow!("poisoned"))?;
    let first = first.lock().map_err(|_| anyhow::anyhow!("poisoned"))?;
    let messages = tally.messages.load(Ordering::Relaxed);
    let bytes = tally.bytes.load(Ordering::Relaxed);
    Ok(Report {
        viewers: args.viewers,
        hz: args.hz,
        mutations_per_second: args.mutations,
        seconds,
        samples: latency.len(),
        latency_ms: Percentiles::of(&latency),
        first_cut_ms: Percentiles::of(&first),
        views_sent: tally.views.load(Ordering::Relaxed),
        deltas_per_second: messages as f64 / seconds,
        bytes_per_second_per_viewer: bytes as f64 / seconds / args.viewers.max(1) as f64,
        placements_per_second_per_viewer: tally.placements.load(Ordering::Relaxed) as f64
            / seconds
            / args.viewers.max(1) as f64,
        coalesced: counted(metrics_before, metrics_after, 0),
        carried: counted(metrics_before, metrics_after, 1),
        planned_unchanged: counted(metrics_before, metrics_after, 2),
        mutations_ok: tally.mutations_ok.load(Ordering::Relaxed),
        errors: tally.errors.load(Ordering::Relaxed),
        error_samples: tally.samples.lock().map(|s| s.clone()).unwrap_or_default(),
        server_cpu_cores: cpu_before.zip(cpu_after).map(|(a, b)| (b - a) / seconds),
        load_cpu_cores: own_before.zip(own_after).map(|(a, b)| (b - a) / seconds),
        server_rss_bytes: rss_end,
        rss_per_viewer_bytes: rss_before
            .zip(rss_connected)
            .map(|(a, b)| (b as f64 - a as f64) / args.viewers.max(1) as f64),
    })
}

/// A seeded walk: a start in the world's box, a heading that turns now and then, a speed.
#[derive(Clone, Debug)]
struct Walker {
    rng: Rng,
    at: [f64; 3],
    heading: f64,
    speed: f64,
    min: [f64; 2],
    max: [f64; 2],
}

impl Walker {
    fn new(seed: u64, viewer: u64, bounds: &horizon_protocol::Bounds, args: &Args) -> Self {
        let mut rng = Rng::new(seed.wrapping_mul(0x9E37_79B9).wrapping_add(viewer));
        let min = [f64::from(bounds.min[0]), f64::from(bounds.min[2])];
        let max = [f64::from(bounds.max[0]), f64::from(bounds.max[2])];
        let x = min[0] + rng.unit_f64() * (max[0] - min[0]);
        let z = min[1] + rng.unit_f64() * (max[1] - min[1]);
        let heading = rng.unit_f64() * std::f64::consts::TAU;
        Self {
            rng,
            at: [x, args.height, z],
            heading,
            speed: args.speed,
            min,
            max,
        }
    }

    fn eye(&self) -> [f64; 3] {
        self.at
    }

    /// Walks `dt` seconds: turns a little at random, bounces off the world's box.
    fn step(&mut self, dt: f64) {
        self.heading += (self.rng.unit_f64() - 0.5) * 0.3;
        let d = self.speed * dt;
        for (axis, (lo, hi)) in [
            (0usize, (self.min[0], self.max[0])),
            (2, (self.min[1], self.max[1])),
        ] {
            let v = if axis == 0 {
                self.heading.cos()
            } else {
                self.heading.sin()
            };
            let next = self.at[axis] + v * d;
            if next < lo || next > hi {
                self.heading += std::f64::consts::PI;
            } else {
                self.at[axis] = next;
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
async fn viewer(
    url: String,
    mut walker: Walker,
    mut view: View,
    hz: f64,
    tally: Arc<Tally>,
    latency: Arc<Mutex<Histogram<u64>>>,
    first: Arc<Mutex<Histogram<u64>>>,
    measuring: Arc<Mutex<Option<Instant>>>,
    connected: Arc<tokio::sync::Barrier>,
    mut stopped: tokio::sync::watch::Receiver<bool>,
) {
    let started = Instant::now();
    let mut ws = match tokio_tungstenite::connect_async(&url).await {
        Ok((ws, _)) => ws,
        Err(e) => {
            tally.error(format!("connect: {e}"));
            connected.wait().await;
            return;
        }
    };
    let mut sent: HashMap<u64, Instant> = HashMap::new();
    let mut id = 1u64;
    let message = |id: u64, view: &View| {
        serde_json::to_string(&ClientMessage::View { id, view: *view }).unwrap_or_default()
    };
    if ws
        .send(Message::Text(message(id, &view).into()))
        .await
        .is_err()
    {
        tally.error("send the first view".into());
        connected.wait().await;
        return;
    }
    // The first cut.
    let mut ok = false;
    while let Some(Ok(m)) = ws.next().await {
        if let Message::Text(t) = m {
            if let Ok(ServerMessage::Reset { seq, .. }) = serde_json::from_str(&t) {
                if let Ok(mut h) = first.lock() {
                    let _ = h.record(started.elapsed().as_micros().max(1) as u64);
                }
                let ack = format!(r#"{{"type":"ack","seq":{seq}}}"#);
                ok = ws.send(Message::Text(ack.into())).await.is_ok();
                break;
            }
        }
    }
    connected.wait().await;
    if !ok {
        tally.error("no first cut".into());
        return;
    }
    let period = Duration::from_secs_f64(1.0 / hz.max(0.01));
    let mut ticker = tokio::time::interval(period);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut answered = id;
    loop {
        tokio::select! {
            _ = stopped.changed() => break,
            _ = ticker.tick() => {
                walker.step(period.as_secs_f64());
                view.eye = walker.eye();
                id += 1;
                sent.insert(id, Instant::now());
                tally.views.fetch_add(1, Ordering::Relaxed);
                if ws.send(Message::Text(message(id, &view).into())).await.is_err() {
                    tally.error("send a view".into());
                    break;
                }
            }
            m = ws.next() => {
                let Some(Ok(m)) = m else {
                    tally.error("the stream ended".into());
                    break;
                };
                let Message::Text(t) = m else {
                    if let Message::Close(c) = m {
                        tally.error(format!("closed: {c:?}"));
                        break;
                    }
                    continue;
                };
                let counting = measuring.lock().ok().and_then(|m| *m).is_some();
                if counting {
                    tally.bytes.fetch_add(t.len() as u64, Ordering::Relaxed);
                }
                match serde_json::from_str::<ServerMessage>(&t) {
                    Ok(ref m @ (ServerMessage::Reset { seq, view: v, .. } | ServerMessage::Delta { seq, view: v, .. })) => {
                        if counting {
                            tally.messages.fetch_add(1, Ordering::Relaxed);
                            tally.placements.fetch_add(placements_added(m), Ordering::Relaxed);
                        }
                        if v > answered {
                            if let (Some(at), true) = (sent.get(&v), counting) {
                                if let Ok(mut h) = latency.lock() {
                                    let _ = h.record(at.elapsed().as_micros().max(1) as u64);
                                }
                            }
                            answered = v;
                            sent.retain(|&k, _| k > v);
                        }
                        let ack = format!(r#"{{"type":"ack","seq":{seq}}}"#);
                        if ws.send(Message::Text(ack.into())).await.is_err() {
                            tally.error("send an ack".into());
                            break;
                        }
                    }
                    Ok(ServerMessage::Error { error }) => tally.error(format!("{:?}: {}", error.code, error.message)),
                    Err(e) => tally.error(format!("a message that does not parse: {e}")),
                }
            }
        }
    }
    let _ = ws.close(None).await;
}

/// The placements a reset or delta adds (an error adds none).
fn placements_added(m: &ServerMessage) -> u64 {
    let count = |e: &horizon_protocol::Entry| e.placements.len() as u64;
    match m {
        ServerMessage::Reset { entries, .. } => entries.iter().map(count).sum(),
        ServerMessage::Delta { add, .. } => add.iter().map(|a| count(&a.entry)).sum(),
        ServerMessage::Error { .. } => 0,
    }
}

/// Places, moves and deletes objects at `args.mutations` per second until stopped.
async fn mutate(
    http: reqwest::Client,
    args: Args,
    bounds: horizon_protocol::Bounds,
    tally: Arc<Tally>,
    mut stopped: tokio::sync::watch::Receiver<bool>,
) {
    let Some(token) = args.token.clone() else {
        tally.error("--mutations needs --token".into());
        return;
    };
    let models: Vec<String> = match http
        .get(format!("{}/v1/models?limit=100", args.url))
        .send()
        .await
    {
        Ok(r) => r
            .json::<horizon_protocol::ModelPage>()
            .await
            .map(|p| p.models.into_iter().map(|m| m.id).collect())
            .unwrap_or_default(),
        Err(_) => Vec::new(),
    };
    if models.is_empty() {
        tally.error("no models to place".into());
        return;
    }
    let mut rng = Rng::new(args.seed ^ 0x4D55_5441);
    let mut mine: Vec<u64> = Vec::new();
    let period = Duration::from_secs_f64(1.0 / args.mutations);
    let mut ticker = tokio::time::interval(period);
    let span =
        |i: usize, r: f64| f64::from(bounds.min[i]) + r * f64::from(bounds.max[i] - bounds.min[i]);
    loop {
        tokio::select! {
            _ = stopped.changed() => return,
            _ = ticker.tick() => {}
        }
        let choice = rng.unit_f64();
        let at = [span(0, rng.unit_f64()), 0.0, span(2, rng.unit_f64())];
        let request = if mine.len() < 5 || choice < 0.4 {
            let model = &models[rng.below(models.len())];
            http.post(format!("{}/v1/objects", args.url))
                .json(&serde_json::json!({"model": model, "translation": at}))
        } else if choice < 0.8 {
            let id = mine[rng.below(mine.len())];
            http.patch(format!("{}/v1/objects/{id}", args.url))
                .json(&serde_json::json!({"translation": at}))
        } else {
            let i = rng.below(mine.len());
            let id = mine.swap_remove(i);
            http.delete(format!("{}/v1/objects/{id}", args.url))
        };
        match request.bearer_auth(&token).send().await {
            Ok(r) if r.status().is_success() => {
                tally.mutations_ok.fetch_add(1, Ordering::Relaxed);
                if r.status() == reqwest::StatusCode::CREATED {
                    if let Ok(c) = r.json::<horizon_protocol::Created>().await {
                        mine.push(c.id);
                    }
                }
            }
            Ok(r) => tally.error(format!("mutation: {}", r.status())),
            Err(e) => tally.error(format!("mutation: {e}")),
        }
    }
}

/// The server's stream counters, from its `/metrics`: views coalesced, carried and planned
/// to no change (see [`Report`]).
async fn stream_counters(http: &reqwest::Client, url: &str) -> Option<[u64; 3]> {
    let text = http
        .get(format!("{url}/metrics"))
        .send()
        .await
        .ok()?
        .text()
        .await
        .ok()?;
    let total = |name: &str| {
        text.lines()
            .filter(|l| l.split(['{', ' ']).next() == Some(name))
            .filter_map(|l| l.split_whitespace().last()?.parse::<f64>().ok())
            .sum::<f64>() as u64
    };
    Some([
        total("horizon_stream_coalesced_total"),
        total("horizon_stream_decisions_held_total"),
        total("horizon_stream_unchanged_total"),
    ])
}

/// Counter `k` of [`stream_counters`] over the measured time.
fn counted(before: Option<[u64; 3]>, after: Option<[u64; 3]>, k: usize) -> Option<u64> {
    before.zip(after).map(|(a, b)| b[k].saturating_sub(a[k]))
}

/// The one `horizon serve` process on this machine, if there is exactly one.
fn find_server() -> Option<u32> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(format!("/proc/{pid}/cmdline")) else {
            continue;
        };
        let args: Vec<&[u8]> = cmdline.split(|&b| b == 0).collect();
        let is_horizon = args.first().is_some_and(|a| a.ends_with(b"horizon"));
        if is_horizon && args.iter().any(|a| *a == b"serve" || *a == b"demo") {
            found.push(pid);
        }
    }
    (found.len() == 1).then(|| found[0])
}

/// User plus system CPU seconds of a process.
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces): utime is the 14th field.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    // Linux reports in clock ticks, 100 a second on every platform Horizon runs on.
    Some((utime + stime) / 100.0)
}

/// Resident memory of a process, bytes.
fn rss(pid: u32) -> Option<u64> {
    status_bytes(&pid.to_string(), "VmRSS:")
}

/// A size field of `/proc/PROC/status` (`PROC` a process id or `self`), in bytes.
pub fn status_bytes(process: &str, field: &str) -> Option<u64> {
    std::fs::read_to_string(format!("/proc/{process}/status"))
        .ok()?
        .lines()
        .find(|l| l.starts_with(field))
        .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map(|kb| kb * 1024)
}
