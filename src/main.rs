//! `petzval`: render scenes through real camera lenses (the command line is `petzval::Cli`).

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    // Behave like other command-line tools when the reader of stdout goes away
    // (`petzval lens info X | head`): end quietly instead of panicking on a broken pipe.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Interrupts are handled from the start (a Ctrl-C while the scene loads ends cleanly).
    petzval::signals::install();
    let cli = petzval::Cli::parse();
    match petzval::run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
