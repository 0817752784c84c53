//! `petzval`: render scenes through real camera lenses (the command line; `main.rs` only parses
//! and runs it).
//!
//! Data flows one way: lens file → lens → camera; scene → integrator → film → EXR/PNG.

use clap::{Parser, Subcommand};

pub mod bench;
#[doc(hidden)]
pub mod fuzzing;
pub mod lens_cmd;
pub mod lrtf_cmd;
pub mod render_cmd;
pub mod signals;
pub mod usd_cmd;

/// Command line.
#[derive(Parser)]
#[command(name = "petzval", version, about = "Render scenes through real camera lenses")]
pub struct Cli {
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Subcommand)]
pub enum Command {
    /// Lens library, analysis, drawing and tracing.
    Lens {
        #[command(subcommand)]
        command: lens_cmd::LensCommand,
    },
    /// Lens ray transfer tables: bake and inspect.
    Lrtf {
        #[command(subcommand)]
        command: lrtf_cmd::LrtfCommand,
    },
    /// Render a glTF or USD scene (or the built-in demo) through a lens to EXR and PNG.
    Render(Box<render_cmd::RenderArgs>),
    /// USD shots: what a shot loads as, and writing a lens onto a camera.
    Usd {
        #[command(subcommand)]
        command: usd_cmd::UsdCommand,
    },
    /// Benchmarks (print tables; see docs/performance.md).
    Bench {
        #[command(subcommand)]
        command: bench::BenchCommand,
    },
}

/// Runs a parsed command line.
pub fn run(command: Command) -> Result<(), Box<dyn std::error::Error>> {
    match command {
        Command::Lens { command } => lens_cmd::run(command).map_err(Into::into),
        Command::Render(args) => render_cmd::run(*args).map_err(Into::into),
        Command::Lrtf { command } => lrtf_cmd::run(command).map_err(Into::into),
        Command::Usd { command } => usd_cmd::run(command).map_err(Into::into),
        Command::Bench { command } => bench::run(command).map_err(Into::into),
    }
}
