//! `horizon-lab bench-service`: the world service measured as a user meets it, over HTTP
//! against the real `horizon serve` process. Three parts, each against its peer in the same
//! run:
//! 1. **uploads**: the models of a world uploaded into an empty one with 1 and with 8
//!    concurrent clients (models/s, MB/s), against the same ingest done offline in this
//!    process on one thread and on every core: import, validate, normalise, hash, describe
//!    (the peer), and the same with the levels of detail the upload also builds (the
//!    like-for-like peer);
//! 2. **freshness**: placements issued at 1 per second over a built world (on the clock, not
//!    after the one before is published), each timed from its 2xx to the first published
//!    generation that includes it (p50, p99); then 20 mutations/s
//!    for 60 s, with the dirty set and the generation lag sampled every 100 ms (maxima);
//! 3. **assets**: an open-loop load at a fixed rate against `GET /assets/{hash}` (aggregates
//!    of the published build) and `GET /v1/world`, latencies measured from each request's
//!    scheduled time (so a slow server cannot hide its queue), and the server's resident
//!    memory.
//!
//! Results: markdown on stdout and in `lab/results/service_<world>.md`, JSON beside it.

use std::fmt::Write as _;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use hdrhistogram::Histogram;
use horizon_mesh::rng::Rng;
use horizon_server::outln;
use horizon_world::ingest::{describe_read, import_upload, level_read, normalise, read_stored};
use horizon_world::{content_hash, UploadLimits, World};
use rayon::prelude::*;
use serde::Serialize;
use serde_json::Value;

/// What `bench-service` is asked.
#[derive(Clone, Debug)]
pub struct Args {
    /// A built world (`horizon build`): its models are uploaded, and it is served.
    pub world: PathBuf,
    /// The `horizon` binary.
    pub horizon: PathBuf,
    /// Most models uploaded per client count.
    pub models: usize,
    /// Placements timed for freshness.
    pub placements: usize,
    /// Seconds of sustained mutations.
    pub sustain_seconds: u64,
    /// Mutations per second when sustained.
    pub sustain_rate: u64,
    /// Requests per second of the asset load.
    pub rate: u64,
    /// Seconds of the asset load.
    pub load_seconds: u64,
    /// The report (default lab/results/service_<world>.md).
    pub out: Option<PathBuf>,
    /// Seed of positions and choices.
    pub seed: u64,
    /// Where the served world's log goes (the rebuild's stage times); none: discarded.
    pub server_log: Option<PathBuf>,
}

#[derive(Debug, Serialize)]
struct Report {
    world: String,
    uploads: Vec<UploadRun>,
    offline_one_thread_ms_per_model: f64,
    offline_all_threads_ms_per_model: f64,
    /// The same with levels of detail, as the upload makes them.
    offline_levels_one_thread_ms_per_model: f64,
    offline_levels_all_threads_ms_per_model: f64,
    freshness_ms: Percentiles,
    freshness_samples: usize,
    sustained: Sustained,
    assets: Vec<LoadRun>,
    server_rss_bytes: u64,
}

#[derive(Debug, Serialize)]
struct UploadRun {
    clients: usize,
    models: usize,
    bytes: u64,
    seconds: f64,
    models_per_second: f64,
    megabytes_per_second: f64,
    ms_per_model: f64,
    /// `ms_per_model` over the offline time per model with as many threads.
    ratio_to_offline: f64,
    /// Over the offline time with levels of detail.
    ratio_to_offline_with_levels: f64,
}

#[derive(Debug, Default, Serialize)]
pub(crate) struct Percentiles {
    pub(crate) p50: f64,
    pub(crate) p99: f64,
    pub(crate) max: f64,
}

#[derive(Debug, Default, Serialize)]
struct Sustained {
    rate: u64,
    seconds: u64,
    mutations: u64,
    max_dirty_nodes: u64,
    max_generation_lag: u64,
    final_lag: u64,
    /// Seconds from the end of the mutations to the last generation published.
    catch_up_seconds: f64,
}

#[derive(Debug, Serialize)]
struct LoadRun {
    target: String,
    rate: u64,
    requests: u64,
    errors: u64,
    latency_ms: Percentiles,
}

/// Runs the benchmark.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let source = World::open(&args.world)?;
    let (name, _) = source.identity()?;
    let mut models = Vec::new();
    for row in source.models().rows()?.into_iter().take(args.models) {
        models.push((row.name.clone(), source.models().glb(row.number)?));
    }
    anyhow::ensure!(!models.is_empty(), "{} has no models", args.world.display());
    anyhow::ensure!(
        source.published_manifest()?.is_some(),
        "{} is not built (run horizon build)",
        args.world.display()
    );
    drop(source);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;

    // 1. Uploads against offline ingest.
    eprintln!(
        "horizon-lab: bench-service: offline ingest of {} models",
        models.len()
    );
    let all = rayon::current_num_threads();
    let offline_one = time_offline(&models, 1, false)?;
    let offline_all = time_offline(&models, all, false)?;
    let levels_one = time_offline(&models, 1, true)?;
    let levels_all = time_offline(&models, all, true)?;
    let mut uploads = Vec::new();
    for clients in [1, 8] {
        let scratch = tempdir("upload")?;
        let server = Server::start(&args.horizon, &scratch, None)?;
        let token = server.token(&scratch, "bench")?;
        eprintln!("horizon-lab: bench-service: uploading with {clients} clients");
        let (seconds, bytes) =
            runtime.block_on(upload_all(&server.url, &token, &models, clients))?;
        let per_model = seconds * 1e3 / models.len() as f64;
        let (offline, levels) = if clients == 1 {
            (offline_one, levels_one)
        } else {
            (offline_all, levels_all)
        };
        uploads.push(UploadRun {
            clients,
            models: models.len(),
            bytes,
            seconds,
            models_per_second: models.len() as f64 / seconds,
            megabytes_per_second: bytes as f64 / 1e6 / seconds,
            ms_per_model: per_model,
            ratio_to_offline: per_model / offline,
            ratio_to_offline_with_levels: per_model / levels,
        });
        drop(server);
        let _ = std::fs::remove_dir_all(&scratch);
    }

    // 2. Freshness and sustained load on a copy of the built world.
    let served = tempdir("served")?;
    copy_dir(&args.world, &served)?;
    let server = Server::start(&args.horizon, &served, args.server_log.as_deref())?;
    let token = server.token(&served, "bench")?;
    eprintln!(
        "horizon-lab: bench-service: {} placements at 1/s",
        args.placements
    );
    let (freshness, samples) =
        runtime.block_on(freshness(&server.url, &token, args.placements, args.seed))?;
    eprintln!(
        "horizon-lab: bench-service: {} mutations/s for {} s",
        args.sustain_rate, args.sustain_seconds
    );
    let sustained = runtime.block_on(sustain(
        &server.url,
        &token,
        args.sustain_rate,
        args.sustain_seconds,
        args.seed,
    ))?;

    // 3. Asset load, once the rebuild has caught up (every aggregate fetched stays named by a
    // published manifest: a load on a world still publishing asks for collected ones), on the
    // aggregates published then.
    let catch_up = runtime.block_on(settle(&server.url))?;
    let mut assets = Vec::new();
    let hashes = runtime.block_on(published_aggregates(&served, &server.url))?;
    for target in ["assets", "world"] {
        eprintln!(
            "horizon-lab: bench-service: {} req/s on {target}",
            args.rate
        );
        let urls: Vec<String> = match target {
            "assets" => hashes
                .iter()
                .map(|h| format!("{}/assets/{h}", server.url))
                .collect(),
            _ => vec![format!("{}/v1/world", server.url)],
        };
        let (requests, errors, latency) = runtime.block_on(open_loop(
            urls,
            args.rate,
            args.load_seconds,
            args.seed,
            None,
        ))?;
        assets.push(LoadRun {
            target: target.into(),
            rate: args.rate,
            requests,
            errors,
            latency_ms: latency,
        });
    }
    let server_rss_bytes = server.peak_rss();
    let sustained = Sustained {
        catch_up_seconds: catch_up,
        ..sustained
    };
    drop(server);
    let _ = std::fs::remove_dir_all(&served);

    let report = Report {
        world: name.clone(),
        uploads,
        offline_one_thread_ms_per_model: offline_one,
        offline_all_threads_ms_per_model: offline_all,
        offline_levels_one_thread_ms_per_model: levels_one,
        offline_levels_all_threads_ms_per_model: levels_all,
        freshness_ms: freshness,
        freshness_samples: samples,
        sustained,
        assets,
        server_rss_bytes,
    };
    let md = markdown(&report, args);
    let path = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(crate::RESULTS).join(format!("service_{name}.md")));
    horizon_world::write_atomically(&path, md.as_bytes())?;
    horizon_world::write_atomically(
        &path.with_extension("json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    outln!("{}", md.trim_end())?;
    Ok(())
}

/// Milliseconds per model of the offline ingest on `threads` threads: import under the upload
/// limits, validate, normalise, hash, describe, and with `levels` the levels of detail (beside
/// the descriptors, as the upload builds them).
fn time_offline(models: &[(String, Vec<u8>)], threads: usize, levels: bool) -> anyhow::Result<f64> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let limits = UploadLimits::default();
    let started = Instant::now();
    pool.install(|| {
        models.par_iter().try_for_each(|(name, bytes)| {
            let ingested = import_upload(bytes, &limits)?;
            let glb = normalise(name, &ingested.mesh)?;
            std::hint::black_box(content_hash(&glb));
            let stored = read_stored(name, &glb)?;
            if levels {
                let (described, chain) = rayon::join(
                    || describe_read(name, &stored),
                    || level_read(&stored, glb.len() as u64),
                );
                described?;
                std::hint::black_box(chain);
            } else {
                describe_read(name, &stored)?;
            }
            Ok::<(), horizon_world::WorldError>(())
        })
    })?;
    Ok(started.elapsed().as_secs_f64() * 1e3 / models.len() as f64)
}

/// Uploads every model with `clients` concurrent clients; returns (seconds, bytes).
async fn upload_all(
    url: &str,
    token: &str,
    models: &[(String, Vec<u8>)],
    clients: usize,
) -> anyhow::Result<(f64, u64)> {
    let client = reqwest::Client::new();
    let queue = Arc::new(std::sync::Mutex::new(models.to_vec()));
    let started = Instant::now();
    let mut tasks = Vec::new();
    for _ in 0..clients {
        let (client, queue, url, token) = (
            client.clone(),
            queue.clone(),
            url.to_owned(),
            token.to_owned(),
        );
        tasks.push(tokio::spawn(async move {
            let mut bytes = 0u64;
            loop {
                let next = queue.lock().ok().and_then(|mut q| q.pop());
                let Some((name, body)) = next else {
                    return Ok::<u64, anyhow::Error>(bytes);
                };
                bytes += body.len() as u64;
                let response = client
                    .post(format!("{url}/v1/models"))
                    .query(&[("name", name)])
                    .bearer_auth(&token)
                    .header("content-type", "model/gltf-binary")
                    .body(body)
                    .send()
                    .await?;
                anyhow::ensure!(
                    response.status().is_success(),
                    "upload answered {}: {}",
                    response.status(),
                    response.text().await.unwrap_or_default()
                );
            }
        }));
    }
    let mut bytes = 0;
    for t in tasks {
        bytes += t.await??;
    }
    Ok((started.elapsed().as_secs_f64(), bytes))
}

/// Places `count` objects at 1 per second at seeded places over the world's bounds (issued on
/// the clock, whatever the rebuild is doing: `DESIGN.md`'s definition), each timed from its
/// 2xx to the first published generation at or past its own, watched by one poller of
/// `/v1/world` every 10 ms.
async fn freshness(
    url: &str,
    token: &str,
    count: usize,
    seed: u64,
) -> anyhow::Result<(Percentiles, usize)> {
    let client = reqwest::Client::new();
    let world: Value = world_status(&client, url).await?;
    let (lo, hi) = bounds(&world)?;
    let models = model_ids(&client, url).await?;
    let (tell, published) = tokio::sync::watch::channel(0u64);
    let _poller = {
        let (client, url) = (client.clone(), url.to_owned());
        AbortOnDrop(tokio::spawn(async move {
            loop {
                let w = world_status(&client, &url).await.ok();
                if let Some(p) = w.and_then(|w| w["published"].as_u64()) {
                    tell.send_if_modified(|v| std::mem::replace(v, p) != p);
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        }))
    };
    let mut rng = Rng::new(seed);
    let mut timed = Vec::with_capacity(count);
    let mut next = Instant::now();
    for _ in 0..count {
        tokio::time::sleep_until(next.into()).await;
        next += Duration::from_secs(1);
        let body = placement(&mut rng, &models, lo, hi);
        let created: Value = client
            .post(format!("{url}/v1/objects"))
            .bearer_auth(token)
            .json(&body)
            .send()
            .await?
            .error_for_status()?
            .json()
            .await?;
        let acknowledged = Instant::now();
        let generation = created["generation"].as_u64().context("no generation")?;
        let mut published = published.clone();
        timed.push(tokio::spawn(async move {
            let seen = tokio::time::timeout(
                Duration::from_secs(600),
                published.wait_for(|&p| p >= generation),
            )
            .await;
            anyhow::ensure!(
                matches!(seen, Ok(Ok(_))),
                "generation {generation} was not published within 10 minutes"
            );
            Ok(acknowledged.elapsed())
        }));
    }
    let mut histogram = Histogram::<u64>::new(3)?;
    for t in timed {
        histogram.record(t.await??.as_micros() as u64)?;
    }
    Ok((percentiles(&histogram), count))
}

/// `GET /v1/world`, parsed.
async fn world_status(client: &reqwest::Client, url: &str) -> anyhow::Result<Value> {
    Ok(client
        .get(format!("{url}/v1/world"))
        .send()
        .await?
        .json()
        .await?)
}

/// A task aborted when this is dropped, so that an early return leaves none running.
#[derive(Debug)]
struct AbortOnDrop(tokio::task::JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// Waits until the last generation is published; returns the seconds that took.
async fn settle(url: &str) -> anyhow::Result<f64> {
    let client = reqwest::Client::new();
    let started = Instant::now();
    loop {
        let w: Value = world_status(&client, url).await?;
        let (Some(published), Some(generation)) =
            (w["published"].as_u64(), w["generation"].as_u64())
        else {
            anyhow::bail!("/v1/world names no generation and published: {w}");
        };
        if published >= generation {
            return Ok(started.elapsed().as_secs_f64());
        }
        anyhow::ensure!(
            started.elapsed() < Duration::from_secs(600),
            "the rebuild did not catch up within 10 minutes"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// `rate` mutations per second for `seconds` (placements, and moves of what was placed),
/// sampling the dirty set and the generation lag every 100 ms.
async fn sustain(
    url: &str,
    token: &str,
    rate: u64,
    seconds: u64,
    seed: u64,
) -> anyhow::Result<Sustained> {
    let client = reqwest::Client::new();
    let world: Value = world_status(&client, url).await?;
    let (lo, hi) = bounds(&world)?;
    let models = model_ids(&client, url).await?;
    let sampler = {
        let (client, url) = (client.clone(), url.to_owned());
        tokio::spawn(async move {
            let (mut dirty, mut lag) = (0u64, 0u64);
            let end = Instant::now() + Duration::from_secs(seconds);
            while Instant::now() < end {
                if let Ok(w) = world_status(&client, &url).await {
                    dirty = dirty.max(w["dirty_nodes"].as_u64().unwrap_or(0));
                    let g = w["generation"].as_u64().unwrap_or(0);
                    let p = w["published"].as_u64().unwrap_or(0);
                    lag = lag.max(g.saturating_sub(p));
                }
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            (dirty, lag)
        })
    };
    let mut rng = Rng::new(seed ^ 0x5A5A);
    let mut placed: Vec<u64> = Vec::new();
    let interval = Duration::from_secs_f64(1.0 / rate.max(1) as f64);
    let started = Instant::now();
    let mut next = started;
    let mut mutations = 0;
    while started.elapsed() < Duration::from_secs(seconds) {
        tokio::time::sleep_until(next.into()).await;
        next += interval;
        let response = if placed.is_empty() || rng.chance(0.5) {
            client
                .post(format!("{url}/v1/objects"))
                .bearer_auth(token)
                .json(&placement(&mut rng, &models, lo, hi))
                .send()
                .await?
        } else {
            let id = placed[rng.below(placed.len())];
            let to = placement(&mut rng, &models, lo, hi);
            client
                .patch(format!("{url}/v1/objects/{id}"))
                .bearer_auth(token)
                .json(&serde_json::json!({"translation": to["translation"]}))
                .send()
                .await?
        };
        let created: Value = response.error_for_status()?.json().await?;
        if let Some(id) = created["id"].as_u64() {
            placed.push(id);
        }
        mutations += 1;
    }
    let (max_dirty_nodes, max_generation_lag) = sampler.await?;
    let w: Value = world_status(&client, url).await?;
    let final_lag = w["generation"]
        .as_u64()
        .unwrap_or(0)
        .saturating_sub(w["published"].as_u64().unwrap_or(0));
    Ok(Sustained {
        rate,
        seconds,
        mutations,
        max_dirty_nodes,
        max_generation_lag,
        final_lag,
        catch_up_seconds: 0.0,
    })
}

/// An open-loop load: requests scheduled at `rate` per second for `seconds`, each sent at its
/// time whatever the ones before are doing; latency from the scheduled time to the body's
/// end. Each request sends `accept_encoding`, if given, as `Accept-Encoding` (the body is read
/// as it comes, not decoded). Returns (requests, errors, latencies).
pub(crate) async fn open_loop(
    urls: Vec<String>,
    rate: u64,
    seconds: u64,
    seed: u64,
    accept_encoding: Option<&str>,
) -> anyhow::Result<(u64, u64, Percentiles)> {
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(256)
        .build()?;
    let histogram = Arc::new(std::sync::Mutex::new(Histogram::<u64>::new(3)?));
    let errors = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let interval = Duration::from_secs_f64(1.0 / rate.max(1) as f64);
    let total = rate * seconds;
    let started = Instant::now();
    let mut rng = Rng::new(seed ^ 0xA55E7);
    let mut tasks = Vec::with_capacity(total as usize);
    for k in 0..total {
        let scheduled = started + interval * k as u32;
        tokio::time::sleep_until(scheduled.into()).await;
        let mut request = client.get(&urls[rng.below(urls.len())]);
        if let Some(encoding) = accept_encoding {
            request = request.header(reqwest::header::ACCEPT_ENCODING, encoding);
        }
        let (histogram, errors) = (histogram.clone(), errors.clone());
        tasks.push(tokio::spawn(async move {
            let ok = match request.send().await {
                Ok(r) if r.status().is_success() => r.bytes().await.is_ok(),
                _ => false,
            };
            if !ok {
                errors.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
            if let Ok(mut h) = histogram.lock() {
                let _ = h.record(scheduled.elapsed().as_micros() as u64);
            }
        }));
    }
    for t in tasks {
        t.await?;
    }
    let h = histogram
        .lock()
        .map_err(|_| anyhow::anyhow!("histogram lock poisoned"))?;
    Ok((
        total,
        errors.load(std::sync::atomic::Ordering::Relaxed),
        percentiles(&h),
    ))
}

/// The aggregate hashes of the manifest `dir` publishes, read over HTTP: the record from the
/// world's database (read beside the server), the manifest from `/assets/{hash}`.
async fn published_aggregates(dir: &Path, url: &str) -> anyhow::Result<Vec<String>> {
    use horizon_world::MetaStore;
    let meta = horizon_world::SqliteMeta::open(&dir.join("world.db"), "", 0)?;
    let hash = meta
        .published()?
        .manifest
        .context("the served world publishes no manifest")?;
    let manifest: Value = reqwest::get(format!("{url}/assets/{hash}"))
        .await?
        .error_for_status()?
        .json()
        .await?;
    let hashes: Vec<String> = manifest["nodes"]
        .as_object()
        .context("a manifest without nodes")?
        .values()
        .filter_map(|e| e["glb"].as_str().map(str::to_owned))
        .collect();
    anyhow::ensure!(
        !hashes.is_empty(),
        "the published manifest names no aggregate"
    );
    Ok(hashes)
}

/// The world's bounds from `/v1/world`.
fn bounds(world: &Value) -> anyhow::Result<([f32; 3], [f32; 3])> {
    let corner = |k: &str| -> anyhow::Result<[f32; 3]> {
        let v = world["bounds"][k]
            .as_array()
            .context("the world has no bounds")?;
        Ok([0, 1, 2].map(|i| v.get(i).and_then(Value::as_f64).unwrap_or(0.0) as f32))
    };
    Ok((corner("min")?, corner("max")?))
}

/// The first page of model ids.
async fn model_ids(client: &reqwest::Client, url: &str) -> anyhow::Result<Vec<String>> {
    let page: Value = client
        .get(format!("{url}/v1/models?limit=1000"))
        .send()
        .await?
        .json()
        .await?;
    let ids: Vec<String> = page["models"]
        .as_array()
        .context("no models")?
        .iter()
        .filter_map(|m| m["id"].as_str().map(str::to_owned))
        .collect();
    anyhow::ensure!(!ids.is_empty(), "the world has no models");
    Ok(ids)
}

/// A seeded placement over the box `lo..hi` at ground level.
fn placement(rng: &mut Rng, models: &[String], lo: [f32; 3], hi: [f32; 3]) -> Value {
    let half = rng.angle() * 0.5;
    serde_json::json!({
        "model": models[rng.below(models.len())],
        "translation": [rng.range(lo[0], hi[0]), 0.0, rng.range(lo[2], hi[2])],
        "rotation": [0.0, half.sin(), 0.0, half.cos()],
    })
}

fn percentiles(h: &Histogram<u64>) -> Percentiles {
    Percentiles {
        p50: h.value_at_quantile(0.5) as f64 / 1e3,
        p99: h.value_at_quantile(0.99) as f64 / 1e3,
        max: h.max() as f64 / 1e3,
    }
}

/// A `horizon serve` child process on a free port.
struct Server {
    child: Child,
    url: String,
}

impl Server {
    fn start(horizon: &Path, dir: &Path, log: Option<&Path>) -> anyhow::Result<Self> {
        let stderr = match log {
            Some(path) => Stdio::from(
                std::fs::File::create(path)
                    .with_context(|| format!("cannot write {}", path.display()))?,
            ),
            None => Stdio::null(),
        };
        let mut child = Command::new(horizon)
            .args(["serve"])
            .arg(dir)
            .args(["--listen", "127.0.0.1:0"])
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(stderr)
            .spawn()
            .with_context(|| format!("cannot start {}", horizon.display()))?;
        let mut line = String::new();
        BufReader::new(child.stdout.take().context("no stdout")?).read_line(&mut line)?;
        let url = line
            .trim()
            .strip_prefix("listening on ")
            .with_context(|| format!("horizon serve printed {line:?}"))?
            .to_owned();
        Ok(Self { child, url })
    }

    fn token(&self, dir: &Path, user: &str) -> anyhow::Result<String> {
        let horizon = std::fs::read_link(format!("/proc/{}/exe", self.child.id()))?;
        let out = Command::new(horizon)
            .args(["token", "create"])
            .arg(dir)
            .args(["--user", user])
            .output()?;
        anyhow::ensure!(out.status.success(), "token create failed");
        Ok(String::from_utf8(out.stdout)?.trim().to_owned())
    }

    /// The server's peak resident set size (Linux `VmHWM`), 0 where unknown.
    fn peak_rss(&self) -> u64 {
        crate::load::status_bytes(&self.child.id().to_string(), "VmHWM:").unwrap_or(0)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn tempdir(what: &str) -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("horizon-bench-{what}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

fn copy_dir(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to)?;
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if entry.file_type()?.is_dir() {
            copy_dir(&entry.path(), &target)?;
        } else {
            std::fs::copy(entry.path(), &target)?;
        }
    }
    Ok(())
}

fn markdown(r: &Report, args: &Args) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# The world service on {}\n", r.world);
    let _ = writeln!(
        s,
        "`horizon-lab bench-service {} --models {} --placements {} --rate {}` against \
         `horizon serve` (a child process) on this machine (2 cores), one run; the client \
         shares the machine.\n",
        args.world.display(),
        args.models,
        args.placements,
        args.rate
    );
    let _ = writeln!(s, "## Uploads\n");
    let _ = writeln!(
        s,
        "Offline ingest in this process (import, validate, normalise, hash, describe): \
         {:.1} ms per model on one thread, {:.1} ms on every core. With the levels of detail \
         the upload also builds (beside the descriptors): {:.1} ms and {:.1} ms.\n",
        r.offline_one_thread_ms_per_model,
        r.offline_all_threads_ms_per_model,
        r.offline_levels_one_thread_ms_per_model,
        r.offline_levels_all_threads_ms_per_model
    );
    let _ = writeln!(
        s,
        "| clients | models | MB | seconds | models/s | MB/s | ms per model | vs offline | target <= 1.25 | vs offline with levels |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for u in &r.uploads {
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {:.2} | {:.1} | {:.2} | {:.1} | {:.2}x | {} | {:.2}x |",
            u.clients,
            u.models,
            u.bytes as f64 / 1e6,
            u.seconds,
            u.models_per_second,
            u.megabytes_per_second,
            u.ms_per_model,
            u.ratio_to_offline,
            if u.ratio_to_offline <= 1.25 {
                "PASS"
            } else {
                "FAIL"
            },
            u.ratio_to_offline_with_levels
        );
    }
    let _ = writeln!(s, "\n## Freshness\n");
    let _ = writeln!(
        s,
        "{} placements issued at 1 per second (on the clock, whatever the rebuild is doing), \
         each from its 2xx to the first published generation that includes it: p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms (target p99 <= 2,000 ms: {}).\n",
        r.freshness_samples,
        r.freshness_ms.p50,
        r.freshness_ms.p99,
        r.freshness_ms.max,
        if r.freshness_ms.p99 <= 2000.0 { "PASS" } else { "FAIL" }
    );
    let _ = writeln!(
        s,
        "Sustained: {} mutations at {}/s for {} s; the dirty set peaked at {} nodes and the \
         generation lag at {} (it was {} at the end, and every generation was published \
         {:.1} s later).\n",
        r.sustained.mutations,
        r.sustained.rate,
        r.sustained.seconds,
        r.sustained.max_dirty_nodes,
        r.sustained.max_generation_lag,
        r.sustained.final_lag,
        r.sustained.catch_up_seconds
    );
    let _ = writeln!(s, "## Assets\n");
    let _ = writeln!(
        s,
        "| target | rate | requests | errors | p50 ms | p99 ms | max ms |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for a in &r.assets {
        let _ = writeln!(
            s,
            "| {} | {}/s | {} | {} | {:.2} | {:.2} | {:.1} |",
            a.target,
            a.rate,
            a.requests,
            a.errors,
            a.latency_ms.p50,
            a.latency_ms.p99,
            a.latency_ms.max
        );
    }
    let _ = writeln!(
        s,
        "\nThe server's peak resident memory: {:.0} MB.",
        r.server_rss_bytes as f64 / 1e6
    );
    s
}
