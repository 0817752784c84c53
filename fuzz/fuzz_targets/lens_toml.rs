//! cargo-fuzz target `lens_toml`: our TOML lens format.
//! Calls `petzval_renderer::fuzzing::lens_toml`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_renderer::fuzzing::lens_toml(data) {
        panic!("{bug}");
    }
});
