//! The `horizon` binary: command-line tools over the Horizon crates.
//!
//! # Layout
//! - `main.rs`: argument parsing and dispatch; every failure becomes one line on stderr and
//!   exit status 1 (2 for usage errors, from clap).
//! - `mesh_cmd.rs`: `horizon mesh stats`, `convert` and `distance`.
//! - `gen_cmd.rs`: `horizon gen model`.
//! - `descriptors_cmd.rs`: `horizon descriptors` and `horizon calibrate`.
//! - `simplify_cmd.rs`: `horizon simplify`.
//! - `world_cmd.rs`: `horizon gen world`, `build`, `cut` and `sweep`; `world_store.rs`: the world
//!   directory they read and write.
//! - `bench_cmd.rs`: `horizon bench-bvh`, issue 5's targets measured on a built world.
//! - `demo.rs`: `horizon demo`, the main job on an embedded default model set.

mod aggregate_cmd;
mod bench_cmd;
mod demo;
mod descriptors_cmd;
mod gen_cmd;
mod mesh_cmd;
mod simplify_cmd;
mod world_cmd;
mod world_store;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Horizon: a world server for large user-generated 3D worlds.
#[derive(Debug, Parser)]
#[command(name = "horizon", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Model tools: statistics and conversion.
    #[command(subcommand)]
    Mesh(MeshCommand),
    /// Simplifies a model to a fraction of its expanded triangles and writes it as GLB.
    Simplify {
        /// A .glb, .gltf, .ply, .obj or .stl file.
        input: PathBuf,
        /// The .glb file to write.
        output: PathBuf,
        /// Fraction of the expanded triangles to keep, between 0 and 1.
        #[arg(long)]
        ratio: f64,
        /// ias: instance-aware; qem: the same engine on the expanded mesh; meshopt: the
        /// meshoptimizer baseline.
        #[arg(long, value_enum, default_value = "ias")]
        method: simplify_cmd::Method,
        /// Quantize and meshopt-compress the output geometry.
        #[arg(long)]
        compress: bool,
        /// Print a JSON report instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Prints a model's shape descriptor (3D Zernike, 121 values) and texture descriptor
    /// (Color Structure, 32 bins), and the time they took.
    Descriptors {
        /// A .glb, .gltf, .ply, .obj or .stl file.
        file: PathBuf,
        /// Fill the inside of closed models before computing the shape descriptor.
        #[arg(long)]
        solid: bool,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
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
    /// Seeded procedural workloads.
    #[command(subcommand)]
    Gen(GenCommand),
    /// Builds the BVH of a world directory (descriptors cached in descriptors.json) and
    /// writes its snapshot bvh.json.
    Build {
        /// The world directory (from `horizon gen world`).
        dir: PathBuf,
        /// Eq. 1's mu: similarity against volume, in [0, 1].
        #[arg(long, default_value_t = 0.8)]
        mu: f32,
        /// Eq. 1's w: texture against shape, in [0, 1].
        #[arg(long, default_value_t = 0.2)]
        omega: f32,
        /// Worker threads (default: every core).
        #[arg(long)]
        jobs: Option<usize>,
        /// Build the BVH only, no aggregates.
        #[arg(long)]
        bvh_only: bool,
        /// Screen pixels per aggregate triangle at its nearest display distance.
        #[arg(long, default_value_t = 16.0)]
        pixels_per_triangle: f64,
        /// The smallest solid angle clients ask to see as itself (sets aggregate budgets).
        #[arg(long, default_value_t = 1e-3)]
        min_solid_angle: f64,
        /// When aggregates get one atlas texture: always, auto (the paper's rule: more than
        /// 100 textures or 64 MB of them in the world) or never.
        #[arg(long, value_enum, default_value = "always")]
        atlas: AtlasArg,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
    },
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
        #[arg(long, default_value_t = 1e-3)]
        min_solid_angle: f32,
        /// Most entries in a cut.
        #[arg(long, default_value_t = 4000)]
        max_results: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Cuts a built world for a viewer: every object subtending at least the minimum solid
    /// angle as itself, the rest through exactly one aggregate.
    Cut {
        /// The built world directory.
        dir: PathBuf,
        /// Viewer position X,Y,Z.
        #[arg(long, allow_hyphen_values = true)]
        pos: String,
        /// Smallest solid angle (steradians) shown as itself.
        #[arg(long)]
        min_solid_angle: f32,
        /// Most entries in the cut.
        #[arg(long, default_value_t = 4000)]
        max_results: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// List the object ids each entry covers.
        #[arg(long)]
        explain: bool,
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
        #[arg(long, default_value_t = 0.001)]
        min_solid_angle: f32,
        /// Most entries per cut.
        #[arg(long, default_value_t = 4000)]
        max_results: usize,
        /// Print JSON instead of a markdown table.
        #[arg(long)]
        json: bool,
    },
    /// Measures issue 5's BVH targets on a built world (bulk rebuild, incremental insertion,
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
        #[arg(long, default_value_t = 0.001)]
        min_solid_angle: f32,
        /// Most entries per cut.
        #[arg(long, default_value_t = 4000)]
        max_results: usize,
        /// The markdown report (default: bench/results/bvh_<world name>.md).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print the report as JSON on stdout (the markdown file is still written).
        #[arg(long)]
        json: bool,
    },
    /// Issue 6's build benchmark: a full aggregate build of a built world from scratch
    /// (time, memory), then seeded inserts and the incremental rebuild (what it touched and
    /// how long it took). Writes bench/results/aggregates_<world>.md.
    BenchAggregates {
        /// The built world directory.
        dir: PathBuf,
        /// Objects inserted before the incremental rebuild.
        #[arg(long, default_value_t = 100)]
        insert: usize,
        /// Seed of the inserted objects.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// The markdown report (default: bench/results/aggregates_<world name>.md).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Runs the main job on the embedded default models and writes the results to a folder.
    Demo {
        /// Where to write the demo's output.
        #[arg(long, default_value = "horizon-demo")]
        out: PathBuf,
    },
}

#[derive(Debug, Subcommand)]
enum GenCommand {
    /// Writes a benchmark world (village, island, city or city9) as a world directory.
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

#[derive(Debug, Subcommand)]
enum MeshCommand {
    /// Prints submeshes, instances, triangles (unique and expanded), textures and bounds.
    Stats {
        /// A .glb, .gltf, .ply, .obj or .stl file.
        file: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
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
    /// Imports a model and writes it as GLB.
    Convert {
        /// A .glb, .gltf, .ply, .obj or .stl file.
        input: PathBuf,
        /// The .glb file to write.
        output: PathBuf,
        /// Quantize and meshopt-compress the geometry.
        #[arg(long)]
        compress: bool,
        /// Print a JSON report instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// `--atlas` of `horizon build`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum AtlasArg {
    /// Every aggregate gets one material and one texture.
    Always,
    /// The paper's rule: only worlds with more than 100 textures or 64 MB of them.
    Auto,
    /// Aggregates keep their source materials.
    Never,
}

impl From<AtlasArg> for horizon_aggregate::AtlasPolicy {
    fn from(a: AtlasArg) -> Self {
        match a {
            AtlasArg::Always => Self::Always,
            AtlasArg::Auto => Self::Auto,
            AtlasArg::Never => Self::Never,
        }
    }
}

/// Sizes rayon's global pool (`--jobs`).
fn set_jobs(jobs: Option<usize>) -> anyhow::Result<()> {
    if let Some(n) = jobs {
        if n == 0 {
            anyhow::bail!("--jobs must be at least 1");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| anyhow::anyhow!("cannot start {n} worker threads: {e}"))?;
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Mesh(MeshCommand::Stats { file, json }) => mesh_cmd::stats(&file, json),
        Command::Mesh(MeshCommand::Convert {
            input,
            output,
            compress,
            json,
        }) => mesh_cmd::convert(&input, &output, compress, json),
        Command::Simplify {
            input,
            output,
            ratio,
            method,
            compress,
            json,
        } => simplify_cmd::run(&input, &output, ratio, method, compress, json),
        Command::Mesh(MeshCommand::Distance {
            a,
            b,
            samples,
            json,
        }) => mesh_cmd::distance(&a, &b, samples, json),
        Command::Gen(GenCommand::Model {
            name,
            output,
            seed,
            json,
        }) => gen_cmd::model(&name, &output, seed, json),
        Command::Descriptors { file, solid, json } => {
            descriptors_cmd::describe_file(&file, solid, json)
        }
        Command::Calibrate {
            out,
            assets,
            ssim,
            seeds,
            pairs,
        } => descriptors_cmd::calibrate(&assets, &out, ssim, seeds, pairs.as_deref()),
        Command::Gen(GenCommand::World {
            name,
            dir,
            seed,
            assets,
        }) => world_cmd::gen_world(&name, &dir, seed, assets.as_deref()),
        Command::Build {
            dir,
            mu,
            omega,
            jobs,
            bvh_only,
            pixels_per_triangle,
            min_solid_angle,
            atlas,
            json,
        } => set_jobs(jobs).and_then(|()| {
            let args = (!bvh_only).then_some(aggregate_cmd::AggregateArgs {
                pixels_per_triangle,
                min_solid_angle,
                atlas: atlas.into(),
            });
            world_cmd::build(&dir, mu, omega, args, json)
        }),
        Command::Report {
            dir,
            views,
            seed,
            min_solid_angle,
            max_results,
            json,
        } => aggregate_cmd::report(&dir, views, seed, min_solid_angle, max_results, json),
        Command::Cut {
            dir,
            pos,
            min_solid_angle,
            max_results,
            json,
            explain,
        } => world_cmd::cut(&dir, &pos, min_solid_angle, max_results, json, explain),
        Command::Sweep {
            dirs,
            views,
            seed,
            min_solid_angle,
            max_results,
            json,
        } => world_cmd::sweep(&dirs, views, seed, min_solid_angle, max_results, json),
        Command::BenchBvh {
            dir,
            views,
            seed,
            steps,
            min_solid_angle,
            max_results,
            out,
            json,
        } => bench_cmd::run(&bench_cmd::BenchArgs {
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
        } => aggregate_cmd::bench(&dir, insert, seed, out.as_deref()),
        Command::Demo { out } => demo::run(&out),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line, whatever the chain of causes.
            let message = format!("{e:#}").replace('\n', " ");
            eprintln!("horizon: error: {message}");
            ExitCode::FAILURE
        }
    }
}
