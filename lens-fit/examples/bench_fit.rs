//! Speed benchmark (issue 10): nine synthetic 128 × 128 captures of double-gauss-50mm with two
//! radii perturbed and the sensor tilted and offset, five free parameters, the whole fit timed
//! by stage.
//!
//! ```sh
//! cargo run --release -p petzval-fit --example bench_fit [-- TIME_LIMIT_S [RAYS [MAX_EVALUATIONS [STARTS]]]]
//! ```
//!
//! Environment: `BENCH_SUBSAMPLES` (the pupil grid's points per cell side; 0 = the spiral),
//! `BENCH_FORWARD` (forward differences first, as `--forward-differences`), `BENCH_GLOBAL_RAYS`, `BENCH_LOCAL_RAYS`,
//! `BENCH_SHIFT_STEPS`, `BENCH_GLOBAL_SHARE`, `BENCH_FROM_TRUTH`, and `BENCH_MODEL_ERROR` (print
//! each pupil pattern's model error at the truth against a dense reference, and stop).
//!
//! Prints the cost of one evaluation (all nine captures traced, splatted and fitted), of one
//! Jacobian, the whole fit's wall-clock time with its evaluations per stage, and the values
//! against the truth.

use petzval_fit::fit::{unscale, FitOptions, Problem};
use petzval_fit::synth::{write_captures, Shot, SynthOptions};
use petzval_fit::{solve, Manifest, Model, Param};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let time_limit: f64 = args.first().map(|a| a.parse().expect("TIME_LIMIT_S")).unwrap_or(20.0);
    let rays: usize = args.get(1).map(|a| a.parse().expect("RAYS")).unwrap_or(petzval_fit::forward::DEFAULT_RAYS);
    let max_evaluations: usize = args.get(2).map(|a| a.parse().expect("MAX_EVALUATIONS")).unwrap_or(0);
    let starts: usize = args.get(3).map(|a| a.parse().expect("STARTS")).unwrap_or(FitOptions::default().starts);
    let dir = std::env::temp_dir().join(format!("petzval-fit-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let lens = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model::new(lens.prescription().clone());
    let radii: Vec<(Param, f64)> = ["surface.3.radius_mm", "surface.7.radius_mm"]
        .iter()
        .map(|n| {
            let p: Param = n.parse().unwrap();
            let v = truth.get(&p).unwrap();
            (p, v)
        })
        .collect();
    truth.set(&radii[0].0, radii[0].1 * 1.03).unwrap();
    truth.set(&radii[1].0, radii[1].1 * 0.98).unwrap();
    truth.camera.sensor_tilt_x_deg = 0.4;
    truth.camera.sensor_tilt_y_deg = -0.3;
    truth.camera.sensor_offset_mm = 0.05;
    let mut shots = Vec::new();
    for (x, y) in [(0.0, 0.0), (0.25, 0.0), (-0.25, 0.0), (0.0, 0.17), (0.0, -0.17), (0.2, 0.12), (-0.2, -0.12)] {
        shots.push(Shot { source_m: [x, y, 2.0], focus_m: 2.0, f_number: 2.8 });
    }
    shots.push(Shot { source_m: [0.0, 0.0, 1.5], focus_m: 2.0, f_number: 2.8 });
    shots.push(Shot { source_m: [0.2, 0.0, 3.0], focus_m: 2.0, f_number: 4.0 });
    let free = format!(
        "[[free]]\nparam = \"surface.3.radius_mm\"\nmin = {}\nmax = {}\n\n\
         [[free]]\nparam = \"surface.7.radius_mm\"\nmin = {}\nmax = {}\n\n\
         [[free]]\nparam = \"sensor.tilt_x_deg\"\nmin = -1.0\nmax = 1.0\n\n\
         [[free]]\nparam = \"sensor.tilt_y_deg\"\nmin = -1.0\nmax = 1.0\n\n\
         [[free]]\nparam = \"sensor.offset_mm\"\nmin = -0.3\nmax = 0.3\n\n",
        radii[0].1 * 0.95,
        radii[0].1 * 1.05,
        (radii[1].1 * 0.95).min(radii[1].1 * 1.05),
        (radii[1].1 * 0.95).max(radii[1].1 * 1.05),
    );
    let t = Instant::now();
    let manifest_path =
        write_captures(&dir, "double-gauss-50mm", &truth, &shots, &free, 128, &SynthOptions::default()).unwrap();
    println!("synthesis: 9 captures of 128² px in {:.2} s", t.elapsed().as_secs_f64());
    let manifest = Manifest::load(&manifest_path).unwrap();
    // BENCH_GLOBAL_RAYS, BENCH_LOCAL_RAYS: the stages' ray counts (else the defaults)
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    let options = FitOptions {
        time_limit_s: time_limit,
        rays,
        max_evaluations,
        starts,
        global_rays: env("BENCH_GLOBAL_RAYS"),
        local_rays: env("BENCH_LOCAL_RAYS"),
        shift_steps: std::env::var("BENCH_SHIFT_STEPS").ok().and_then(|v| v.parse().ok()).unwrap_or(2),
        global_share: std::env::var("BENCH_GLOBAL_SHARE").ok().and_then(|v| v.parse().ok()).unwrap_or(0.35),
        central_differences: std::env::var_os("BENCH_FORWARD").is_none(),
        subsamples: std::env::var("BENCH_SUBSAMPLES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(petzval_fit::forward::DEFAULT_SUBSAMPLES),
        ..Default::default()
    };
    println!(
        "rays: global {}, local {}, Levenberg–Marquardt {rays}",
        options.global_rays(),
        if options.local_rays > 0 { options.local_rays } else { rays }
    );
    let t = Instant::now();
    let problem = Problem::new(&manifest, &options).unwrap();
    println!("prepare: {:.2} s", t.elapsed().as_secs_f64());
    // the residual photon noise alone would leave: √(Σ d) / ‖d − median‖ (Poisson, the images
    // are in photons over a dark level of 100)
    let floor: Vec<f64> = problem
        .captures
        .iter()
        .map(|p| {
            let sum: f64 =
                p.image.channels[0].iter().zip(&p.image.mask).filter(|(_, m)| **m).map(|(v, _)| v.max(0.0)).sum();
            (sum.sqrt() / p.norms[0] * 1e4).round() / 1e4
        })
        .collect();
    println!("noise floor of the residuals: {floor:?}");
    let x0 = vec![0.5; problem.free.len()];
    let t = Instant::now();
    let reps = 5;
    let mut f = 0.0;
    for _ in 0..reps {
        f = problem.objective(&x0);
    }
    println!(
        "one evaluation (9 captures, {rays} rays each): {:.1} ms (objective {f:.6})",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    let model = problem.model_at(&unscale(&problem.free, &x0)).unwrap();
    let t = Instant::now();
    let landings = problem.landings(&model).unwrap();
    let trace = t.elapsed().as_secs_f64();
    let shifts = problem.centroid_shifts(&landings);
    let t = Instant::now();
    let r = problem.residual_vector(Some(&landings), &shifts);
    println!(
        "  of which trace {:.1} ms, splat + scale/background {:.1} ms ({} residuals)",
        trace * 1e3,
        t.elapsed().as_secs_f64() * 1e3,
        r.len()
    );
    let truth_values = [radii[0].1 * 1.03, radii[1].1 * 0.98, 0.4, -0.3, 0.05];
    if std::env::var_os("BENCH_MODEL_ERROR").is_some() {
        model_error(&problem, &truth_values);
        return;
    }
    if std::env::var_os("BENCH_FROM_TRUTH").is_some() {
        // the floor: the local stages alone, started at the truth
        let mut p = problem.clone();
        for (f, v) in p.free.clone().iter().zip(truth_values) {
            p.start.set(&f.param, v).unwrap();
        }
        let o = FitOptions { global_share: 0.0, ..options };
        let r = solve::run(&p, &o);
        println!(
            "from the truth: residuals {:?}, values {:?}, {:?}",
            r.residuals.iter().map(|r| (r * 1e4).round() / 1e4).collect::<Vec<_>>(),
            r.params.iter().map(|p| p.value).collect::<Vec<_>>(),
            r.evaluations
        );
    }
    let t = Instant::now();
    let result = solve::run(&problem, &options);
    let total = t.elapsed().as_secs_f64();
    for (p, tv) in result.params.iter().zip(truth_values) {
        println!("{:<24} {:>12.6} (truth {:>10.6}, start {:>10.6}) σ {:?}", p.name, p.value, tv, p.start, p.sigma);
    }
    println!("residuals {:?}", result.residuals.iter().map(|r| (r * 1e4).round() / 1e4).collect::<Vec<_>>());
    println!("evaluations {:?}; Levenberg–Marquardt stopped on {:?}", result.evaluations, result.lm_stop);
    println!(
        "stage seconds {:?}",
        result.stage_seconds.iter().map(|(k, v)| (k.as_str(), (v * 100.0).round() / 100.0)).collect::<Vec<_>>()
    );
    println!(
        "fit: {total:.1} s (time limit {time_limit} s, max evaluations {max_evaluations}, starts {starts}, load {})",
        std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The model's own error at the truth for several pupil patterns: each capture's noise-free
/// model image (unit sum, no shift) against a grid's of 65 536 rays × 8², ‖m − m_ref‖ / ‖m_ref‖, with the
/// time of one landing + splat of all nine captures.
fn model_error(problem: &Problem, truth_values: &[f64]) {
    use petzval_fit::forward::{splat, Pattern};
    let mut model = problem.start.clone();
    for (f, v) in problem.free.iter().zip(truth_values) {
        model.set(&f.param, *v).unwrap();
    }
    let images = |pattern: Pattern| {
        let p = Problem { pattern, ..problem.clone() };
        let t = Instant::now();
        let landings = p.landings(&model).unwrap();
        let imgs: Vec<Vec<f64>> = landings
            .iter()
            .zip(&p.captures)
            .map(|(l, c)| {
                let img = splat(&l[0], glam::DVec2::ZERO, p.footprint_px, c.frame.width, c.frame.height);
                let sum: f64 = img.iter().sum();
                img.into_iter().map(|v| v / sum).collect()
            })
            .collect();
        (imgs, t.elapsed().as_secs_f64(), landings.iter().map(|l| l[0].weights.len()).sum::<usize>())
    };
    let (reference, _, _) = images(Pattern::grid(1 << 16, 8));
    let patterns = [
        ("spiral 1048576", Pattern::spiral(1 << 20)),
        ("spiral 16384", Pattern::spiral(16384)),
        ("spiral 65536", Pattern::spiral(65536)),
        ("grid 4096 × 2²/2²", Pattern::grid_edges(4096, 2, 2)),
        ("grid 4096 × 2²/4²", Pattern::grid_edges(4096, 2, 4)),
        ("grid 4096 × 2²/8²", Pattern::grid_edges(4096, 2, 8)),
        ("grid 4096 × 3²/8²", Pattern::grid_edges(4096, 3, 8)),
        ("grid 4096 × 4²/8²", Pattern::grid_edges(4096, 4, 8)),
        ("grid 2048 × 4²/8²", Pattern::grid_edges(2048, 4, 8)),
        ("grid 2048 × 4²/16²", Pattern::grid_edges(2048, 4, 16)),
        ("grid 8192 × 2²/4²", Pattern::grid_edges(8192, 2, 4)),
        ("grid 8192 × 2²/8²", Pattern::grid_edges(8192, 2, 8)),
        ("grid 16384 × 2²/2²", Pattern::grid_edges(16384, 2, 2)),
    ];
    for (name, pattern) in patterns {
        let (imgs, seconds, points) = images(pattern);
        let errors: Vec<f64> = imgs
            .iter()
            .zip(&reference)
            .map(|(m, r)| {
                let d: f64 = m.iter().zip(r).map(|(a, b)| (a - b) * (a - b)).sum();
                let n: f64 = r.iter().map(|b| b * b).sum();
                (d / n).sqrt() * 100.0
            })
            .collect();
        let worst = errors.iter().copied().fold(0.0, f64::max);
        println!(
            "{name:16} {:6.1} ms, {points:7} points: model error % {:?} (worst {worst:.2})",
            seconds * 1e3,
            errors.iter().map(|e| (e * 100.0).round() / 100.0).collect::<Vec<_>>()
        );
    }
}
