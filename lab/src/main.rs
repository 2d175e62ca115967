//! The `horizon-lab` binary: what measures and researches Horizon, kept out of the product.
//! Workloads (`gen`), reports and benchmarks against peers and baselines (`report`, `sweep`,
//! `bench-bvh`, `bench-aggregates`, `distance`) and calibration (`calibrate`). Its results
//! go to `lab/results/`; the scripts that drive peers and third-party tools are in
//! `lab/bench/`.
//!
//! # Layout
//! - `gen.rs`: `gen model`, `gen world`.
//! - `report.rs`: `report`, the join download against naive and unoptimised aggregates;
//!   `measuring.rs`: the store the unoptimised baseline is built into.
//! - `sweep.rs`: `sweep`, Figure 5.
//! - `bench_bvh.rs`: `bench-bvh`; `bench_aggregates.rs`: `bench-aggregates`;
//!   `bench_descriptors.rs`: `bench-descriptors`; `bench_service.rs`: `bench-service` (uploads,
//!   freshness, asset load against `horizon serve`).
//! - `load.rs`: `load`, the query API under simulated viewers and mutations.
//! - `fidelity.rs`: `fidelity`, what a cut's image loses against the full world, ray-cast.
//! - `calibrate.rs`: `calibrate`, Table 1.
//! - `distance.rs`: `distance`, the Hausdorff yardstick.
//! - `views.rs`: the seeded viewpoints they share; `input.rs`: a built world's BVH input.

mod bench_aggregates;
mod bench_bvh;
mod bench_descriptors;
mod bench_service;
mod calibrate;
mod distance;
mod fidelity;
mod gen;
mod input;
mod load;
mod measuring;
mod report;
mod sweep;
mod views;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use horizon_bvh::{DEFAULT_MAX_RESULTS, DEFAULT_MIN_SOLID_ANGLE};

/// Where results are written by default, relative to the repository's root.
const RESULTS: &str = "lab/results";

/// Horizon's lab: workloads, benchmarks, reports and calibration.
#[derive(Debug, Parser)]
#[command(name = "horizon-lab", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Seeded procedural workloads.
    #[command(subcommand)]
    Gen(GenCommand),
    /// The join download of a built world: for seeded viewpoints, the unique bytes of every
    /// asset in the cut, with draw calls and textures, against every model of the world
    /// (naive) and against unoptimised aggregates (built into DIR/baseline on first use; only their sizes and handoffs are kept).
    Report {
        /// The built world directory.
        dir: PathBuf,
        /// Number of seeded viewpoints.
        #[arg(long, default_value_t = 10)]
        views: usize,
        /// Seed of the viewpoints.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Smallest solid angle (steradians) shown as itself.
        #[arg(long, default_value_t = DEFAULT_MIN_SOLID_ANGLE as f32)]
        min_solid_angle: f32,
        /// Most entries in a cut.
        #[arg(long, default_value_t = DEFAULT_MAX_RESULTS)]
        max_results: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Figure 5: average cut cost (nodes visited, cut size) over seeded viewpoints for trees
    /// built with mu in {0, 0.2, ..., 1} and w in {0, 0.2, 0.5, 1}, on built worlds.
    Sweep {
        /// Built world directories.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Viewpoints per tree.
        #[arg(long, default_value_t = 50)]
        views: usize,
        /// Seed of the viewpoints.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Smallest solid angle (steradians) shown as itself.
        #[arg(long, default_value_t = DEFAULT_MIN_SOLID_ANGLE as f32)]
        min_solid_angle: f32,
        /// Most entries per cut.
        #[arg(long, default_value_t = DEFAULT_MAX_RESULTS)]
        max_results: usize,
        /// Print JSON instead of a markdown table.
        #[arg(long)]
        json: bool,
    },
    /// Measures the BVH's targets on a built world (bulk rebuild, incremental insertion,
    /// cut queries beside the obvhs baseline, standing-query updates, memory) and writes a
    /// markdown report with PASS/FAIL per target.
    BenchBvh {
        /// The built world directory (`horizon build` wrote its descriptors.json).
        dir: PathBuf,
        /// Seeded viewpoints for the cut queries.
        #[arg(long, default_value_t = 200)]
        views: usize,
        /// Seed of the viewpoints and of the walk.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Steps of 1 m of the standing-query walk.
        #[arg(long, default_value_t = 2000)]
        steps: usize,
        /// Smallest solid angle (steradians) shown as itself.
        #[arg(long, default_value_t = DEFAULT_MIN_SOLID_ANGLE as f32)]
        min_solid_angle: f32,
        /// Most entries per cut.
        #[arg(long, default_value_t = DEFAULT_MAX_RESULTS)]
        max_results: usize,
        /// The markdown report (default: lab/results/bvh_<world name>.md).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print the report as JSON on stdout (the markdown file is still written).
        #[arg(long)]
        json: bool,
    },
    /// The rebuild's benchmark: a full aggregate build of a built world from scratch
    /// (time, memory), then seeded inserts and the incremental rebuild (what it touched and
    /// how long it took). Writes lab/results/aggregates_<world>.md.
    BenchAggregates {
        /// The built world directory.
        dir: PathBuf,
        /// Objects inserted before the incremental rebuild.
        #[arg(long, default_value_t = 100)]
        insert: usize,
        /// Seed of the inserted objects.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// The markdown report (default: lab/results/aggregates_<world name>.md).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The descriptors' targets: time per model on one core, batch speed-up, invariance to
    /// rigid motions, hostile UVs. Writes lab/results/descriptors.{md,json}.
    BenchDescriptors {
        /// Folder holding the shared models (assets/models of the repository).
        #[arg(long, default_value = "assets/models")]
        assets: PathBuf,
        /// Folder to write descriptors.md and descriptors.json into.
        #[arg(long, default_value = RESULTS)]
        out: PathBuf,
    },
    /// The world service over HTTP against a `horizon serve` child: uploads with 1 and 8
    /// clients against offline ingest, freshness of placements, sustained mutations, asset
    /// load at a fixed rate. Writes lab/results/service_<world>.{md,json}.
    BenchService {
        /// A built world (`horizon build`): its models are uploaded, and a copy is served.
        world: PathBuf,
        /// The `horizon` binary (default: beside this one).
        #[arg(long)]
        horizon: Option<PathBuf>,
        /// Most models uploaded per client count.
        #[arg(long, default_value_t = 2000)]
        models: usize,
        /// Placements timed for freshness (one per second).
        #[arg(long, default_value_t = 200)]
        placements: usize,
        /// Seconds of sustained mutations.
        #[arg(long, default_value_t = 60)]
        sustain_seconds: u64,
        /// Mutations per second when sustained.
        #[arg(long, default_value_t = 20)]
        sustain_rate: u64,
        /// Requests per second of the asset load.
        #[arg(long, default_value_t = 1000)]
        rate: u64,
        /// Seconds of each asset load.
        #[arg(long, default_value_t = 30)]
        load_seconds: u64,
        /// The report (default lab/results/service_<world>.md).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed of positions and choices.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Where the served world's log goes (its rebuilds' stage times).
        #[arg(long)]
        server_log: Option<PathBuf>,
    },
    /// The query API under load: simulated viewers walk seeded paths holding standing queries
    /// on `/v1/stream` while a client mutates the world; camera-update-to-delta latency,
    /// deltas, bytes, coalesced views, errors, and the server's CPU and memory.
    Load {
        #[command(flatten)]
        args: load::Args,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// What a cut's image loses against the full world: both ray-cast at seeded views (street
    /// level, overhead, outside), PSNR, SSIM, pixels off by more than 16 levels, holes, and the
    /// bytes, draw calls and triangles of each, with the bounds IoU of every aggregate.
    Fidelity {
        #[command(flatten)]
        args: fidelity::Args,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// `GET /v1/cut` under an open-loop load at seeded street-level eyes: p50 and p99.
    BenchCut {
        /// The server, `http://HOST:PORT`.
        url: String,
        /// Requests per second.
        #[arg(long, default_value_t = 500)]
        rate: u64,
        /// Seconds.
        #[arg(long, default_value_t = 30)]
        seconds: u64,
        /// Distinct seeded eyes.
        #[arg(long, default_value_t = 200)]
        views: usize,
        /// Seed of the eyes.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Eye height (y), metres.
        #[arg(long, default_value_t = 2.0)]
        height: f64,
        /// Ask for cuts without instances entries (every node as its aggregate).
        #[arg(long)]
        no_instances: bool,
        /// Send this `Accept-Encoding` (`zstd`, `gzip`), as a browser does; by default none,
        /// and the server sends plain JSON.
        #[arg(long)]
        accept_encoding: Option<String>,
    },
    /// Derives Table 1's deduplication thresholds by the paper's procedure (renders from three
    /// directions, SSIM, every pair of models and perturbed variants) and writes table1.json
    /// and table1.md.
    Calibrate {
        /// Folder to write table1.json and table1.md into.
        #[arg(long, default_value = "descriptors/data")]
        out: PathBuf,
        /// Folder holding the shared models (assets/models of the repository).
        #[arg(long, default_value = "assets/models")]
        assets: PathBuf,
        /// SSIM at or above which two renders count as indistinguishable.
        #[arg(long, default_value_t = 0.95)]
        ssim: f64,
        /// Seeds per worldgen model (each seed is a similar but distinct model).
        #[arg(long, default_value_t = 2)]
        seeds: u64,
        /// Also write every compared pair (names, z_diff, t_diff, SSIM per size) as JSON.
        #[arg(long)]
        pairs: Option<PathBuf>,
    },
    /// Symmetric Metro-style Hausdorff distance between two models (vertex, edge and face
    /// samples; exact point-to-triangle distance).
    Distance {
        /// The reference model.
        a: PathBuf,
        /// The model compared with it.
        b: PathBuf,
        /// Area-uniform face samples per direction (edges get as many; vertices are added).
        #[arg(long, default_value_t = 100_000)]
        samples: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Debug, Subcommand)]
enum GenCommand {
    /// Writes a benchmark world (village, island, city, city9 or city-distinct) as a world
    /// directory.
    World {
        /// The world's name.
        name: String,
        /// The directory to write (created if missing).
        dir: PathBuf,
        /// Seed of the generator: the same seed gives the same world.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Folder of user models for city and city9 (default: the repository's
        /// assets/models).
        #[arg(long)]
        assets: Option<PathBuf>,
        /// city-distinct only: the number of buildings (default 60,000).
        #[arg(long)]
        objects: Option<usize>,
    },
    /// Writes one of the benchmark models shaped like the IAS paper's Table 2:
    /// maple-tree, village-mesh, patio-chair or stonehenge.
    Model {
        /// The model's name.
        name: String,
        /// The .glb file to write.
        output: PathBuf,
        /// Seed of the generator: the same seed gives the same model.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print a JSON report instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// The `horizon` binary: as given, else the one beside this binary.
fn horizon_binary(given: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    if let Some(path) = given {
        return Ok(path);
    }
    let beside = std::env::current_exe()?.with_file_name("horizon");
    anyhow::ensure!(
        beside.is_file(),
        "no horizon binary at {} (build horizon-server, or pass --horizon)",
        beside.display()
    );
    Ok(beside)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Gen(GenCommand::Model {
            name,
            output,
            seed,
            json,
        }) => gen::model(&name, &output, seed, json),
        Command::Gen(GenCommand::World {
            name,
            dir,
            seed,
            assets,
            objects,
        }) => gen::world(&name, &dir, seed, assets.as_deref(), objects),
        Command::Report {
            dir,
            views,
            seed,
            min_solid_angle,
            max_results,
            json,
        } => report::run(&dir, views, seed, min_solid_angle, max_results, json),
        Command::Fidelity { args, json } => fidelity::run(&args, json),
        Command::Sweep {
            dirs,
            views,
            seed,
            min_solid_angle,
            max_results,
            json,
        } => sweep::run(&dirs, views, seed, min_solid_angle, max_results, json),
        Command::BenchBvh {
            dir,
            views,
            seed,
            steps,
            min_solid_angle,
            max_results,
            out,
            json,
        } => bench_bvh::run(&bench_bvh::BenchArgs {
            dir,
            views,
            seed,
            steps,
            min_solid_angle,
            max_results,
            out,
            json,
        }),
        Command::BenchAggregates {
            dir,
            insert,
            seed,
            out,
        } => bench_aggregates::run(&dir, insert, seed, out.as_deref()),
        Command::BenchDescriptors { assets, out } => bench_descriptors::run(&assets, &out),
        Command::Load { args, json } => load::run(&args).and_then(|r| load::print(&r, json)),
        Command::BenchCut {
            url,
            rate,
            seconds,
            views,
            seed,
            height,
            no_instances,
            accept_encoding,
        } => {
            let instances = !no_instances;
            let encoding = accept_encoding.as_deref();
            load::bench_cut(
                &url, rate, seconds, views, seed, height, instances, encoding,
            )
            .and_then(|r| {
                Ok(horizon_server::outln!(
                    "{}",
                    serde_json::to_string_pretty(&r)?
                )?)
            })
        }
        Command::BenchService {
            world,
            horizon,
            models,
            placements,
            sustain_seconds,
            sustain_rate,
            rate,
            load_seconds,
            out,
            seed,
            server_log,
        } => horizon_binary(horizon).and_then(|horizon| {
            bench_service::run(&bench_service::Args {
                world,
                horizon,
                models,
                placements,
                sustain_seconds,
                sustain_rate,
                rate,
                load_seconds,
                out,
                seed,
                server_log,
            })
        }),
        Command::Calibrate {
            out,
            assets,
            ssim,
            seeds,
            pairs,
        } => calibrate::calibrate(&assets, &out, ssim, seeds, pairs.as_deref()),
        Command::Distance {
            a,
            b,
            samples,
            json,
        } => distance::run(&a, &b, samples, json),
    };
    horizon_server::terminal::finish("horizon-lab", result)
}
