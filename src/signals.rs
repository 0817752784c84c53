//! Interrupts (SIGINT, SIGTERM, SIGHUP): one handler, installed when the program starts.
//!
//! | phase | first signal | second signal |
//! |---|---|---|
//! | before the render (loading, building) | ends the program (exit 130), nothing written | — |
//! | rendering | the render stops after its pass and what converged is written (`complete=false`) | ends the program (exit 130); no output has been started, so none is left partial |
//! | writing | the write finishes (temp file, then rename), then the program ends (exit 130) | the same: a write is never cut off |

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU8, Ordering};

/// Where the program is (see the module's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Phase {
    /// Loading and building: nothing to keep.
    Preparing = 0,
    /// Rendering: a signal stops the render, which keeps what converged.
    Rendering = 1,
    /// Writing outputs: signals wait for the write.
    Writing = 2,
}

static PHASE: AtomicU8 = AtomicU8::new(Phase::Preparing as u8);
static SIGNALS: AtomicU32 = AtomicU32::new(0);
static WRITE_INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Installs the handler (SIGINT, SIGTERM and SIGHUP through ctrlc's `termination` feature).
pub fn install() {
    let _ = ctrlc::set_handler(|| {
        let n = SIGNALS.fetch_add(1, Ordering::SeqCst) + 1;
        match PHASE.load(Ordering::SeqCst) {
            0 => {
                eprintln!("\ninterrupted before the render started: nothing written");
                std::process::exit(130);
            }
            1 if n == 1 => eprintln!("\ninterrupted: finishing and writing what has converged (again to quit)"),
            1 => {
                eprintln!("\ninterrupted again: quitting without writing");
                std::process::exit(130);
            }
            _ => {
                WRITE_INTERRUPTED.store(true, Ordering::SeqCst);
                eprintln!("\ninterrupted: finishing the write first");
            }
        }
    });
}

/// Enters a phase.
pub fn enter(phase: Phase) {
    PHASE.store(phase as u8, Ordering::SeqCst);
}

/// Whether a signal has arrived.
pub fn interrupted() -> bool {
    SIGNALS.load(Ordering::SeqCst) > 0
}

/// After the outputs are written: a signal that arrived while writing ends the program now.
pub fn finish_writing() {
    enter(Phase::Preparing);
    if WRITE_INTERRUPTED.load(Ordering::SeqCst) {
        std::process::exit(130);
    }
}
