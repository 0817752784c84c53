//! cargo-fuzz target `usd`: USD layers, .usda/.usdc/.usdz (stage → scene, RenderSettings, cameras, BVH).
//! Calls `petzval_usd::fuzzing::usd_stage`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_usd::fuzzing::usd_stage(data) {
        panic!("{bug}");
    }
});
