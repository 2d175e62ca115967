//! `horizon-client`: Horizon's world service from the command line, as a viewer sees it.
//! - `cut URL --eye X,Y,Z`: one `GET /v1/cut`, summarised (or `--json`: the body as sent).
//! - `stream URL --eye X,Y,Z --steps N`: the stream, moved a little each step; after every
//!   message the kept cut must count every object once and equal a fresh `GET /v1/cut` at the
//!   same view (compared when both are of the same generation and published generation).
//! - `walk URL --path FILE`: a viewer walking the waypoints in FILE (a JSON array of
//!   `[x, y, z]`), loading assets through a cache; reports latencies and incomplete frames.
//!
//! Errors are one line on stderr, with status 1.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{bail, Context};
use clap::{Args, Parser, Subcommand};
use horizon_client::{
    check_cut, walk, AssetCache, Client, LocalCut, Stream, StreamError, WalkOptions,
};
use horizon_protocol::{Budgets, CutResponse, EntryKind, ServerMessage, View};
use serde::Serialize;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            let rendered = e.to_string();
            let line = rendered.lines().next().unwrap_or("bad arguments");
            let line = line.strip_prefix("error: ").unwrap_or(line);
            let _ = writeln!(
                std::io::stderr(),
                "horizon-client: error: {line} (see --help)"
            );
            return ExitCode::FAILURE;
        }
    };
    let result = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
        .and_then(|runtime| runtime.block_on(run(cli)));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            let message = format!("{e:#}").replace(['\n', '\r'], " ");
            let _ = writeln!(std::io::stderr(), "horizon-client: error: {message}");
            ExitCode::FAILURE
        }
    }
}

#[derive(Debug, Parser)]
#[command(
    name = "horizon-client",
    version,
    about = "A client of Horizon's world service"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// One cut (`GET /v1/cut`): entries by kind, objects, bytes, what stopped it.
    Cut {
        /// The server, `http://host:port`.
        url: String,
        #[command(flatten)]
        view: ViewArgs,
        /// Print the server's body as it came.
        #[arg(long)]
        json: bool,
    },
    /// The standing cut (`/v1/stream`), checked after every message against `GET /v1/cut`.
    Stream {
        /// The server, `http://host:port`.
        url: String,
        #[command(flatten)]
        view: ViewArgs,
        /// Views to send, each `--step` metres further along +x.
        #[arg(long, default_value_t = 10)]
        steps: u64,
        /// Metres between views.
        #[arg(long, default_value_t = 2.0)]
        step: f64,
        /// Seconds to wait for the answer to a view before the next (a view that leaves the
        /// cut as it was gets none).
        #[arg(long, default_value_t = 1.0)]
        wait: f64,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
    /// A viewer walking a path, loading assets; latencies and incomplete frames.
    Walk {
        /// The server, `http://host:port`.
        url: String,
        /// A JSON array of `[x, y, z]` waypoints.
        #[arg(long)]
        path: PathBuf,
        /// Metres per second.
        #[arg(long, default_value_t = 1.5)]
        speed: f64,
        /// Bytes per second for asset downloads (default: no limit).
        #[arg(long)]
        bandwidth: Option<f64>,
        /// Seconds to walk.
        #[arg(long, default_value_t = 30.0)]
        duration: f64,
        /// The asset cache's folder (default: a fresh temporary folder, removed after).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// Asset downloads at once.
        #[arg(long, default_value_t = 4)]
        concurrency: usize,
        /// Fetch assets in the order their entries arrive, instead of every preview first
        /// and then the entries largest on screen first.
        #[arg(long)]
        in_order: bool,
        #[command(flatten)]
        view: ViewArgs,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// The view's options, shared by the commands.
#[derive(Debug, Args)]
struct ViewArgs {
    /// The eye, `X,Y,Z` (the walk's is its path).
    #[arg(long, value_parser = parse_eye, allow_hyphen_values = true)]
    eye: Option<[f64; 3]>,
    /// Smallest solid angle shown as itself, steradians.
    #[arg(long)]
    min_solid_angle: Option<f64>,
    /// Solid angle of one pixel, steradians.
    #[arg(long)]
    pixel_solid_angle: Option<f64>,
    /// Most geometric error an object's level of detail may show, pixels (0: full detail).
    #[arg(long)]
    max_pixel_error: Option<f64>,
    /// Ask for no orthoview impostors (far nodes as their aggregates).
    #[arg(long)]
    no_impostors: bool,
    /// Ask for no instances entries (every node as its aggregate or impostor).
    #[arg(long)]
    no_instances: bool,
    /// Most entries.
    #[arg(long)]
    max_entries: Option<u64>,
    /// Most asset bytes.
    #[arg(long)]
    max_bytes: Option<u64>,
    /// Most draw calls.
    #[arg(long)]
    max_draw_calls: Option<u64>,
    /// Most triangles.
    #[arg(long)]
    max_triangles: Option<u64>,
}

impl ViewArgs {
    /// The view these options describe, at `eye` if none was given.
    fn view(&self, eye: Option<[f64; 3]>) -> anyhow::Result<View> {
        let Some(at) = self.eye.or(eye) else {
            bail!("--eye X,Y,Z is required");
        };
        let mut view = View::at(at);
        if let Some(a) = self.min_solid_angle {
            view.min_solid_angle = a;
        }
        if let Some(a) = self.pixel_solid_angle {
            view.pixel_solid_angle = a;
        }
        if let Some(e) = self.max_pixel_error {
            view.max_pixel_error = e;
        }
        view.impostors = !self.no_impostors;
        view.instances = !self.no_instances;
        view.budgets = Budgets {
            max_entries: self.max_entries,
            max_bytes: self.max_bytes,
            max_draw_calls: self.max_draw_calls,
            max_triangles: self.max_triangles,
        };
        view.check().map_err(anyhow::Error::msg)?;
        Ok(view)
    }
}

fn parse_eye(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').collect();
    let [x, y, z] = parts.as_slice() else {
        return Err(format!("{text:?} is not X,Y,Z"));
    };
    let number = |s: &str| -> Result<f64, String> {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{s:?} is not a finite number"))
    };
    Ok([number(x)?, number(y)?, number(z)?])
}

async fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Cut { url, view, json } => cut(&url, &view.view(None)?, json).await,
        Command::Stream {
            url,
            view,
            steps,
            step,
            wait,
            json,
        } => {
            let view = view.view(None)?;
            if !(wait.is_finite() && wait > 0.0 && step.is_finite()) {
                bail!("--wait must be a positive number of seconds and --step a finite number");
            }
            stream(&url, view, steps, step, Duration::from_secs_f64(wait), json).await
        }
        Command::Walk {
            url,
            path,
            speed,
            bandwidth,
            duration,
            cache,
            concurrency,
            in_order,
            view,
            json,
        } => {
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            let waypoints: Vec<[f64; 3]> = serde_json::from_str(&text)
                .with_context(|| format!("{} is not a JSON array of [x, y, z]", path.display()))?;
            let first = waypoints.first().copied();
            if !(duration.is_finite() && duration >= 0.0) {
                bail!("--duration {duration} is not a number of seconds");
            }
            let options = WalkOptions {
                view: view.view(first.or(Some([0.0; 3])))?,
                speed,
                bandwidth,
                duration: Duration::from_secs_f64(duration),
                concurrency,
                in_order,
                ..WalkOptions::new(waypoints)
            };
            walk_command(&url, &options, cache, json).await
        }
    }
}

// ---------------------------------------------------------------------------------------------
// cut
// ---------------------------------------------------------------------------------------------

async fn cut(url: &str, view: &View, json: bool) -> anyhow::Result<()> {
    let client = Client::new(url)?;
    let body = client.cut_body(view).await?;
    let response: CutResponse =
        serde_json::from_str(&body).context("the server's answer is not a cut")?;
    if json {
        return out(body.trim_end());
    }
    let mut by_kind: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    for e in &response.entries {
        let kind = match e.kind {
            EntryKind::Object => "object",
            EntryKind::Aggregate => "aggregate",
            EntryKind::Impostor => "impostor",
            EntryKind::Instances => "instances",
        };
        let slot = by_kind.entry(kind).or_default();
        slot.0 += 1;
        slot.1 += e.covers;
    }
    let mut assets: HashMap<&str, u64> = HashMap::new();
    for e in &response.entries {
        for a in &e.assets {
            assets.insert(&a.hash, a.bytes);
        }
    }
    let pending = response.entries.iter().filter(|e| e.pending).count();
    let triangles: u64 = response.entries.iter().map(|e| e.triangles).sum();
    out(&format!(
        "generation {} (published {}): {} objects in {} entries",
        response.generation,
        response.published,
        response.objects,
        response.entries.len()
    ))?;
    for (kind, (n, covers)) in &by_kind {
        out(&format!("  {kind}: {n} entries covering {covers} objects"))?;
    }
    out(&format!("  pending: {pending}"))?;
    out(&format!(
        "bytes: {} in {} distinct assets; triangles: {triangles}",
        assets.values().sum::<u64>(),
        assets.len()
    ))?;
    let stopped = response
        .stopped_by
        .and_then(|s| serde_json::to_value(s).ok())
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| "nothing".into());
    out(&format!("stopped by: {stopped}"))?;
    match check_cut(&response) {
        Ok(()) => out("complete: yes"),
        Err(e) => bail!("the cut is incomplete: {e}"),
    }
}

// ---------------------------------------------------------------------------------------------
// stream
// ---------------------------------------------------------------------------------------------

/// What `stream` checked.
#[derive(Debug, Default, Serialize)]
struct StreamReport {
    views: u64,
    messages: u64,
    resets: u64,
    deltas: u64,
    /// Comparisons with a fresh cut at the same generation.
    compared: u64,
    /// Messages whose fresh cut was of another generation.
    skipped: u64,
    entries: usize,
    generation: u64,
}

async fn stream(
    url: &str,
    view: View,
    steps: u64,
    step: f64,
    wait: Duration,
    json: bool,
) -> anyhow::Result<()> {
    let client = Client::new(url)?;
    let mut stream = Stream::connect(url).await?;
    let mut cut = LocalCut::new();
    let mut views: HashMap<u64, View> = HashMap::new();
    let mut report = StreamReport::default();
    for id in 1..=steps.max(1) {
        let mut v = view;
        v.eye[0] += step * (id - 1) as f64;
        stream.send_view(id, &v).await?;
        views.insert(id, v);
        report.views += 1;
        // Take messages until one answers this view, or the server is quiet for `wait`.
        loop {
            let message = match tokio::time::timeout(wait, stream.next()).await {
                Err(_) => break,
                Ok(m) => m?,
            };
            let answered = check_message(&client, &mut cut, &views, &message, &mut report).await?;
            if let Some(seq) = message.seq() {
                stream.ack(seq).await?;
            }
            if answered >= id {
                break;
            }
        }
    }
    // Whatever is still in flight (a publish), briefly.
    while let Ok(m) = tokio::time::timeout(Duration::from_millis(500), stream.next()).await {
        let message = match m {
            Ok(message) => message,
            Err(StreamError::Closed { .. } | StreamError::Ended) => break,
            Err(e) => return Err(e.into()),
        };
        check_message(&client, &mut cut, &views, &message, &mut report).await?;
    }
    let _ = stream.close().await;
    report.entries = cut.len();
    report.generation = cut.generation();
    if json {
        return out(&serde_json::to_string(&report)?);
    }
    out(&format!(
        "{} views, {} messages ({} resets, {} deltas): the kept cut was complete after each; \
         {} compared equal with a fresh cut, {} skipped (another generation); \
         {} entries at generation {} at the end",
        report.views,
        report.messages,
        report.resets,
        report.deltas,
        report.compared,
        report.skipped,
        report.entries,
        report.generation
    ))
}

/// Applies one message, checks the cut and compares it with a fresh one; the view it
/// answers.
async fn check_message(
    client: &Client,
    cut: &mut LocalCut,
    views: &HashMap<u64, View>,
    message: &ServerMessage,
    report: &mut StreamReport,
) -> anyhow::Result<u64> {
    match message {
        ServerMessage::Error { error } => bail!(
            "the server refused a view: {}: {}",
            horizon_client::code_name(error.code),
            error.message
        ),
        ServerMessage::Reset { .. } => report.resets += 1,
        ServerMessage::Delta { .. } => report.deltas += 1,
    }
    report.messages += 1;
    let seq = message.seq().unwrap_or(0);
    cut.apply(message)
        .with_context(|| format!("message seq {seq}"))?;
    cut.check_complete()
        .with_context(|| format!("after message seq {seq}"))?;
    let Some(view) = views.get(&cut.view()) else {
        bail!(
            "message seq {seq} answers view {}, which was never sent",
            cut.view()
        );
    };
    let fresh = client.cut(view).await?;
    if (fresh.generation, fresh.published) == (cut.generation(), cut.published()) {
        cut.same_as(&fresh).with_context(|| {
            format!(
                "after message seq {seq} (view {} at {:?}, generation {})",
                cut.view(),
                view.eye,
                cut.generation()
            )
        })?;
        report.compared += 1;
    } else {
        report.skipped += 1;
    }
    Ok(cut.view())
}

// ---------------------------------------------------------------------------------------------
// walk
// ---------------------------------------------------------------------------------------------

async fn walk_command(
    url: &str,
    options: &WalkOptions,
    cache: Option<PathBuf>,
    json: bool,
) -> anyhow::Result<()> {
    let client = Client::new(url)?;
    let (dir, temporary) = match cache {
        Some(dir) => (dir, false),
        None => (
            std::env::temp_dir().join(format!("horizon-client-cache-{}", std::process::id())),
            true,
        ),
    };
    let cache = AssetCache::with_client(&dir, &client)?;
    let report = walk(url, options, &cache).await;
    if temporary {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let report = report?;
    if json {
        return out(&serde_json::to_string(&report)?);
    }
    let l = &report.view_latency_ms;
    let ms = |t: Option<f64>| t.map_or("never".to_owned(), |ms| format!("{ms:.0} ms"));
    out(&format!(
        "walked {:.1} m in {:.1} s: {} views, {} resets, {} deltas (+{} -{} entries)",
        report.distance,
        report.seconds,
        report.views_sent,
        report.resets,
        report.deltas,
        report.entries_added,
        report.entries_removed
    ))?;
    out(&format!(
        "assets: {} fetched ({} bytes: {} for objects, {} for aggregates, {} for impostors, {} for instances), {} from the cache, {} gone",
        report.assets_fetched,
        report.bytes_fetched,
        report.bytes_objects,
        report.bytes_aggregates,
        report.bytes_impostors,
        report.bytes_instances,
        report.assets_cached,
        report.assets_gone
    ))?;
    out(&format!(
        "view loaded: p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms over {} answered views \
         ({} not loaded at the end; {} views without a message of their own); \
         first complete view {}, first view with every entry drawn {}",
        l.p50,
        l.p99,
        l.max,
        l.count,
        report.views_unloaded,
        report.views_unanswered,
        ms(report.first_complete_ms),
        ms(report.first_drawn_ms)
    ))?;
    out(&format!(
        "frames with a drawn entry missing: {} of {} ({:.1}%), with an entry not drawn at all \
         {} ({:.1}%); drawn on average: {:.1}% of the entries, {:.1}% of what they cover on \
         screen; {} entries at generation {}",
        report.incomplete_frames,
        report.frames,
        report.incomplete_share * 100.0,
        report.hole_frames,
        report.hole_share * 100.0,
        report.drawn_entries_share * 100.0,
        report.drawn_screen_share * 100.0,
        report.final_entries,
        report.final_generation
    ))
}

// ---------------------------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------------------------

/// One line on stdout; a closed pipe is an error that ends the command quietly.
fn out(line: &str) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();
    stdout.write_all(line.as_bytes())?;
    stdout.write_all(b"\n")?;
    stdout.flush()?;
    Ok(())
}

fn broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
