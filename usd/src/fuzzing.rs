//! The USD fuzzing entry point (issue 12), shared by the bounded run in this crate's test binary
//! (`usd/tests/fuzz.rs`) and the cargo-fuzz target `fuzz/fuzz_targets/usd.rs`; the driver and
//! the conventions ([`Outcome`], [`Bug`]) are `petzval_renderer::fuzzing`'s.
//!
//! [`usd_stage`] writes the input as a layer (`.usdc` when it starts with `PXR-USDC`, `.usdz`
//! for a zip, else `.usda`) into a folder holding the seeds' side files (the asset the
//! instancing seed references), loads the shot with the stage → scene walk at its start time and
//! at frame 2, reads its RenderSettings, turns every camera into a camera spec, and hands the
//! scene to the renderer's scene checks (finite values, BVH build, rays).
//!
//! Not part of the crate's API (hidden from its docs).

use petzval_renderer::fuzzing::{bug_if, repo_root, use_scene, Bug, Outcome, Verdict};
use std::path::{Path, PathBuf};

/// The folder of the USD seeds (their side files are copied next to every fuzzed layer).
pub fn seed_dir() -> PathBuf {
    repo_root().join("usd/tests/data/fuzz/seeds")
}

/// A folder of this thread's own for the fuzzed layer, with the seeds' side files in it.
fn case_dir() -> PathBuf {
    thread_local! {
        static DIR: PathBuf = {
            let id = format!("{:?}", std::thread::current().id()).replace(|c: char| !c.is_ascii_alphanumeric(), "");
            let dir = std::env::temp_dir().join(format!("petzval-fuzz-usd-{}-{id}", std::process::id()));
            let _ = std::fs::create_dir_all(&dir);
            if let Ok(entries) = std::fs::read_dir(seed_dir()) {
                for e in entries.flatten() {
                    let _ = std::fs::copy(e.path(), dir.join(e.file_name()));
                }
            }
            dir
        };
    }
    DIR.with(Clone::clone)
}

/// The extension the layer's bytes are read as.
pub fn layer_extension(data: &[u8]) -> &'static str {
    if data.starts_with(b"PXR-USDC") {
        "usdc"
    } else if data.starts_with(b"PK\x03\x04") {
        "usdz"
    } else {
        "usda"
    }
}

/// A USD layer's bytes (see the module docs).
pub fn usd_stage(data: &[u8]) -> Verdict {
    let path = case_dir().join(format!("fuzz-case.{}", layer_extension(data)));
    if let Err(e) = std::fs::write(&path, data) {
        // the machine, not the input: say so loudly rather than count it as a refusal
        return Err(Bug(format!("cannot write the case file {}: {e}", path.display())));
    }
    usd_file(&path)
}

/// A USD shot on disk, loaded and used as `petzval render` would.
pub fn usd_file(path: &Path) -> Verdict {
    let mut loaded_any = false;
    let mut refusal = None;
    for time in [None, Some(2.0)] {
        let shot = match crate::load(path, time) {
            Ok(s) => s,
            Err(e) => {
                refusal.get_or_insert(e.to_string());
                continue;
            }
        };
        loaded_any = true;
        for c in &shot.cameras {
            bug_if(!c.to_world.is_finite(), || format!("camera {}: non-finite transform", c.path))?;
            if let Ok(host) = c.host_camera() {
                if let Ok(spec) = host.camera_spec(64, 48) {
                    let s = spec.sensor;
                    bug_if(!(s.width_mm.is_finite() && s.height_mm.is_finite() && s.shift_mm.is_finite()), || {
                        format!("camera {}: non-finite sensor {s:?}", c.path)
                    })?;
                }
            }
        }
        let _ = shot.info_json(true);
        let _ = crate::render_settings::read(path, time, None);
        if let Err(b) = match use_scene(shot.scene) {
            Ok(Outcome::Refused(m)) => {
                refusal.get_or_insert(m);
                Ok(())
            }
            Ok(Outcome::Loaded) => Ok(()),
            Err(b) => Err(b),
        } {
            return Err(Bug(format!("at time {time:?}: {b}")));
        }
    }
    Ok(if loaded_any { Outcome::Loaded } else { Outcome::Refused(refusal.unwrap_or_default()) })
}
