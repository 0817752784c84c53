//! cargo-fuzz target `cli_flags`: `petzval render`'s flags (the bytes pick real flags and values,
//! then clap and every check before loading). Calls `petzval::fuzzing::cli_flags`, the entry point
//! the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval::fuzzing::cli_flags(data) {
        panic!("{bug}");
    }
});
