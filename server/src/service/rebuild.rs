//! [`Rebuilder`]: the live rebuild. A thread of its own, off the async runtime, waits for
//! changes, debounces them (the quiet time after the last change, at most the longest wait
//! after the first), then rebuilds the aggregates of what changed and publishes the
//! generation it built (`World::rebuild_aggregates`, which uses every core). Changes made
//! during a build stay dirty and start the next one. A failed build is logged and retried. A
//! stop takes effect before the next tree level of a build under way (or between builds);
//! what the build had committed is reused by the next start's build.
//!
//! The worker and its own thread pool run at a lower priority (nice 10 on Linux) than the
//! threads that answer requests: under load, cuts and streams keep their latency and the
//! rebuild takes longer; on an idle machine nothing changes.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use horizon_world::World;

use super::Config;

/// The running worker (see the module docs).
#[derive(Debug)]
pub struct Rebuilder {
    world: Arc<World>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Rebuilder {
    /// Starts the worker over `world`.
    pub fn spawn(world: Arc<World>, config: Config) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (world, stop) = (world.clone(), stop.clone());
            std::thread::Builder::new()
                .name("horizon-rebuild".into())
                .spawn(move || {
                    lower_priority();
                    let pool = rayon::ThreadPoolBuilder::new()
                        .thread_name(|i| format!("horizon-rebuild-{i}"))
                        .start_handler(|_| lower_priority())
                        .build();
                    match pool {
                        Ok(pool) => pool.install(|| work(&world, &config, &stop)),
                        Err(_) => work(&world, &config, &stop),
                    }
                })
                .ok()
        };
        if thread.is_none() {
            tracing::error!("the rebuild worker could not start; generations will not publish");
        }
        Self {
            world,
            stop,
            thread,
        }
    }

    /// Stops the worker at its next safe point (between tree levels of a build) and waits.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        self.world.wake();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The nice value of the rebuild's threads.
const REBUILD_NICE: i32 = 10;

/// Lowers the calling thread's priority (Linux: a thread id names one thread to
/// `setpriority`); elsewhere, or if refused, nothing changes.
fn lower_priority() {
    #[cfg(target_os = "linux")]
    {
        let _ = rustix::process::setpriority_process(Some(rustix::thread::gettid()), REBUILD_NICE);
    }
}

fn work(world: &World, config: &Config, stop: &AtomicBool) {
    let stopped = || stop.load(Ordering::SeqCst);
    loop {
        let due = world.wait_for_rebuild(
            config.debounce_quiet,
            config.debounce_max,
            Duration::from_secs(1),
            &stopped,
        );
        if stopped() {
            return;
        }
        match due {
            Ok(true) => {}
            Ok(false) => continue,
            Err(e) => {
                tracing::error!(error = %e, "the rebuild worker cannot wait for changes");
                std::thread::sleep(Duration::from_secs(1));
                continue;
            }
        }
        let started = Instant::now();
        match world.rebuild_aggregates_until(config.aggregates, &|_| {}, &stopped) {
            Ok(report) => {
                let seconds = started.elapsed().as_secs_f64();
                for (node, why) in report.build.impostors.iter().flat_map(|i| &i.unreadable) {
                    tracing::warn!(node, error = %why, "impostor ray-cast: a child's images could not be read");
                }
                metrics::histogram!("horizon_rebuild_seconds").record(seconds);
                metrics::counter!("horizon_aggregates_built_total")
                    .increment(report.build.built as u64);
                metrics::gauge!("horizon_published_generation").set(report.generation as f64);
                tracing::info!(
                    generation = report.generation,
                    built = report.build.built,
                    reused = report.build.reused,
                    failed = report.build.failed.len(),
                    seconds,
                    build_seconds = report.build.seconds,
                    impostor_seconds = report.build.impostors.as_ref().map_or(0.0, |i| i.seconds),
                    prepare_seconds = report.overhead.prepare_seconds,
                    publish_seconds = report.overhead.publish_seconds,
                    collect_seconds = report.overhead.collect_seconds,
                    level_seconds = ?report
                        .build
                        .level_times
                        .iter()
                        .filter(|l| l.built > 0)
                        .map(|l| (l.depth, l.built, (l.seconds * 1e3).round() / 1e3))
                        .collect::<Vec<_>>(),
                    stages = ?report.build.stages,
                    "published"
                );
            }
            Err(_) if stopped() => {
                tracing::info!("rebuild stopped between levels; the next start resumes it");
                return;
            }
            Err(e) => {
                tracing::error!(error = %e, "rebuild failed; the dirty set waits for the next");
                std::thread::sleep(Duration::from_secs(1));
            }
        }
    }
}
