//! cargo-fuzz target `lrtf`: LRTF tables of double-gauss-50mm (checksum repaired, then lookups).
//! Calls `petzval_renderer::fuzzing::lrtf`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_renderer::fuzzing::lrtf(data) {
        panic!("{bug}");
    }
});
