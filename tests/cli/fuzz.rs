//! Fuzzing of `petzval render`'s flags (issue 12): random command lines of real flags with
//! values drawn from what each flag takes and from extremes (`petzval::fuzzing::argv_from_bytes`),
//! parsed with the real clap definitions and run through every check before loading
//! (`petzval::fuzzing::check_argv`) — the function the cargo-fuzz target `cli_flags` calls.
//! No input may panic; and a sample of the accepted command lines of the built-in demo is
//! rendered small through the real `petzval render` code (`render_small`): an accepted command
//! line must render, to finite pixels.
//!
//! `PETZVAL_FUZZ_ITERATIONS` inputs (default 3 000), `PETZVAL_FUZZ_SPOT_CHECKS` renders
//! (default 3; then every `PETZVAL_FUZZ_SPOT_STRIDE`th accepted render command line, default
//! 200). Kept inputs (`tests/cli/fuzz/*.argv`,
//! one argument a line) are regression cases.

use petzval::fuzzing::{argv_from_bytes, check_argv, cli_flags, render_small, NotRendered};
use petzval_renderer::fuzzing::{self, bug_if, Bug, Outcome, Verdict};
use std::cell::{Cell, RefCell};
use std::path::{Path, PathBuf};
use std::time::Duration;

const DEFAULT_ITERATIONS: usize = 3_000;

/// An input slower than this is a hang (spot-check renders included).
const TIME_LIMIT: Duration = Duration::from_secs(10);

fn env_or(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Every pixel of the EXR at `path` is finite.
fn finite_exr(path: &Path) -> Result<(), Bug> {
    let img = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0f32; 4]; res.width() * res.height()]),
        |(w, px), pos, (r, g, b, a): (f32, f32, f32, f32)| px[pos.y() * *w + pos.x()] = [r, g, b, a],
    )
    .map_err(|e| Bug(format!("{}: cannot read back: {e}", path.display())))?;
    let px = &img.layer_data.channel_data.pixels.1;
    let bad = px.iter().filter(|p| p.iter().any(|v| !v.is_finite())).count();
    bug_if(bad > 0, || format!("{}: {bad} non-finite pixels", path.display()))
}

#[test]
fn flags_never_panic_and_accepted_ones_render() {
    let out_dir = std::env::temp_dir().join(format!("petzval-fuzz-cli-render-{}", std::process::id()));
    std::fs::create_dir_all(&out_dir).unwrap();
    let (accepted_demo, rendered) = (Cell::new(0usize), Cell::new(0usize));
    let outcomes: RefCell<Vec<String>> = RefCell::new(Vec::new());
    let (budget, stride) = (env_or("PETZVAL_FUZZ_SPOT_CHECKS", 3), env_or("PETZVAL_FUZZ_SPOT_STRIDE", 200).max(1));
    let entry = |data: &[u8]| -> Verdict {
        // the cargo-fuzz target's function; the command line again for the spot check
        let v = cli_flags(data)?;
        let argv = argv_from_bytes(data);
        let demo_render = argv.get(1).is_some_and(|a| a == "render");
        if v == Outcome::Loaded && demo_render {
            let k = accepted_demo.get();
            accepted_demo.set(k + 1);
            if rendered.get() < budget || k % stride == 0 {
                match render_small(&argv, &out_dir) {
                    Ok(exr) => {
                        rendered.set(rendered.get() + 1);
                        finite_exr(&exr)?;
                    }
                    Err(NotRendered::Failed(e)) => {
                        return Err(Bug(format!("accepted, then failed to render: {e}\n  argv: {argv:?}")));
                    }
                    Err(other) => outcomes.borrow_mut().push(format!("{other:?}")),
                }
            }
        }
        Ok(v)
    };
    let mut inputs = |rng: &mut fuzzing::Rng, _i: usize| {
        let n = 2 + rng.below(40);
        rng.bytes(n)
    };
    let report = fuzzing::run_campaign(
        "cli_flags",
        fuzzing::iterations(DEFAULT_ITERATIONS),
        fuzzing::time_limit(TIME_LIMIT),
        "bin",
        &mut inputs,
        &entry,
    );
    println!("{report}");
    println!(
        "cli_flags: {} accepted render command lines, {} rendered small (all finite); not rendered: {:?}",
        accepted_demo.get(),
        rendered.get(),
        outcomes.borrow()
    );
    for f in &report.failures {
        if let Ok(data) = std::fs::read(&f.kept) {
            eprintln!("input {}: argv {:?}", f.index, argv_from_bytes(&data));
        }
    }
    assert!(report.failures.is_empty(), "{report}\n{:#?}", report.failures);
    assert!(report.loaded > 0 && report.refused > 0, "{report}");
    assert!(rendered.get() >= budget.min(1), "no accepted command line was rendered");
    let _ = std::fs::remove_dir_all(&out_dir);
}

#[test]
fn generated_command_lines_reach_every_flag() {
    // the generator is not stuck in a corner: over a few thousand inputs it uses every flag
    let mut rng = fuzzing::Rng(7);
    let mut seen = std::collections::BTreeSet::new();
    for _ in 0..5000 {
        let n = 2 + rng.below(40);
        for a in argv_from_bytes(&rng.bytes(n)) {
            if let Some(flag) = a.strip_prefix("--") {
                seen.insert(flag.split('=').next().unwrap_or("").to_string());
            }
        }
    }
    for flag in ["fstop", "focus", "resolution", "time-limit", "threads", "lens", "aperture", "frames", "environment"] {
        assert!(seen.contains(flag), "--{flag} never generated: {seen:?}");
    }
}

/// Kept command lines (`tests/cli/fuzz/*.argv`, one argument a line, without `petzval`): none
/// panics.
#[test]
fn kept_command_lines_pass() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cli/fuzz");
    let Ok(entries) = std::fs::read_dir(&dir) else { return };
    let mut cases: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    cases.sort();
    for p in cases.iter().filter(|p| p.extension().is_some_and(|e| e == "argv")) {
        let text = std::fs::read_to_string(p).unwrap();
        let mut argv = vec!["petzval".to_string()];
        argv.extend(text.lines().map(str::to_string));
        let outcome = fuzzing::check_case(&|_: &[u8]| check_argv(&argv), &[]);
        assert!(outcome.is_ok(), "{}: {outcome:?}", p.display());
    }
}

/// Replays one kept input: `PETZVAL_FUZZ_CASE=FILE cargo test --release -p petzval --test cli
/// replay -- --ignored --nocapture` prints the command line it makes, what the checks say and,
/// when they accept it, renders it small.
#[test]
#[ignore]
fn replay() {
    let Ok(path) = std::env::var("PETZVAL_FUZZ_CASE") else { return };
    let data = std::fs::read(&path).unwrap();
    let argv = argv_from_bytes(&data);
    println!("argv: {argv:?}");
    let t0 = std::time::Instant::now();
    println!("checks: {:?} ({:.3} s)", fuzzing::check_case(&cli_flags, &data), t0.elapsed().as_secs_f64());
    let out = std::env::temp_dir().join("petzval-fuzz-replay");
    std::fs::create_dir_all(&out).unwrap();
    let t0 = std::time::Instant::now();
    println!("render_small: {:?} ({:.3} s)", render_small(&argv, &out), t0.elapsed().as_secs_f64());
}
