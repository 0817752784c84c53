//! Synthetic recovery: captures rendered by our own tracer (a denser ray pattern than the fit
//! uses, photon noise and a dark level) from a library lens with a known perturbation; the fit
//! starts from the unperturbed lens and must find the perturbation.

use petzval_fit::fit::{FitOptions, Problem};
use petzval_fit::synth::{self, Shot, SynthOptions};
use petzval_fit::{solve, Manifest, Model};
use std::path::Path;

/// Renders `truth`'s captures into `dir` (the shared synthetic renderer, its defaults: 120 000
/// rays, 20 000-photon peaks, dark level 100) and writes a manifest fitting `free` from the
/// library lens.
fn write_captures(dir: &Path, truth: &Model, shots: &[Shot], free: &str, size: usize) -> std::path::PathBuf {
    synth::write_captures(dir, "double-gauss-50mm", truth, shots, free, size, &SynthOptions::default()).unwrap()
}

#[test]
fn recovers_a_radius_a_sensor_tilt_and_offset() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-recovery-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nominal = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model::new(nominal.prescription().clone());
    let r3: petzval_fit::Param = "surface.3.radius_mm".parse().unwrap();
    let r3_nominal = truth.get(&r3).unwrap();
    truth.set(&r3, r3_nominal * 1.03).unwrap();
    truth.camera.sensor_tilt_x_deg = 0.4;
    truth.camera.sensor_offset_mm = 0.05;
    let mut shots = Vec::new();
    for (x, y) in [(0.0, 0.0), (0.25, 0.0), (-0.25, 0.0), (0.0, 0.17), (0.0, -0.17), (0.2, 0.12), (-0.2, -0.12)] {
        shots.push(Shot { source_m: [x, y, 2.0], focus_m: 2.0, f_number: 2.8 });
    }
    shots.push(Shot { source_m: [0.0, 0.0, 1.5], focus_m: 2.0, f_number: 2.8 });
    shots.push(Shot { source_m: [0.2, 0.0, 3.0], focus_m: 2.0, f_number: 4.0 });
    let free = format!(
        "[[free]]\nparam = \"surface.3.radius_mm\"\nmin = {}\nmax = {}\n\n[[free]]\nparam = \"sensor.tilt_x_deg\"\nmin = -1.0\nmax = 1.0\n\n[[free]]\nparam = \"sensor.offset_mm\"\nmin = -0.3\nmax = 0.3\n\n",
        r3_nominal * 0.95,
        r3_nominal * 1.05
    );
    let manifest_path = write_captures(&dir, &truth, &shots, &free, 48);
    let manifest = Manifest::load(&manifest_path).unwrap();
    // an evaluation budget ends the fit (the time limit is only a cap far beyond it), so the
    // end point does not depend on the machine's load
    let options = FitOptions { time_limit_s: 600.0, max_evaluations: 400, ..Default::default() };
    let problem = Problem::new(&manifest, &options).unwrap();
    let result = solve::run(&problem, &options);
    let values: Vec<f64> = result.params.iter().map(|p| p.value).collect();
    let model = problem.model_at(&values).unwrap();
    petzval_fit::report::write_report(&dir.join("report"), &problem, &result, &model).unwrap();
    let get = |n: &str| result.params.iter().find(|p| p.name == n).unwrap().clone();
    let (r, t, o) = (get("surface.3.radius_mm"), get("sensor.tilt_x_deg"), get("sensor.offset_mm"));
    println!(
        "radius {} (truth {}), tilt {} (0.4), offset {} (0.05), residuals {:?}, {:.1} s, {:?}",
        r.value,
        r3_nominal * 1.03,
        t.value,
        o.value,
        result.residuals,
        result.seconds,
        result.evaluations
    );
    assert!((r.value / (r3_nominal * 1.03) - 1.0).abs() < 0.003, "radius {} vs {}", r.value, r3_nominal * 1.03);
    assert!((t.value - 0.4).abs() < 0.05, "tilt {}", t.value);
    assert!((o.value - 0.05).abs() < 0.01, "offset {}", o.value);
    for (c, res) in result.residuals.iter().enumerate() {
        assert!(*res <= 0.02, "capture {c}: residual {res} (target: 2 % of the signal)");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The other perturbations: a decentred element (the front singlet, surface 1, moved
/// 0.15 mm right) and the stop's size (its widest opening 8.0 mm for the nominal 8.55), with
/// the sensor offset. Three captures with the stop fully open (`f_number = "open"`: a defocused
/// disc on and off the axis, whose size and cat's eye show the stop) and six stopped down, in
/// focus across the field (the decentred element's coma and its field-dependent image shift).
/// The fit starts from the nominal lens, centred, with the nominal stop.
#[test]
fn recovers_a_decentred_element_and_the_stop_size() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-recovery-decentre-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nominal = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model::new(nominal.prescription().clone());
    let dx: petzval_fit::Param = "surface.1.decenter_x_mm".parse().unwrap();
    let stop: petzval_fit::Param = "stop.semi_diameter_mm".parse().unwrap();
    truth.set(&dx, 0.15).unwrap();
    truth.set(&stop, 8.0).unwrap();
    truth.camera.sensor_offset_mm = 0.03;
    let mut shots = Vec::new();
    for (x, y) in [(0.0, 0.0), (0.25, 0.0), (-0.25, 0.0), (0.0, 0.17), (0.0, -0.17)] {
        shots.push(Shot { source_m: [x, y, 2.0], focus_m: 2.0, f_number: 2.8 });
    }
    shots.push(Shot { source_m: [0.2, -0.12, 3.0], focus_m: 2.0, f_number: 4.0 });
    shots.push(Shot { source_m: [0.0, 0.0, 1.5], focus_m: 2.0, f_number: 0.0 });
    shots.push(Shot { source_m: [0.2, 0.1, 1.5], focus_m: 2.0, f_number: 0.0 });
    shots.push(Shot { source_m: [-0.25, 0.0, 2.0], focus_m: 2.0, f_number: 0.0 });
    let free = "[[free]]\nparam = \"surface.1.decenter_x_mm\"\nmin = -0.5\nmax = 0.5\n\n\
                [[free]]\nparam = \"surface.1.decenter_y_mm\"\nmin = -0.5\nmax = 0.5\n\n\
                [[free]]\nparam = \"stop.semi_diameter_mm\"\nmin = 7.0\nmax = 9.0\nstart = 8.55\n\n\
                [[free]]\nparam = \"sensor.offset_mm\"\nmin = -0.3\nmax = 0.3\n\n";
    let manifest_path = write_captures(&dir, &truth, &shots, free, 48);
    let manifest = Manifest::load(&manifest_path).unwrap();
    let options = FitOptions { time_limit_s: 600.0, max_evaluations: 400, ..Default::default() };
    let problem = Problem::new(&manifest, &options).unwrap();
    let result = solve::run(&problem, &options);
    let get = |n: &str| result.params.iter().find(|p| p.name == n).unwrap().clone();
    let (x, y, s, o) = (
        get("surface.1.decenter_x_mm"),
        get("surface.1.decenter_y_mm"),
        get("stop.semi_diameter_mm"),
        get("sensor.offset_mm"),
    );
    println!(
        "decentre {} ± {:?} (0.15), {} ± {:?} (0), stop {} ± {:?} (8.0), offset {} (0.03), residuals {:?}, {:.1} s, {:?}",
        x.value,
        x.sigma,
        y.value,
        y.sigma,
        s.value,
        s.sigma,
        o.value,
        result.residuals,
        result.seconds,
        result.evaluations
    );
    assert!((x.value - 0.15).abs() < TOLERANCE_DECENTRE_MM, "decentre x {}", x.value);
    assert!(y.value.abs() < TOLERANCE_DECENTRE_MM, "decentre y {}", y.value);
    assert!((s.value - 8.0).abs() < TOLERANCE_STOP_MM, "stop {}", s.value);
    assert!((o.value - 0.03).abs() < 0.01, "offset {}", o.value);
    for (c, res) in result.residuals.iter().enumerate() {
        assert!(*res <= 0.02, "capture {c}: residual {res} (target: 2 % of the signal)");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Tolerance on a fitted decentre (mm): a tenth of the 0.15 mm perturbation.
const TOLERANCE_DECENTRE_MM: f64 = 0.015;

/// Tolerance on the fitted stop semi-diameter (mm): 0.5 % of it.
const TOLERANCE_STOP_MM: f64 = 0.04;

/// The command line's contract: `-o`, `--report` (fit.json with `params`, `captures`,
/// `seconds`), the fitted lens loads, and `--evaluate` fits only the nuisance of other captures
/// through the earlier fit.
#[test]
fn the_command_line_fits_reports_and_evaluates() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nominal = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model::new(nominal.prescription().clone());
    truth.camera.sensor_offset_mm = 0.04;
    let free = "[[free]]\nparam = \"sensor.offset_mm\"\nmin = -0.2\nmax = 0.2\n\n[[free]]\nparam = \"surface.9.tilt_y_deg\"\nmin = -0.5\nmax = 0.5\n\n";
    let fit_dir = dir.join("fit");
    std::fs::create_dir_all(&fit_dir).unwrap();
    let shots = [
        Shot { source_m: [0.0, 0.0, 2.0], focus_m: 2.0, f_number: 2.8 },
        Shot { source_m: [0.1, 0.05, 1.6], focus_m: 2.0, f_number: 2.8 },
    ];
    let manifest = write_captures(&fit_dir, &truth, &shots, free, 40);
    let other_dir = dir.join("other");
    std::fs::create_dir_all(&other_dir).unwrap();
    let other = write_captures(
        &other_dir,
        &truth,
        &[Shot { source_m: [-0.1, 0.0, 2.5], focus_m: 2.0, f_number: 4.0 }],
        free,
        40,
    );
    let bin = env!("CARGO_BIN_EXE_petzval-fit");
    let lens_out = dir.join("fitted.toml");
    let report = dir.join("report");
    let out = std::process::Command::new(bin)
        .args([manifest.to_str().unwrap(), "-o", lens_out.to_str().unwrap(), "--report", report.to_str().unwrap()])
        .args(["--time-limit", "600", "--max-evaluations", "100", "--rays", "8192"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    // stderr is a pipe here, not a terminal: no progress bar
    assert!(!stderr.contains("evaluations"), "a progress bar on a pipe: {stderr}");
    // bad budgets and start counts are refused, naming the option
    for (flag, value) in [("--max-evaluations", "0"), ("--starts", "0"), ("--starts", "65")] {
        let bad = std::process::Command::new(bin)
            .args([manifest.to_str().unwrap(), "-o", lens_out.to_str().unwrap(), "--report", report.to_str().unwrap()])
            .args([flag, value])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&bad.stderr);
        assert!(!bad.status.success() && err.contains(flag), "{flag} {value}: {err}");
    }
    let fit: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("fit.json")).unwrap()).unwrap();
    let offset = fit["params"]["sensor.offset_mm"]["value"].as_f64().unwrap();
    assert!((offset - 0.04).abs() < 0.01, "offset {offset}");
    assert!(fit["params"]["sensor.offset_mm"]["sigma"].as_f64().is_some());
    assert_eq!(fit["captures"].as_array().unwrap().len(), 2);
    assert!(fit["captures"][0]["residual"].as_f64().unwrap() < 0.05);
    // captures the model explains raise no warning (a second source in a capture does)
    assert_eq!(fit["warnings"].as_array().map(Vec::len), Some(0), "{}", fit["warnings"]);
    assert!(fit["seconds"].as_f64().unwrap() > 0.0);
    assert!(report.join("01-c01.png").is_file() && report.join("convergence.svg").is_file());
    // the fitted lens is our format and loads
    let fitted = petzval_optics::load_lens_file(&lens_out).unwrap();
    assert_eq!(fitted.surfaces().len(), nominal.surfaces().len());
    // other captures through the earlier fit
    let report2 = dir.join("report2");
    let out = std::process::Command::new(bin)
        .args([other.to_str().unwrap(), "--evaluate", report.to_str().unwrap(), "--report", report2.to_str().unwrap()])
        .args(["--time-limit", "600", "--max-evaluations", "40", "--rays", "8192"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report2.join("fit.json")).unwrap()).unwrap();
    assert_eq!(eval["params"]["sensor.offset_mm"]["value"].as_f64().unwrap(), offset.clamp(-0.2, 0.2));
    let r = eval["captures"][0]["residual"].as_f64().unwrap();
    assert!(r < 0.05, "held-out capture residual {r}");
    println!("fit: offset {offset}; held-out residual {r}\n{stdout}");
    // Evaluating through a fit whose parameters this manifest does not list is refused (it
    // used the start lens's values for them in silence).
    let bare_dir = dir.join("bare");
    std::fs::create_dir_all(&bare_dir).unwrap();
    let bare = write_captures(&bare_dir, &truth, &shots[..1], "", 40);
    let out = std::process::Command::new(bin)
        .args([
            bare.to_str().unwrap(),
            "--evaluate",
            report.to_str().unwrap(),
            "--report",
            dir.join("r3").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("free") && err.contains("sensor.offset_mm"), "{err}");
    // Where the results go is checked before the fit: a report path that is a file, an output
    // folder that does not exist; nothing is written.
    let a_file = dir.join("a-file");
    std::fs::write(&a_file, "x").unwrap();
    let nowhere = dir.join("no-such-folder").join("f.toml");
    for (out_lens, rep, words) in
        [(lens_out.clone(), a_file.clone(), "not a folder"), (nowhere.clone(), dir.join("r4"), "does not exist")]
    {
        let t0 = std::time::Instant::now();
        let out = std::process::Command::new(bin)
            .args([manifest.to_str().unwrap(), "-o", out_lens.to_str().unwrap(), "--report", rep.to_str().unwrap()])
            .args(["--time-limit", "600", "--max-evaluations", "100", "--rays", "8192"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(words), "{err}");
        assert!(t0.elapsed().as_secs_f64() < 5.0, "checked only after fitting: {:?}", t0.elapsed());
        assert!(!dir.join("r4").exists(), "a report was written by a failed run");
    }
    std::fs::remove_dir_all(&dir).ok();
}
