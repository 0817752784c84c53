//! cargo-fuzz target `lens_zmx`: Zemax .zmx lens files.
//! Calls `petzval_renderer::fuzzing::lens_zmx`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_renderer::fuzzing::lens_zmx(data) {
        panic!("{bug}");
    }
});
