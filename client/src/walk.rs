//! [`walk`]: a viewer moving along a path at a steady speed, as a client would: it sends its
//! view over the stream ten times a second, applies and acks every message (checking that
//! the kept cut counts every object exactly once after each), and fetches the assets its cut
//! needs through the [`AssetCache`], a few at a time and, if asked, within a bandwidth. It
//! reports what that cost and what a viewer would have seen: how long each view took until
//! every asset of the cut that answered it was loaded, the share of frames in which an entry
//! of the cut had an asset still missing, and the share in which one had nothing to draw.
//!
//! Fetching is progressive, as the web viewer's (issue 28): every entry's `preview` (its
//! model's coarsest level, drawn until its own level has loaded) comes first, then the
//! entries' own assets, largest on screen first (radius² / distance² from the eye last
//! sent). [`WalkOptions::in_order`] fetches in the order the entries arrived instead, the
//! peer the progressive order is measured against.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

use futures_util::stream::FuturesUnordered;
use futures_util::StreamExt;
use horizon_protocol::{AssetRole, ErrorCode, ServerMessage, View};
use serde::Serialize;

use crate::assets::{AssetCache, AssetError, Fetched, TokenBucket};
use crate::http::{code_name, ClientError};
use crate::local::{ApplyError, Incomplete, LocalCut};
use crate::stream::{Stream, StreamError};

/// Walks `options.path` against the server at `base_url`: see the module docs.
///
/// # Errors
/// [`WalkError`]: a bad path or view, a stream that fails or closes, a message that does not
/// apply or leaves the cut incomplete, an error message from the server, or an asset that
/// cannot be fetched (other than one the server no longer has, which is counted).
pub async fn walk(
    base_url: &str,
    options: &WalkOptions,
    cache: &AssetCache,
) -> Result<WalkReport, WalkError> {
    let path = Polyline::new(&options.path)?;
    if !(options.speed.is_finite() && options.speed >= 0.0) {
        return Err(WalkError::BadOptions(format!(
            "speed {} is not a finite number of at least 0",
            options.speed
        )));
    }
    let mut template = options.view;
    template.eye = path.at(0.0);
    template.check().map_err(WalkError::BadView)?;
    let interval = options.interval.max(Duration::from_millis(1));
    let bucket = match options.bandwidth {
        Some(b) if b.is_finite() && b > 0.0 => Some(TokenBucket::new(b, (b * 0.1).max(16_384.0))),
        Some(b) => {
            return Err(WalkError::BadOptions(format!(
                "bandwidth {b} is not a positive number of bytes per second"
            )))
        }
        None => None,
    };

    let mut stream = Stream::connect(base_url).await?;
    let mut walker = Walker::new(Instant::now(), options.concurrency.max(1));
    walker.in_order = options.in_order;
    let deadline = tokio::time::Instant::from_std(walker.start + options.duration);
    let mut ticker = tokio::time::interval(interval);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut fetches = FuturesUnordered::new();
    let mut next_view = 1u64;

    loop {
        tokio::select! {
            () = tokio::time::sleep_until(deadline) => break,
            _ = ticker.tick() => {
                walker.frame();
                let elapsed = walker.start.elapsed().as_secs_f64();
                let mut view = template;
                view.eye = path.walked(options.speed * elapsed);
                stream.send_view(next_view, &view).await?;
                walker.eye = view.eye;
                walker.sent.insert(next_view, Instant::now());
                walker.report.views_sent += 1;
                walker.report.distance = options.speed * elapsed;
                next_view += 1;
            }
            message = stream.next() => {
                let message = message?;
                walker.message(&message)?;
                if let Some(seq) = message.seq() {
                    stream.ack(seq).await?;
                }
            }
            Some((hash, result)) = fetches.next(), if !fetches.is_empty() => {
                walker.fetched(hash, result)?;
            }
        }
        while fetches.len() < walker.concurrency {
            let Some(hash) = walker.next_fetch() else {
                break;
            };
            fetches.push(fetch(cache, bucket.as_ref(), hash));
        }
    }
    let _ = stream.close().await;
    Ok(walker.finish())
}

/// What a walk does: where, how fast, for how long, with which view.
#[derive(Clone, Debug)]
pub struct WalkOptions {
    /// The waypoints, world space; the walker goes from the first to the last and back.
    pub path: Vec<[f64; 3]>,
    /// Metres per second along the path.
    pub speed: f64,
    /// Bytes per second the asset downloads may use together (None: no limit).
    pub bandwidth: Option<f64>,
    /// How long the walk lasts.
    pub duration: Duration,
    /// The view sent at every step, its `eye` replaced by the walker's position.
    pub view: View,
    /// Asset downloads at once.
    pub concurrency: usize,
    /// Time between views, which is also a frame. Default 100 ms.
    pub interval: Duration,
    /// Fetch assets in the order their entries arrived, previews as any other asset, instead
    /// of previews first and then largest on screen first.
    pub in_order: bool,
}

impl WalkOptions {
    /// A walk along `path` at 1.5 m/s for 30 s with the default view, no bandwidth limit,
    /// 4 downloads at once, a view every 100 ms, and progressive fetching.
    pub fn new(path: Vec<[f64; 3]>) -> Self {
        Self {
            path,
            speed: 1.5,
            bandwidth: None,
            duration: Duration::from_secs(30),
            view: View::at([0.0, 0.0, 0.0]),
            concurrency: 4,
            interval: Duration::from_millis(100),
            in_order: false,
        }
    }
}

/// What a walk cost and what its viewer saw.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct WalkReport {
    /// Seconds walked.
    pub seconds: f64,
    /// Metres walked.
    pub distance: f64,
    /// Views sent.
    pub views_sent: u64,
    /// Resets received.
    pub resets: u64,
    /// Deltas received.
    pub deltas: u64,
    /// Entries that arrived in resets.
    pub reset_entries: u64,
    /// Entries added by deltas.
    pub entries_added: u64,
    /// Entries removed by deltas.
    pub entries_removed: u64,
    /// Assets downloaded.
    pub assets_fetched: u64,
    /// Assets already in the cache (a 304).
    pub assets_cached: u64,
    /// Assets the server no longer had (404) when asked.
    pub assets_gone: u64,
    /// Body bytes downloaded.
    pub bytes_fetched: u64,
    /// Of them, for object entries (the geometry near the viewer).
    pub bytes_objects: u64,
    /// For aggregate entries.
    pub bytes_aggregates: u64,
    /// For impostor entries (orthoview images).
    pub bytes_impostors: u64,
    /// For instances entries (model levels shared by their placements).
    pub bytes_instances: u64,
    /// Views a message answered (named in its `view`) whose cut was loaded whole before the
    /// walk ended: the samples of `view_latency_ms`.
    pub views_loaded: u64,
    /// Views a message answered whose cut was not loaded whole when the walk ended.
    pub views_unloaded: u64,
    /// Views no message named: the server sends nothing for a view that leaves the cut as it
    /// was, and answers views that queue up behind a message with one delta for the last.
    pub views_unanswered: u64,
    /// For each view a message answered: from sending the view until every asset of the cut
    /// after that message (and any message that came before they loaded) was loaded.
    pub view_latency_ms: Latencies,
    /// From the start until the first cut was loaded whole.
    pub first_complete_ms: Option<f64>,
    /// From the start until every entry of the cut first had something to draw: its own
    /// assets, or its preview.
    pub first_drawn_ms: Option<f64>,
    /// Frames since the first cut arrived.
    pub frames: u64,
    /// Frames in which an entry of the cut had an asset still missing.
    pub incomplete_frames: u64,
    /// `incomplete_frames / frames` (0 without frames).
    pub incomplete_share: f64,
    /// Frames in which an entry of the cut had nothing to draw: an asset of its own missing,
    /// and no preview loaded.
    pub hole_frames: u64,
    /// `hole_frames / frames` (0 without frames).
    pub hole_share: f64,
    /// The share of the cut's entries that had something to draw, averaged over frames.
    pub drawn_entries_share: f64,
    /// The same, each entry weighed by how large it looks (its radius² / distance² from
    /// the eye, at most 1): the share of what the cut shows that was drawn.
    pub drawn_screen_share: f64,
    /// Entries of the cut at the end.
    pub final_entries: usize,
    /// The cut's generation at the end.
    pub final_generation: u64,
}

/// Percentiles of a set of durations, milliseconds (0 for an empty set).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Latencies {
    /// How many.
    pub count: usize,
    /// The median.
    pub p50: f64,
    /// The 99th percentile.
    pub p99: f64,
    /// The largest.
    pub max: f64,
}

impl Latencies {
    /// The percentiles of `samples` (nearest rank).
    pub fn of(samples: &[Duration]) -> Self {
        let mut ms: Vec<f64> = samples.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        ms.sort_by(f64::total_cmp);
        let rank = |q: f64| -> f64 {
            if ms.is_empty() {
                return 0.0;
            }
            let i = ((q * ms.len() as f64).ceil() as usize).clamp(1, ms.len()) - 1;
            ms[i]
        };
        Self {
            count: ms.len(),
            p50: rank(0.5),
            p99: rank(0.99),
            max: ms.last().copied().unwrap_or(0.0),
        }
    }
}

/// A path through waypoints, walked at a distance from its start.
#[derive(Clone, Debug, PartialEq)]
pub struct Polyline {
    points: Vec<[f64; 3]>,
    /// Distance from the start to each point.
    along: Vec<f64>,
}

impl Polyline {
    /// The path through `points` (at least one, every coordinate finite).
    ///
    /// # Errors
    /// [`WalkError::BadPath`].
    pub fn new(points: &[[f64; 3]]) -> Result<Self, WalkError> {
        if points.is_empty() {
            return Err(WalkError::BadPath("the path has no waypoint".into()));
        }
        if let Some(i) = points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
            return Err(WalkError::BadPath(format!(
                "waypoint {i} is not finite: {:?}",
                points[i]
            )));
        }
        let mut along = Vec::with_capacity(points.len());
        let mut total = 0.0;
        along.push(0.0);
        for pair in points.windows(2) {
            total += distance(pair[0], pair[1]);
            along.push(total);
        }
        Ok(Self {
            points: points.to_vec(),
            along,
        })
    }

    /// The path's length.
    pub fn length(&self) -> f64 {
        self.along.last().copied().unwrap_or(0.0)
    }

    /// The point `d` along the path, clamped to its ends.
    pub fn at(&self, d: f64) -> [f64; 3] {
        let d = d.clamp(0.0, self.length());
        // The first segment whose end is at least `d`.
        let i = self.along.partition_point(|&a| a < d).max(1);
        let Some(&end) = self.points.get(i) else {
            return self.points[self.points.len() - 1];
        };
        let start = self.points[i - 1];
        let span = self.along[i] - self.along[i - 1];
        let t = if span > 0.0 {
            (d - self.along[i - 1]) / span
        } else {
            0.0
        };
        [0, 1, 2].map(|k| start[k] + (end[k] - start[k]) * t)
    }

    /// The point after walking `d` from the start, turning back at each end.
    pub fn walked(&self, d: f64) -> [f64; 3] {
        let length = self.length();
        if length <= 0.0 || !d.is_finite() {
            return self.at(0.0);
        }
        let m = d.max(0.0) % (2.0 * length);
        self.at(if m <= length { m } else { 2.0 * length - m })
    }
}

/// How large an entry looks from `eye`: its radius² / distance², at most 1.
fn screen_size(e: &horizon_protocol::Entry, eye: [f64; 3]) -> f64 {
    let d2: f64 = (0..3)
        .map(|k| (f64::from(e.center[k]) - eye[k]).powi(2))
        .sum();
    let r2 = f64::from(e.radius).powi(2);
    if r2 >= d2 {
        1.0
    } else {
        r2 / d2
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Why a walk stopped.
#[derive(Debug, thiserror::Error)]
pub enum WalkError {
    /// The waypoints are not a path.
    #[error("bad path: {0}")]
    BadPath(String),
    /// The view template is not a view the server takes.
    #[error("bad view: {0}")]
    BadView(String),
    /// Speed or bandwidth out of range.
    #[error("{0}")]
    BadOptions(String),
    /// The stream failed or was closed.
    #[error(transparent)]
    Stream(#[from] StreamError),
    /// A message did not apply.
    #[error("message seq {seq} does not apply: {error}")]
    Apply {
        /// The message's seq.
        seq: u64,
        /// Why.
        error: ApplyError,
    },
    /// After a message, the cut did not count every object exactly once.
    #[error("after message seq {seq} the cut is incomplete: {error}")]
    Incomplete {
        /// The message's seq.
        seq: u64,
        /// How.
        error: Incomplete,
    },
    /// The server answered a view with an error message.
    #[error("the server refused a view: {code}: {message}")]
    Refused {
        /// The error code.
        code: String,
        /// The message.
        message: String,
    },
    /// An asset could not be fetched.
    #[error("asset {hash}: {error}")]
    Asset {
        /// The asset.
        hash: String,
        /// Why.
        error: AssetError,
    },
}

/// One asset download: the hash, and what came of it.
async fn fetch(
    cache: &AssetCache,
    bucket: Option<&TokenBucket>,
    hash: String,
) -> (String, Result<Fetched, AssetError>) {
    let result = cache.get_throttled(&hash, bucket).await;
    (hash, result)
}

/// A walk's state between events: the kept cut, the assets, the views awaiting their cut.
struct Walker {
    start: Instant,
    concurrency: usize,
    cut: LocalCut,
    /// Assets loaded.
    loaded: HashSet<String>,
    /// Assets being downloaded.
    inflight: HashSet<String>,
    /// Assets to download, in the order their entries arrived (with `in_order`).
    queue: VecDeque<String>,
    queued: HashSet<String>,
    /// Fetch in arrival order rather than previews, then largest on screen, first.
    in_order: bool,
    /// The eye of the last view sent.
    eye: [f64; 3],
    /// Every asset the cut needs.
    needed: HashSet<String>,
    /// The kind of entry that first asked for each asset queued, for the report's split.
    kinds: HashMap<String, horizon_protocol::EntryKind>,
    /// How many of them are not loaded.
    missing: usize,
    /// Views sent and not answered yet: id -> when sent.
    sent: BTreeMap<u64, Instant>,
    /// When the views answered, but whose cut is not loaded yet, were sent.
    awaiting: Vec<Instant>,
    /// Views the server answered with no message of their own.
    unanswered: u64,
    latencies: Vec<Duration>,
    report: WalkReport,
}

impl Walker {
    fn new(start: Instant, concurrency: usize) -> Self {
        Self {
            start,
            concurrency,
            cut: LocalCut::new(),
            loaded: HashSet::new(),
            inflight: HashSet::new(),
            queue: VecDeque::new(),
            queued: HashSet::new(),
            in_order: false,
            eye: [0.0; 3],
            needed: HashSet::new(),
            kinds: HashMap::new(),
            missing: 0,
            sent: BTreeMap::new(),
            awaiting: Vec::new(),
            unanswered: 0,
            latencies: Vec::new(),
            report: WalkReport::default(),
        }
    }

    /// One frame: complete or not, once a cut has arrived.
    fn frame(&mut self) {
        if !self.cut.started() {
            return;
        }
        self.report.frames += 1;
        let (mut entries, mut screen) = (1.0, 1.0);
        if self.missing > 0 {
            self.report.incomplete_frames += 1;
            (entries, screen) = self.drawn_shares();
            if entries < 1.0 {
                self.report.hole_frames += 1;
            }
        }
        // Sums over frames until `finish` divides them.
        self.report.drawn_entries_share += entries;
        self.report.drawn_screen_share += screen;
    }

    /// Whether an entry has something to draw: its own assets, or its preview.
    fn entry_drawn(&self, e: &horizon_protocol::Entry) -> bool {
        let loaded = |a: &&horizon_protocol::Asset| self.loaded.contains(&a.hash);
        let preview = |a: &&horizon_protocol::Asset| a.role == AssetRole::Preview;
        e.assets.iter().filter(|a| !preview(a)).all(|a| loaded(&a))
            || e.assets.iter().filter(preview).any(|a| loaded(&a))
    }

    /// Whether every entry of the cut has something to draw.
    fn drawn(&self) -> bool {
        self.cut.entries().values().all(|e| self.entry_drawn(e))
    }

    /// The share of the cut's entries that have something to draw, by count and by how large
    /// they look from the last eye.
    fn drawn_shares(&self) -> (f64, f64) {
        let (mut n, mut drawn, mut size, mut drawn_size) = (0usize, 0usize, 0.0, 0.0);
        for e in self.cut.entries().values() {
            let s = screen_size(e, self.eye);
            n += 1;
            size += s;
            if self.entry_drawn(e) {
                drawn += 1;
                drawn_size += s;
            }
        }
        let share = |a: f64, b: f64| if b > 0.0 { a / b } else { 1.0 };
        (share(drawn as f64, n as f64), share(drawn_size, size))
    }

    /// Applies a server message, checks the cut, and queues the assets it brought.
    fn message(&mut self, message: &ServerMessage) -> Result<(), WalkError> {
        let seq = message.seq().unwrap_or(0);
        let arrived: Vec<&horizon_protocol::Entry> = match message {
            ServerMessage::Error { error } => {
                return Err(WalkError::Refused {
                    code: code_name(error.code),
                    message: error.message.clone(),
                })
            }
            ServerMessage::Reset { entries, .. } => {
                self.report.resets += 1;
                self.report.reset_entries += entries.len() as u64;
                entries.iter().collect()
            }
            ServerMessage::Delta { add, remove, .. } => {
                self.report.deltas += 1;
                self.report.entries_added += add.len() as u64;
                self.report.entries_removed += remove.len() as u64;
                add.iter().map(|a| &a.entry).collect()
            }
        };
        self.cut
            .apply(message)
            .map_err(|error| WalkError::Apply { seq, error })?;
        self.cut
            .check_complete()
            .map_err(|error| WalkError::Incomplete { seq, error })?;
        // The views before the one answered got no message of their own.
        let answered = self.cut.view();
        let later = self.sent.split_off(&(answered + 1));
        let earlier = std::mem::replace(&mut self.sent, later);
        for (id, sent) in earlier {
            if id == answered {
                self.awaiting.push(sent);
            } else {
                self.unanswered += 1;
            }
        }
        for entry in arrived {
            for asset in &entry.assets {
                let h = &asset.hash;
                if self.in_order
                    && !self.loaded.contains(h)
                    && !self.inflight.contains(h)
                    && self.queued.insert(h.clone())
                {
                    self.queue.push_back(h.clone());
                }
                if !self.loaded.contains(h) {
                    self.kinds.entry(h.clone()).or_insert(entry.kind);
                }
            }
        }
        self.needed = self
            .cut
            .asset_hashes()
            .into_iter()
            .map(str::to_owned)
            .collect();
        self.missing = self
            .needed
            .iter()
            .filter(|h| !self.loaded.contains(*h))
            .count();
        self.settle();
        Ok(())
    }

    /// Records a finished download.
    fn fetched(
        &mut self,
        hash: String,
        result: Result<Fetched, AssetError>,
    ) -> Result<(), WalkError> {
        self.inflight.remove(&hash);
        match result {
            Ok(f) => {
                if f.fetched {
                    self.report.assets_fetched += 1;
                } else {
                    self.report.assets_cached += 1;
                }
                self.report.bytes_fetched += f.downloaded;
                let by_kind = match self.kinds.remove(&hash) {
                    Some(horizon_protocol::EntryKind::Object) => &mut self.report.bytes_objects,
                    Some(horizon_protocol::EntryKind::Impostor) => &mut self.report.bytes_impostors,
                    Some(horizon_protocol::EntryKind::Instances) => {
                        &mut self.report.bytes_instances
                    }
                    _ => &mut self.report.bytes_aggregates,
                };
                *by_kind += f.downloaded;
                if self.needed.contains(&hash) {
                    self.missing = self.missing.saturating_sub(1);
                }
                self.loaded.insert(hash);
                self.settle();
                Ok(())
            }
            // An asset of a generation since collected: the delta that replaces it is due.
            Err(AssetError::Client(ClientError::Server { body, .. }))
                if body.error.code == ErrorCode::NotFound =>
            {
                self.report.assets_gone += 1;
                Ok(())
            }
            Err(error) => Err(WalkError::Asset { hash, error }),
        }
    }

    /// The next asset to download: with `in_order`, the oldest queued that the cut still
    /// needs; otherwise a preview the cut needs first, then the asset of the entry largest
    /// on screen from the last eye (ties by hash, so that a walk is repeatable).
    fn next_fetch(&mut self) -> Option<String> {
        if !self.in_order {
            let hash = self.most_wanted()?;
            self.inflight.insert(hash.clone());
            return Some(hash);
        }
        while let Some(hash) = self.queue.pop_front() {
            self.queued.remove(&hash);
            if self.needed.contains(&hash)
                && !self.loaded.contains(&hash)
                && self.inflight.insert(hash.clone())
            {
                return Some(hash);
            }
        }
        None
    }

    /// The asset the progressive order fetches next, if any is still wanted.
    fn most_wanted(&self) -> Option<String> {
        let mut best: Option<((bool, f64), &str)> = None;
        for e in self.cut.entries().values() {
            let screen = screen_size(e, self.eye);
            for a in &e.assets {
                if self.loaded.contains(&a.hash) || self.inflight.contains(&a.hash) {
                    continue;
                }
                let rank = (a.role == AssetRole::Preview, screen);
                let better = best.is_none_or(|(b, h)| {
                    rank.0 != b.0 && rank.0
                        || rank.0 == b.0 && (rank.1 > b.1 || rank.1 == b.1 && a.hash.as_str() < h)
                });
                if better {
                    best = Some((rank, &a.hash));
                }
            }
        }
        best.map(|(_, h)| h.to_owned())
    }

    /// When every asset of the cut is loaded, the views awaiting it are loaded.
    fn settle(&mut self) {
        if !self.cut.started() {
            return;
        }
        if self.report.first_drawn_ms.is_none() && (self.missing == 0 || self.drawn()) {
            self.report.first_drawn_ms = Some(self.start.elapsed().as_secs_f64() * 1e3);
        }
        if self.missing > 0 {
            return;
        }
        let now = Instant::now();
        if self.report.first_complete_ms.is_none() {
            self.report.first_complete_ms =
                Some(now.duration_since(self.start).as_secs_f64() * 1e3);
        }
        for sent in self.awaiting.drain(..) {
            self.latencies.push(now.duration_since(sent));
        }
    }

    fn finish(mut self) -> WalkReport {
        let mut r = std::mem::take(&mut self.report);
        r.seconds = self.start.elapsed().as_secs_f64();
        r.views_loaded = self.latencies.len() as u64;
        r.views_unloaded = self.awaiting.len() as u64;
        r.views_unanswered = self.unanswered + self.sent.len() as u64;
        r.view_latency_ms = Latencies::of(&self.latencies);
        let share = |n: u64| {
            if r.frames > 0 {
                n as f64 / r.frames as f64
            } else {
                0.0
            }
        };
        r.incomplete_share = share(r.incomplete_frames);
        r.hole_share = share(r.hole_frames);
        if r.frames > 0 {
            r.drawn_entries_share /= r.frames as f64;
            r.drawn_screen_share /= r.frames as f64;
        }
        r.final_entries = self.cut.len();
        r.final_generation = self.cut.generation();
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use horizon_protocol::Entry;

    #[test]
    fn the_polyline_interpolates_by_distance() {
        let p =
            Polyline::new(&[[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 0.0, 5.0]]).expect("a path");
        assert_eq!(p.length(), 15.0);
        assert_eq!(p.at(0.0), [0.0, 0.0, 0.0]);
        assert_eq!(p.at(2.5), [2.5, 0.0, 0.0]);
        assert_eq!(p.at(10.0), [10.0, 0.0, 0.0]);
        assert_eq!(p.at(12.0), [10.0, 0.0, 2.0]);
        assert_eq!(p.at(15.0), [10.0, 0.0, 5.0]);
        assert_eq!(p.at(99.0), [10.0, 0.0, 5.0]);
        assert_eq!(p.at(-1.0), [0.0, 0.0, 0.0]);
        // Walking turns back at the end.
        assert_eq!(p.walked(12.0), [10.0, 0.0, 2.0]);
        assert_eq!(p.walked(18.0), [10.0, 0.0, 2.0]);
        assert_eq!(p.walked(25.0), [5.0, 0.0, 0.0]);
        assert_eq!(p.walked(30.0), [0.0, 0.0, 0.0]);
        assert_eq!(p.walked(32.0), [2.0, 0.0, 0.0]);
    }

    #[test]
    fn degenerate_paths_stand_still_and_bad_ones_are_refused() {
        let one = Polyline::new(&[[1.0, 2.0, 3.0]]).expect("one point");
        assert_eq!(one.length(), 0.0);
        assert_eq!(one.walked(100.0), [1.0, 2.0, 3.0]);
        let repeated =
            Polyline::new(&[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]).expect("a path");
        assert_eq!(repeated.at(0.5), [1.5, 0.0, 0.0]);
        assert_eq!(repeated.at(0.0), [1.0, 0.0, 0.0]);
        assert!(Polyline::new(&[]).is_err());
        assert!(Polyline::new(&[[0.0, f64::NAN, 0.0]]).is_err());
    }

    /// An object entry at `x` on the x axis of `radius`, with its own asset and maybe a
    /// preview.
    fn entry(id: &str, x: f32, radius: f32, own: &str, preview: Option<&str>) -> Entry {
        let asset = |hash: &str, role| horizon_protocol::Asset {
            hash: hash.to_owned(),
            bytes: 100,
            role,
        };
        let mut assets = vec![asset(own, AssetRole::Model)];
        assets.extend(preview.map(|p| asset(p, AssetRole::Preview)));
        Entry {
            id: id.to_owned(),
            kind: horizon_protocol::EntryKind::Object,
            assets,
            placements: Vec::new(),
            level: 0,
            pending: false,
            bytes: 100,
            triangles: 12,
            draw_calls: 1,
            center: [x, 0.0, 0.0],
            radius,
            covers: 1,
            impostor: None,
        }
    }

    fn walker_with(in_order: bool, entries: Vec<Entry>) -> Walker {
        let mut w = Walker::new(Instant::now(), 1);
        w.in_order = in_order;
        let reset = ServerMessage::Reset {
            seq: 1,
            view: 1,
            generation: 1,
            published: 1,
            objects: entries.len() as u64,
            entries,
            stopped_by: None,
        };
        w.message(&reset).expect("the reset applies");
        w
    }

    fn fetch_all(w: &mut Walker) -> Vec<String> {
        let mut order = Vec::new();
        while let Some(hash) = w.next_fetch() {
            order.push(hash.clone());
            let fetched = Fetched {
                bytes: Vec::new(),
                fetched: true,
                downloaded: 100,
            };
            w.fetched(hash, Ok(fetched)).expect("recorded");
            w.frame();
        }
        order
    }

    #[test]
    fn previews_come_first_then_the_largest_on_screen_and_a_preview_draws_its_entry() {
        let entries = || {
            vec![
                // Far and small, with a preview; near and large; mid-way.
                entry("o:1@1/1", 500.0, 5.0, "far", Some("far-preview")),
                entry("o:2@1", 10.0, 2.0, "near", None),
                entry("o:3@1", 100.0, 4.0, "mid", None),
            ]
        };
        let mut w = walker_with(false, entries());
        assert!(!w.drawn(), "nothing loaded, nothing drawn");
        assert_eq!(fetch_all(&mut w), ["far-preview", "near", "mid", "far"]);
        assert!(w.drawn());
        let r = w.finish();
        // After the preview and two fetches every entry could be drawn, but the far one
        // was at its preview: the frames in between are incomplete, not holes.
        assert_eq!((r.frames, r.incomplete_frames, r.hole_frames), (4, 3, 2));
        assert!(r.first_drawn_ms <= r.first_complete_ms);
        // Drawn after each fetch: a third, two thirds, all, all.
        assert!((r.drawn_entries_share - 0.75).abs() < 1e-9, "{r:?}");

        // In order: as the entries listed their assets. The near entry, most of the screen,
        // comes third.
        let mut w = walker_with(true, entries());
        let order = fetch_all(&mut w);
        assert_eq!(order.len(), 4);
        assert_eq!(order.iter().filter(|h| h.contains("preview")).count(), 1);
        let in_order = w.finish();
        assert!(in_order.hole_frames <= in_order.incomplete_frames);
        assert!(
            r.drawn_screen_share > in_order.drawn_screen_share + 0.1,
            "{r:?} {in_order:?}"
        );
    }

    #[test]
    fn latencies_are_nearest_rank_percentiles() {
        let samples: Vec<Duration> = (1..=100).map(Duration::from_millis).collect();
        let l = Latencies::of(&samples);
        assert_eq!(l.count, 100);
        assert!((l.p50 - 50.0).abs() < 1e-9);
        assert!((l.p99 - 99.0).abs() < 1e-9);
        assert!((l.max - 100.0).abs() < 1e-9);
        assert_eq!(Latencies::of(&[]), Latencies::default());
    }
}
