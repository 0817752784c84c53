//! cargo-fuzz target `gltf`: glTF scenes, .gltf and .glb (BVH build and rays).
//! Calls `petzval_renderer::fuzzing::gltf`, the entry point the stable run in `tests/run` calls too.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(bug) = petzval_renderer::fuzzing::gltf(data) {
        panic!("{bug}");
    }
});
