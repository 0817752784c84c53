//! Integration tests of the command line crate (one binary; the Python suites in `tests/` drive
//! the built `petzval` binary as a user would).

mod fuzz;

use clap::CommandFactory;

#[test]
fn clap_definitions_are_consistent() {
    // clap checks its definitions only in debug builds, when a command line is parsed; this checks
    // them all, in any build (conflicting names, bad defaults, …)
    petzval::Cli::command().debug_assert();
}
