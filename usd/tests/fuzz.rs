//! Bounded mutation fuzzing of USD stages (issue 12): the seeds of `fuzz/seeds.txt` (.usda and
//! .usdc stages in `tests/data/fuzz/seeds/`, written by its `make_seeds.py` with Pixar's USD)
//! mutated and loaded through `petzval_usd::fuzzing::usd_stage` (stage → scene at two time
//! codes, RenderSettings, camera specs, the renderer's scene checks and BVH) — the function the
//! cargo-fuzz target `usd` calls. `PETZVAL_FUZZ_ITERATIONS` inputs (default 150); kept crash
//! inputs in `tests/data/fuzz/` are regression cases.

use petzval_renderer::fuzzing::{self, Outcome};
use petzval_usd::fuzzing::usd_stage;
use std::path::Path;
use std::time::Duration;

const DEFAULT_ITERATIONS: usize = 150;

/// An input slower than this is a hang.
const TIME_LIMIT: Duration = Duration::from_secs(5);

#[test]
fn usd_stages_never_panic() {
    let files = fuzzing::seed_files("usd");
    assert!(files.len() >= 5, "{files:?}");
    let seeds: Vec<Vec<u8>> = files.iter().map(|p| std::fs::read(p).unwrap()).collect();
    for (p, s) in files.iter().zip(&seeds) {
        assert_eq!(fuzzing::check_case(&usd_stage, s), Ok(Outcome::Loaded), "seed {} does not load", p.display());
    }
    let report = fuzzing::run_campaign(
        "usd",
        fuzzing::iterations(DEFAULT_ITERATIONS),
        fuzzing::time_limit(TIME_LIMIT),
        "usd",
        &mut fuzzing::mutations_of(seeds),
        &usd_stage,
    );
    println!("{report}");
    assert!(report.failures.is_empty(), "{report}\n{:#?}", report.failures);
}

/// Inputs that crashed, kept as regression cases (`tests/data/fuzz/*.usd*`).
#[test]
fn kept_usd_crash_cases_pass() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let p = e.path();
        if !p.is_file() || !petzval_usd::is_usd_path(&p) {
            continue;
        }
        let outcome = fuzzing::check_case(&usd_stage, &std::fs::read(&p).unwrap());
        assert!(outcome.is_ok(), "{}: {outcome:?}", p.display());
    }
}
