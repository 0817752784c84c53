//! Synthetic recovery: captures rendered by our own tracer (a denser ray pattern than the fit
//! uses, photon noise and a dark level) from a library lens with a known perturbation; the fit
//! starts from the unperturbed lens and must find the perturbation.

use glam::DVec2;
use petzval_fit::fit::{FitOptions, Problem};
use petzval_fit::forward::{disc_pattern, land, splat, Aim, Frame, Geometry};
use petzval_fit::manifest::DistancesFrom;
use petzval_fit::{solve, CameraParams, Manifest, Model, SensorSpec};
use std::path::Path;

/// A deterministic Poisson-ish photon count (normal approximation, Box–Muller on SplitMix).
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn photons(&mut self, mean: f64) -> f64 {
        let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
        let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        (mean + g * mean.max(0.0).sqrt()).max(0.0)
    }
}

struct Shot {
    source_m: [f64; 3],
    focus_m: f64,
    f_number: f64,
}

/// Renders the captures of `truth` into `dir` and writes a manifest fitting `free` from the
/// library lens.
fn write_captures(dir: &Path, truth: &Model, shots: &[Shot], free: &str, size: usize) -> std::path::PathBuf {
    let sensor = SensorSpec { width_mm: 36.0, height_mm: 24.0, pixels: [6000, 4000] };
    let lens = petzval_optics::Lens::new(
        truth.prescription.clone(),
        &petzval_optics::prescription::SourceMap::new("truth", vec![]),
        None,
    )
    .unwrap();
    let pattern = disc_pattern(120_000);
    let mut manifest = String::from(
        "[lens]\nstart = \"double-gauss-50mm\"\n\n[sensor]\nwidth_mm = 36.0\nheight_mm = 24.0\npixels = [6000, 4000]\n\n",
    );
    manifest.push_str(free);
    let mut noise = Noise(7);
    for (i, s) in shots.iter().enumerate() {
        let l = lens.stopped_down(s.f_number).unwrap();
        let g = Geometry::new(&l, &truth.camera, s.source_m, s.focus_m, DistancesFrom::Sensor).unwrap();
        let aim = Aim::find(&l, g.source_mm, 550.0).unwrap();
        // where the spot lands on the full sensor: crop around it
        let full = Frame { sensor, crop_origin_px: [0, 0], width: 1, height: 1 };
        let landing = land(&l, &truth.camera, &g, &aim, &pattern, 550.0, &full);
        let w: f64 = landing.weights.iter().sum();
        let c = landing.positions_px.iter().zip(&landing.weights).fold(DVec2::ZERO, |a, (p, wt)| a + *p * *wt) / w;
        let origin = [(c.x - size as f64 / 2.0).round() as i64 + 1, (c.y - size as f64 / 2.0).round() as i64 - 1];
        let frame = Frame { sensor, crop_origin_px: origin, width: size, height: size };
        let landing = land(&l, &truth.camera, &g, &aim, &pattern, 550.0, &frame);
        let img = splat(&landing, DVec2::ZERO, 0.0, size, size);
        let peak = img.iter().copied().fold(0.0, f64::max);
        let dark = 100.0;
        let values: Vec<f32> = img.iter().map(|v| noise.photons(dark + 20_000.0 * v / peak) as f32).collect();
        let name = format!("c{:02}.exr", i + 1);
        exr::prelude::write_rgb_file(dir.join(&name), size, size, |x, y| {
            let v = values[y * size + x];
            (v, v, v)
        })
        .unwrap();
        manifest.push_str(&format!(
            "[[capture]]\nimage = \"{name}\"\ncrop_origin_px = [{}, {}]\nsource_m = [{}, {}, {}]\nfocus_m = {}\nf_number = {}\nwavelength_nm = 550\n\n",
            origin[0], origin[1], s.source_m[0], s.source_m[1], s.source_m[2], s.focus_m, s.f_number
        ));
    }
    let path = dir.join("manifest.toml");
    std::fs::write(&path, manifest).unwrap();
    path
}

#[test]
fn recovers_a_radius_a_sensor_tilt_and_offset() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-recovery-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nominal = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model { prescription: nominal.prescription().clone(), camera: CameraParams::default() };
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
    let options = FitOptions { time_limit_s: 25.0, rays: 32_768, ..Default::default() };
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

/// The command line's contract: `-o`, `--report` (fit.json with `params`, `captures`,
/// `seconds`), the fitted lens loads, and `--evaluate` fits only the nuisance of other captures
/// through the earlier fit.
#[test]
fn the_command_line_fits_reports_and_evaluates() {
    let dir = std::env::temp_dir().join(format!("petzval-fit-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nominal = petzval_optics::library_lens("double-gauss-50mm").unwrap();
    let mut truth = Model { prescription: nominal.prescription().clone(), camera: CameraParams::default() };
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
        .args(["--time-limit", "6", "--rays", "8192"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let fit: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("fit.json")).unwrap()).unwrap();
    let offset = fit["params"]["sensor.offset_mm"]["value"].as_f64().unwrap();
    assert!((offset - 0.04).abs() < 0.01, "offset {offset}");
    assert!(fit["params"]["sensor.offset_mm"]["sigma"].as_f64().is_some());
    assert_eq!(fit["captures"].as_array().unwrap().len(), 2);
    assert!(fit["captures"][0]["residual"].as_f64().unwrap() < 0.05);
    assert!(fit["seconds"].as_f64().unwrap() > 0.0);
    assert!(report.join("01-c01.png").is_file() && report.join("convergence.svg").is_file());
    // the fitted lens is our format and loads
    let fitted = petzval_optics::load_lens_file(&lens_out).unwrap();
    assert_eq!(fitted.surfaces().len(), nominal.surfaces().len());
    // other captures through the earlier fit
    let report2 = dir.join("report2");
    let out = std::process::Command::new(bin)
        .args([other.to_str().unwrap(), "--evaluate", report.to_str().unwrap(), "--report", report2.to_str().unwrap()])
        .args(["--time-limit", "4", "--rays", "8192"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report2.join("fit.json")).unwrap()).unwrap();
    assert_eq!(eval["params"]["sensor.offset_mm"]["value"].as_f64().unwrap(), offset.clamp(-0.2, 0.2));
    let r = eval["captures"][0]["residual"].as_f64().unwrap();
    assert!(r < 0.05, "held-out capture residual {r}");
    println!("fit: offset {offset}; held-out residual {r}\n{stdout}");
    std::fs::remove_dir_all(&dir).ok();
}
