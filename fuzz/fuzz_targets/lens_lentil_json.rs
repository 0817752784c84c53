//! cargo-fuzz target `lens_lentil_json`: lentil JSON lens databases (the first three entries).
//! Calls `petzval_renderer::fuzzing::lens_lentil_json`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_renderer::fuzzing::lens_lentil_json(data) {
        panic!("{bug}");
    }
});
