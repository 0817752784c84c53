//! cargo-fuzz target `lens_dat`: pbrt .dat lens tables.
//! Calls `petzval_renderer::fuzzing::lens_dat`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_renderer::fuzzing::lens_dat(data) {
        panic!("{bug}");
    }
});
