//! The `horizon` binary: command-line tools over the Horizon crates.
//!
//! # Layout
//! - `main.rs`: argument parsing and dispatch; every failure becomes one line on stderr and
//!   exit status 1 (2 for usage errors, from clap).
//! - `mesh_cmd.rs`: `horizon mesh stats` and `horizon mesh convert`.
//! - `demo.rs`: `horizon demo`, the main job on an embedded default model set.

mod demo;
mod mesh_cmd;

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
    /// Runs the main job on the embedded default models and writes the results to a folder.
    Demo {
        /// Where to write the demo's output.
        #[arg(long, default_value = "horizon-demo")]
        out: PathBuf,
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
