//! Bounded mutation fuzzing of the renderer's input formats (issue 12): the four lens formats
//! (our TOML, Zemax .zmx, pbrt .dat, lentil JSON), glTF (.gltf and .glb) and LRTF tables. The
//! entry points and the driver are `petzval_renderer::fuzzing`'s, the same functions the
//! cargo-fuzz targets in `fuzz/` call; the seeds are `fuzz/seeds.txt`'s.
//!
//! `PETZVAL_FUZZ_ITERATIONS` sets the inputs per entry point (default 300: a few seconds in
//! release); the long campaign in docs/reliability.md ran 100 000 per entry point. A panic, a
//! hang (an input over the time limit) or a non-finite output fails the run; failing inputs are
//! written to the temp folder's `petzval-fuzz-failures/` and, once fixed, kept as regression
//! cases in `tests/data/fuzz/` (see its README).

use petzval_renderer::fuzzing::{self, Outcome, Report, Verdict};
use petzval_renderer::library_lens;
use petzval_renderer::optics::lrtf::{BakeOptions, LrtfTable};
use std::path::{Path, PathBuf};
use std::time::Duration;

const DEFAULT_ITERATIONS: usize = 300;

/// An input slower than this is a hang (the slowest of the 100 000-input campaign took well
/// under a tenth of it).
const TIME_LIMIT: Duration = Duration::from_secs(5);

fn seeds(target: &str) -> Vec<Vec<u8>> {
    let files = fuzzing::seed_files(target);
    assert!(!files.is_empty(), "no seeds for {target} in fuzz/seeds.txt");
    files.iter().map(|p| std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).collect()
}

fn campaign(name: &str, ext: &str, seeds: Vec<Vec<u8>>, entry: &dyn Fn(&[u8]) -> Verdict) -> Report {
    // every seed loads: a refused seed would make the campaign weak without saying so
    for (i, s) in seeds.iter().enumerate() {
        let outcome = fuzzing::check_case(entry, s);
        assert_eq!(outcome, Ok(Outcome::Loaded), "{name}: seed {i} does not load");
    }
    let count = fuzzing::iterations(DEFAULT_ITERATIONS);
    let report = fuzzing::run_campaign(
        name,
        count,
        fuzzing::time_limit(TIME_LIMIT),
        ext,
        &mut fuzzing::mutations_of(seeds),
        entry,
    );
    println!("{report}");
    assert!(report.failures.is_empty(), "{report}\n{:#?}", report.failures);
    report
}

#[test]
fn lens_toml_never_panics() {
    campaign("lens_toml", "toml", seeds("lens_toml"), &fuzzing::lens_toml);
}

#[test]
fn lens_zmx_never_panics() {
    campaign("lens_zmx", "zmx", seeds("lens_zmx"), &fuzzing::lens_zmx);
}

#[test]
fn lens_dat_never_panics() {
    campaign("lens_dat", "dat", seeds("lens_dat"), &fuzzing::lens_dat);
}

#[test]
fn lentil_json_never_panics() {
    let report = campaign("lens_lentil_json", "json", seeds("lens_lentil_json"), &fuzzing::lens_lentil_json);
    // entries are looked up by the file's own keys: most mutations keep one loadable
    assert!(report.loaded * 10 >= report.inputs, "{report}");
}

#[test]
fn gltf_files_never_panic() {
    campaign("gltf", "gltf", seeds("gltf"), &fuzzing::gltf);
}

/// The LRTF seed: a table of the entry point's lens at resolution 8, baked now (so it always has
/// the current format).
fn lrtf_seed() -> Vec<u8> {
    let lens = library_lens(fuzzing::LRTF_LENS).unwrap();
    let table = LrtfTable::bake(&lens, &BakeOptions { resolution: 8, ..BakeOptions::default() }, &|_| {}).unwrap();
    // one file per call: tests run on several threads of one process, and two of them bake a
    // seed (a name from the process id alone let one remove the other's file before it was read)
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("petzval-fuzz-seed-{}-{call}.lrtf", std::process::id()));
    table.save(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    bytes
}

#[test]
fn lrtf_tables_never_panic() {
    campaign("lrtf", "lrtf", vec![lrtf_seed()], &fuzzing::lrtf);
}

#[test]
fn lrtf_checksum_repair_is_needed_and_works() {
    // without the repair, a one-byte change of the data is refused by the checksum alone
    let seed = lrtf_seed();
    let mut changed = seed.clone();
    let last = changed.len() - 1;
    changed[last] ^= 0x01;
    let lens = library_lens(fuzzing::LRTF_LENS).unwrap();
    let Err(err) = LrtfTable::from_bytes(&changed, &lens, "x.lrtf") else { panic!("a changed byte was accepted") };
    assert!(err.to_string().contains("checksum"), "{err}");
    assert!(LrtfTable::from_bytes(&fuzzing::repair_lrtf_checksum(&changed), &lens, "x.lrtf").is_ok());
    assert_eq!(fuzzing::repair_lrtf_checksum(&seed).len(), seed.len());
}

/// The entry point a kept input belongs to, by its extension.
fn entry_for(path: &Path) -> Option<fn(&[u8]) -> Verdict> {
    Some(match path.extension()?.to_str()? {
        "gltf" | "glb" => fuzzing::gltf,
        "toml" => fuzzing::lens_toml,
        "zmx" => fuzzing::lens_zmx,
        "dat" => fuzzing::lens_dat,
        "json" => fuzzing::lens_lentil_json,
        "lrtf" => fuzzing::lrtf,
        _ => return None,
    })
}

/// Inputs the campaigns found that crashed, kept as regression cases (`tests/data/fuzz/`, by
/// extension): each loads or is refused, without a panic or a non-finite output.
#[test]
fn kept_crash_cases_pass() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut cases: Vec<PathBuf> = std::fs::read_dir(&dir).unwrap().flatten().map(|e| e.path()).collect();
    cases.sort();
    let mut n = 0;
    for p in cases {
        let Some(entry) = entry_for(&p) else { continue };
        n += 1;
        let outcome = fuzzing::check_case(&entry, &std::fs::read(&p).unwrap());
        assert!(outcome.is_ok(), "{}: {outcome:?}", p.display());
    }
    assert!(n >= 2, "{n} cases");
}

/// cargo-fuzz (overflow checks on) found a GLB whose header length is below the header's own
/// 12 bytes: the gltf crate's subtraction underflowed. It is refused before the gltf crate sees it.
#[test]
fn glb_header_length_below_the_header_is_refused() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz/gltf-glb-length-underflow.glb");
    let e = petzval_renderer::scene::gltf::load_gltf(&p).unwrap_err().to_string();
    assert!(e.contains("gltf-glb-length-underflow.glb") && e.contains("below its own 12 bytes"), "{e}");
}
