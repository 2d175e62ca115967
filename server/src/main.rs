//! The `horizon` binary: the product's command-line tools over `horizon-world`.
//!
//! # Layout
//! - `main.rs`: argument parsing and dispatch; every failure becomes one line on stderr and
//!   exit status 1 (2 for usage errors, from clap); a closed stdout ends a command quietly.
//! - `mesh_cmd.rs`: `horizon mesh stats` and `convert`.
//! - `simplify_cmd.rs`: `horizon simplify`.
//! - `descriptors_cmd.rs`: `horizon descriptors`.
//! - `world_cmd.rs`: `horizon build` and `cut`, over a world directory.
//! - `serve_cmd.rs`: `horizon serve`, `token create` and `demo` (the village, served).
//!
//! Workloads, benchmarks and research tools are in `horizon-lab` (the `lab/` crate).

mod descriptors_cmd;
mod mesh_cmd;
mod serve_cmd;
mod simplify_cmd;
mod world_cmd;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use horizon_aggregate::AggregateOptions;
use horizon_bvh::{DEFAULT_MAX_RESULTS, DEFAULT_MIN_SOLID_ANGLE, DEFAULT_MU, DEFAULT_W};

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
    /// Builds a world directory: the models' descriptors (cached in descriptors.json), the
    /// BVH (its snapshot bvh.json) and every node's aggregate (aggregates/).
    Build {
        /// The world directory (from `horizon-lab gen world`).
        dir: PathBuf,
        /// Eq. 1's mu: similarity against volume, in [0, 1].
        #[arg(long, default_value_t = DEFAULT_MU)]
        mu: f32,
        /// Eq. 1's w: texture against shape, in [0, 1].
        #[arg(long, default_value_t = DEFAULT_W)]
        omega: f32,
        /// Worker threads (default: every core).
        #[arg(long)]
        jobs: Option<usize>,
        /// Build the BVH only, no aggregates.
        #[arg(long)]
        bvh_only: bool,
        /// Screen pixels per aggregate triangle at its nearest display distance.
        #[arg(long, default_value_t = AggregateOptions::default().pixels_per_triangle)]
        pixels_per_triangle: f64,
        /// The smallest solid angle clients ask to see as itself (sets aggregate budgets).
        #[arg(long, default_value_t = DEFAULT_MIN_SOLID_ANGLE)]
        min_solid_angle: f64,
        /// When aggregates get one atlas texture: always, auto (the paper's rule: more than
        /// 100 textures or 64 MB of them in the world) or never.
        #[arg(long, value_enum, default_value = "always")]
        atlas: AtlasArg,
        /// Which nodes get orthoview impostors.
        #[arg(long, value_enum, default_value = "where-paying")]
        impostors: ImpostorArg,
        /// Print the summary as JSON.
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
        #[arg(long, default_value_t = DEFAULT_MAX_RESULTS)]
        max_results: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// List the object ids each entry covers.
        #[arg(long)]
        explain: bool,
    },
    /// Serves a world: model uploads, objects, assets and the live rebuild over HTTP. Prints
    /// `listening on http://ADDR` first; stops on SIGTERM or Ctrl-C.
    Serve {
        /// The world directory (a missing or empty one starts an empty world).
        dir: PathBuf,
        /// Address to listen on (port 0: any free port).
        #[arg(long, default_value = "127.0.0.1:8080")]
        listen: SocketAddr,
        /// Which nodes the live rebuild gives orthoview impostors.
        #[arg(long, value_enum, default_value = "where-paying")]
        impostors: ImpostorArg,
    },
    /// Bearer tokens for writing to a world.
    #[command(subcommand)]
    Token(TokenCommand),
    /// Serves the village: generated and built into the data folder on first run.
    Demo {
        /// The data folder.
        #[arg(long, default_value = "horizon-demo")]
        data: PathBuf,
        /// Address to listen on (port 0: any free port).
        #[arg(long, default_value = "127.0.0.1:8080")]
        listen: SocketAddr,
    },
}

#[derive(Debug, Subcommand)]
enum TokenCommand {
    /// Creates a random 256-bit token for a user (adding the user, or setting their quotas)
    /// and prints it once; only its hash is stored. Works while a server runs on the world.
    Create {
        /// The world directory.
        dir: PathBuf,
        /// The user the token writes as.
        #[arg(long)]
        user: String,
        /// Most objects the user may own at once.
        #[arg(long)]
        max_objects: Option<u64>,
        /// Most bytes of models the user may upload.
        #[arg(long)]
        max_bytes: Option<u64>,
        /// Print {"token", "user"} as JSON.
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

/// `--impostors` of `horizon build` and `horizon serve`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum ImpostorArg {
    /// Nodes whose impostor costs less to serve than their aggregate.
    WherePaying,
    /// Every node.
    Everywhere,
    /// None.
    Off,
}

impl From<ImpostorArg> for horizon_aggregate::ImpostorPolicy {
    fn from(a: ImpostorArg) -> Self {
        match a {
            ImpostorArg::WherePaying => Self::WherePaying,
            ImpostorArg::Everywhere => Self::Everywhere,
            ImpostorArg::Off => Self::Off,
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
        Command::Descriptors { file, solid, json } => {
            descriptors_cmd::describe_file(&file, solid, json)
        }
        Command::Build {
            dir,
            mu,
            omega,
            jobs,
            bvh_only,
            pixels_per_triangle,
            min_solid_angle,
            atlas,
            impostors,
            json,
        } => set_jobs(jobs).and_then(|()| {
            let options = (!bvh_only).then_some(AggregateOptions {
                pixels_per_triangle,
                min_solid_angle,
                atlas: atlas.into(),
                ..AggregateOptions::default()
            });
            world_cmd::build(&dir, mu, omega, options, impostors.into(), json)
        }),
        Command::Cut {
            dir,
            pos,
            min_solid_angle,
            max_results,
            json,
            explain,
        } => world_cmd::cut(&dir, &pos, min_solid_angle, max_results, json, explain),
        Command::Serve {
            dir,
            listen,
            impostors,
        } => serve_cmd::serve(&dir, listen, impostors.into()),
        Command::Token(TokenCommand::Create {
            dir,
            user,
            max_objects,
            max_bytes,
            json,
        }) => serve_cmd::create_token(&dir, &user, max_objects, max_bytes, json),
        Command::Demo { data, listen } => serve_cmd::demo(&data, listen),
    };
    horizon_server::terminal::finish("horizon", result)
}
