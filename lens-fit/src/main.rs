//! `petzval-fit`: fit a lens to photographs of point light sources (see `docs/lens-fit.md`).
//!
//! ```text
//! petzval-fit MANIFEST -o FITTED.toml [--lrtf FITTED.lrtf] --report DIR [--time-limit S]
//!             [--max-evaluations N] [--starts K] [--rays N] [--subsamples K] [--central-differences | --forward-differences] [--quiet]
//! petzval-fit MANIFEST --evaluate DIR --report DIR2
//! petzval-fit MANIFEST --check
//! ```
//!
//! Interrupts (SIGINT, SIGTERM, SIGHUP):
//!
//! | phase | first signal | second signal |
//! |---|---|---|
//! | loading and checking | ends the program (exit 130), nothing written | — |
//! | fitting | the fit stops at its next evaluation; its best point so far is written as usual, with `lm_stop.reason` = `interrupted` and a warning in `fit.json` (uncertainties only if its end point already had a Jacobian); exit 130 after the write | ends the program (exit 130); no output has been started |
//! | writing (report, lens, LRTF) | the writes finish (each a temp file, then a rename), then exit 130 | the same |

use clap::Parser;
use petzval_fit::fit::{FitOptions, Problem};
use petzval_fit::{report, solve, Error, Manifest};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU8, Ordering};

/// Where the program is, for the interrupt handler (see the module's table): 0 loading,
/// 1 fitting, 2 writing.
static PHASE: AtomicU8 = AtomicU8::new(0);
/// Signals received.
static SIGNALS: AtomicU32 = AtomicU32::new(0);
/// Set at the first signal while fitting: the fit's stop flag.
static STOP_FIT: AtomicBool = AtomicBool::new(false);

/// Installs the interrupt handler (SIGINT, SIGTERM and SIGHUP through ctrlc's `termination`).
fn install_interrupts() {
    let _ = ctrlc::set_handler(|| {
        let n = SIGNALS.fetch_add(1, Ordering::SeqCst) + 1;
        match PHASE.load(Ordering::SeqCst) {
            0 => {
                eprintln!("\ninterrupted before the fit started: nothing written");
                std::process::exit(130);
            }
            1 if n == 1 => {
                STOP_FIT.store(true, Ordering::SeqCst);
                eprintln!("\ninterrupted: ending the fit and writing its best point so far (again to quit)");
            }
            1 => {
                eprintln!("\ninterrupted again: quitting without writing");
                std::process::exit(130);
            }
            _ => eprintln!("\ninterrupted: finishing the writes first"),
        }
    });
}

/// Fit a Petzval lens to photographs of point light sources.
#[derive(Parser, Debug)]
#[command(name = "petzval-fit", version)]
struct Args {
    /// The capture manifest (TOML).
    manifest: PathBuf,
    /// The fitted lens (our TOML lens format).
    #[arg(short = 'o', long = "output")]
    output: Option<PathBuf>,
    /// Also bake the fitted lens's LRTF table (film → scene) to this file, with the fitted
    /// correction applied when `correction.*` parameters are free (LRTF correction mode).
    #[arg(long)]
    lrtf: Option<PathBuf>,
    /// The report folder (fit.json, a PNG per capture, convergence.svg).
    #[arg(long)]
    report: Option<PathBuf>,
    /// Wall-clock budget of the fit in seconds.
    #[arg(long, default_value_t = 60.0)]
    time_limit: f64,
    /// Bound on the fit's objective evaluations (split over the stages as the time is): with
    /// it, the end point does not depend on the machine's speed (the time limit stays a cap).
    #[arg(long)]
    max_evaluations: Option<usize>,
    /// Local (BOBYQA) starts from the global stage's best mutually distinct points.
    #[arg(long, default_value_t = FitOptions::default().starts)]
    starts: usize,
    /// Traced rays per wavelength per capture (the pupil grid's corners, or the spiral's points).
    #[arg(long, default_value_t = petzval_fit::forward::DEFAULT_RAYS)]
    rays: usize,
    /// Points per pupil-grid cell side, interpolated from the cell's traced corners (twice as
    /// many near a rim; 0: a spiral of `--rays` points, each traced).
    #[arg(long, default_value_t = petzval_fit::forward::DEFAULT_SUBSAMPLES)]
    subsamples: usize,
    /// Levenberg–Marquardt's parameter Jacobian by central differences from the start: the
    /// default (kept so that earlier command lines still run).
    #[arg(long, conflicts_with = "forward_differences")]
    central_differences: bool,
    /// Levenberg–Marquardt's parameter Jacobian by forward differences (half the cost per
    /// iteration) until two steps gain under a tenth of their predicted decrease, then by
    /// central differences.
    #[arg(long)]
    forward_differences: bool,
    /// No progress bar (it is drawn on stderr only when stderr is a terminal).
    #[arg(long, short = 'q')]
    quiet: bool,
    /// Fit nothing but each capture's position, scale and background, through the lens and
    /// camera of an earlier fit's report folder.
    #[arg(long)]
    evaluate: Option<PathBuf>,
    /// Only validate the manifest against its lens and print what would be fitted.
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    install_interrupts();
    match run(&args) {
        Ok(()) if SIGNALS.load(Ordering::SeqCst) > 0 => ExitCode::from(130),
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The fit's progress on stderr: stage, evaluations (of the budget, if any), best objective,
/// elapsed time; hidden with `--quiet` or when stderr is not a terminal.
fn progress_bar(quiet: bool, budget: usize) -> indicatif::ProgressBar {
    use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
    let bar = if budget > 0 { ProgressBar::new(budget as u64) } else { ProgressBar::no_length() };
    if quiet || !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    } else {
        bar.set_draw_target(ProgressDrawTarget::stderr());
    }
    let template = if budget > 0 {
        "{elapsed_precise} [{bar:20}] {pos}/{len} evaluations {msg}"
    } else {
        "{elapsed_precise} {spinner} {pos} evaluations {msg}"
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

fn run(args: &Args) -> petzval_fit::Result<()> {
    let manifest = Manifest::load(&args.manifest)?;
    let file = manifest.file.display().to_string();
    let usage = |m: &str| Error::manifest(&file, "(command line)", m);
    if !(args.time_limit.is_finite() && args.time_limit > 0.0 && args.time_limit <= 86_400.0) {
        return Err(usage("--time-limit must be a number of seconds in (0, 86400]"));
    }
    if !(64..=1 << 22).contains(&args.rays) {
        return Err(usage("--rays must be in 64..=4194304"));
    }
    if args.subsamples > 16 {
        return Err(usage("--subsamples must be in 0..=16"));
    }
    if args.max_evaluations.is_some_and(|n| !(1..=100_000_000).contains(&n)) {
        return Err(usage("--max-evaluations must be in 1..=100000000"));
    }
    if !(1..=64).contains(&args.starts) {
        return Err(usage("--starts must be in 1..=64"));
    }
    let mut options = FitOptions {
        time_limit_s: args.time_limit,
        rays: args.rays,
        subsamples: args.subsamples,
        central_differences: args.central_differences || !args.forward_differences,
        max_evaluations: args.max_evaluations.unwrap_or(0),
        starts: args.starts,
        stop: petzval_fit::fit::StopFlag::new(&STOP_FIT),
        ..Default::default()
    };
    let mut manifest = manifest;
    if let Some(earlier) = &args.evaluate {
        // The earlier fit's values become the start, and nothing but the nuisance is fitted.
        let path = earlier.join("fit.json");
        let text = std::fs::read_to_string(&path).map_err(|e| Error::Io { path: path.clone(), source: e })?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| Error::manifest(path.display().to_string(), "fit.json", e.to_string()))?;
        // Every parameter the earlier fit set must be listed here (its bounds say where it may
        // lie), or evaluating would silently use the start lens's value for it.
        if let Some(params) = v["params"].as_object() {
            let missing: Vec<&String> =
                params.keys().filter(|k| !manifest.free.iter().any(|f| &f.name == *k)).collect();
            if !missing.is_empty() {
                return Err(Error::manifest(
                    &file,
                    "free",
                    format!(
                        "{} fitted {} which this manifest's [[free]] tables do not list; list them (with their bounds) to evaluate through that fit",
                        path.display(),
                        missing.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
        }
        for (i, f) in manifest.free.iter_mut().enumerate() {
            let field = format!("free[{}].param", i + 1);
            let value = v["params"][&f.name]["value"].as_f64().ok_or_else(|| {
                Error::manifest(&file, &field, format!("'{}' has no numeric value in {}", f.name, path.display()))
            })?;
            if !(value >= f.min && value <= f.max) {
                return Err(Error::manifest(
                    &file,
                    &field,
                    format!(
                        "{} = {value} in {} is outside this manifest's bounds [{}, {}]",
                        f.name,
                        path.display(),
                        f.min,
                        f.max
                    ),
                ));
            }
            f.start = Some(value);
        }
        options.global_share = 0.0;
    }
    let problem = Problem::new(&manifest, &options)?;
    println!(
        "{}: {} captures, {} free parameters, start lens {}",
        file,
        problem.captures.len(),
        problem.free.len(),
        problem.source_label
    );
    for (c, p) in problem.captures.iter().enumerate() {
        let transfer = petzval_fit::captures::transfer_warning(&p.capture, &p.image);
        for w in transfer.into_iter().chain(petzval_fit::captures::undersampled_warning(&p.capture, &p.image)) {
            eprintln!("warning: capture {}: {w}", c + 1);
        }
        if p.image.clipped + p.image.hot > 0 {
            println!(
                "capture {} ({}): {} clipped and {} hot pixels masked",
                c + 1,
                p.capture.image.display(),
                p.image.clipped,
                p.image.hot
            );
        }
    }
    if args.check {
        for f in &problem.free {
            println!(
                "free {:<28} start {:>12.6} in [{}, {}]",
                f.name,
                problem.start.get(&f.param).unwrap_or(f64::NAN),
                f.min,
                f.max
            );
        }
        return Ok(());
    }
    let (report_dir, evaluate) = match (&args.report, &args.evaluate) {
        (Some(r), e) => (r.clone(), e.is_some()),
        (None, _) => return Err(usage("--report DIR is required (where fit.json and the images go)")),
    };
    if !evaluate && args.output.is_none() {
        return Err(usage("-o FITTED.toml is required (the fitted lens)"));
    }
    // Where the results go is checked before the fit, not after it.
    if report_dir.exists() && !report_dir.is_dir() {
        return Err(usage(&format!("--report {}: exists and is not a folder", report_dir.display())));
    }
    for out in [args.output.as_ref(), args.lrtf.as_ref()].into_iter().flatten() {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !parent.is_dir() {
            return Err(usage(&format!("{}: the folder {} does not exist", out.display(), parent.display())));
        }
        if out.is_dir() {
            return Err(usage(&format!("{}: is a folder", out.display())));
        }
    }
    let fit_problem = if evaluate {
        let mut p = problem.clone();
        p.start = p
            .model_at(&manifest.free.iter().map(|f| f.start.unwrap_or(f.min)).collect::<Vec<_>>())
            .map_err(|m| usage(&m))?;
        p.free.clear();
        p
    } else {
        problem.clone()
    };
    let bar = progress_bar(args.quiet, options.max_evaluations);
    let update = |p: &solve::Progress| {
        if let Some(b) = p.budget {
            bar.set_length(b as u64);
        }
        bar.set_position(p.evaluations as u64);
        let best = if p.best.is_finite() { format!("{:.3e}", p.best) } else { "–".to_string() };
        bar.set_message(format!("{} best {best}", p.stage));
    };
    PHASE.store(1, Ordering::SeqCst);
    let result = petzval_fit::staged::run_with_progress(&fit_problem, &options, &update);
    // From here on a signal waits for the writes (each a temp file, then a rename).
    PHASE.store(2, Ordering::SeqCst);
    bar.finish_and_clear();
    let values: Vec<f64> = result.params.iter().map(|p| p.value).collect();
    let model = fit_problem.model_at(&values).map_err(|m| usage(&m))?;
    let mut result = result;
    if evaluate {
        // report the earlier fit's parameters as they were
        result.params = manifest
            .free
            .iter()
            .map(|f| solve::ParamResult {
                name: f.name.clone(),
                value: f.start.unwrap_or(f.min),
                sigma: None,
                start: f.start.unwrap_or(f.min),
            })
            .collect();
    }
    let written = report::write_report(&report_dir, &fit_problem, &result, &model)?;
    for w in written["warnings"].as_array().into_iter().flatten().filter_map(|w| w.as_str()) {
        eprintln!("warning: {w}");
    }
    for p in &result.params {
        match p.sigma {
            Some(s) => println!("{:<28} {:>14.6} ± {:.2e}   (start {:.6})", p.name, p.value, s, p.start),
            None if evaluate => println!("{:<28} {:>14.6}   (from the earlier fit)", p.name, p.value),
            None if !result.uncertainties_computed => {
                println!("{:<28} {:>14.6}   (interrupted: no uncertainty; start {:.6})", p.name, p.value, p.start)
            }
            None => {
                println!("{:<28} {:>14.6}   not determined by these captures (start {:.6})", p.name, p.value, p.start)
            }
        }
    }
    for (c, r) in result.residuals.iter().enumerate() {
        println!("capture {:>2}: residual {:.4}", c + 1, r);
    }
    println!("{:.1} s; report in {}", result.seconds, report_dir.display());
    if let Some(out) = &args.output {
        report::write_lens(out, &model, &file)?;
        println!("wrote {}", out.display());
        if let Some(lrtf) = &args.lrtf {
            // baked for the lens as written (its name and hash are what the renderer loads)
            let written = petzval_optics::load_lens_file(out)?;
            fit_problem.bake_lrtf(&written, &model)?.save(lrtf)?;
            println!("wrote {}", lrtf.display());
        }
    }
    Ok(())
}
