//! `petzval bench ...`: benchmarks that print tables (results recorded in docs/performance.md).

use clap::Subcommand;
use petzval_renderer::Error;

/// Benchmark subcommands.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// ns per traced ray for every library lens, and the exit-pupil rejection rate.
    Lens {
        /// Only this lens.
        #[arg(long)]
        lens: Option<String>,
        /// Rays per lens.
        #[arg(long, default_value_t = 200_000)]
        rays: usize,
    },
}

/// Runs a benchmark.
pub fn run(cmd: BenchCommand) -> Result<(), Error> {
    match cmd {
        BenchCommand::Lens { .. } => Err(Error::Optics("not yet".into())),
    }
}
