//! `petzval`: render scenes through real camera lenses.
//!
//! Data flows one way: lens file → lens → camera; scene → integrator → film → EXR/PNG.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod bench;
mod lens_cmd;
mod lrtf_cmd;
mod render_cmd;
mod signals;
mod usd_cmd;

/// Command line.
#[derive(Parser)]
#[command(name = "petzval", version, about = "Render scenes through real camera lenses")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
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

fn main() -> ExitCode {
    // Behave like other command-line tools when the reader of stdout goes away
    // (`petzval lens info X | head`): end quietly instead of panicking on a broken pipe.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Interrupts are handled from the start (a Ctrl-C while the scene loads ends cleanly).
    signals::install();
    let cli = Cli::parse();
    let result: Result<(), Box<dyn std::error::Error>> = match cli.command {
        Command::Lens { command } => lens_cmd::run(command).map_err(Into::into),
        Command::Render(args) => render_cmd::run(*args).map_err(Into::into),
        Command::Lrtf { command } => lrtf_cmd::run(command).map_err(Into::into),
        Command::Usd { command } => usd_cmd::run(command).map_err(Into::into),
        Command::Bench { command } => bench::run(command).map_err(Into::into),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
