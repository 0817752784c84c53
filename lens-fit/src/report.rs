//! The fit's outputs: the fitted lens file, and the report folder (`fit.json`, one PNG per
//! capture with measured | fitted | difference on one scale, `convergence.svg`).
//!
//! `fit.json` keys: `params` (name → `{value, sigma, start, determined}`; `sigma` is null for
//! a parameter the captures cannot determine, and for every parameter of a fit interrupted
//! before its end point had a Jacobian, whose `determined` is then null: unknown), `captures` (list of `{image, residual,
//! shift_px, scale, background, clipped_pixels, hot_pixels}`), `warnings` (captures the
//! fitted model does not explain: a non-positive intensity scale or a residual over 0.5; an
//! interrupted fit; an 8-bit capture read as linear by default; a capture whose spot is one pixel, see `captures`; the command also prints them), `seconds`, `iterations`
//! (objective evaluations per stage; a Jacobian counts one per parameter), `stage_seconds`
//! (wall-clock per stage), `lm_stop` (`{reason, iterations, central_from_iteration}` of Levenberg–Marquardt: the last is the iteration from which its Jacobians were central differences, null for forward differences throughout), `correlations` (`{names, matrix}`), `history`
//! (`[seconds, objective]` after each improvement), `camera` (the fitted camera parameters),
//! `start_lens`, `manifest`.

use crate::error::{Error, Result};
use crate::fit::Problem;
use crate::params::Model;
use crate::solve::FitResult;
use serde_json::{json, Map, Value};
use std::path::Path;

fn io_err(path: &Path, e: std::io::Error) -> Error {
    Error::Io { path: path.to_path_buf(), source: e }
}

/// Writes the fitted lens as our TOML format (atomically).
pub fn write_lens(path: &Path, model: &Model, manifest_file: &str) -> Result<()> {
    let mut p = model.prescription.clone();
    if !p.lens.name.ends_with(" (fitted)") {
        p.lens.name = format!("{} (fitted)", p.lens.name);
    }
    p.lens.notes =
        format!("Fitted by petzval-fit to the captures of {manifest_file}. {}", p.lens.notes).trim().to_string();
    let text = format!("# Written by petzval-fit from {manifest_file}\n{}", petzval_optics::prescription::to_toml(&p));
    petzval_optics::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// Writes `fit.json`, the capture PNGs and the convergence plot into `dir`.
pub fn write_report(dir: &Path, problem: &Problem, result: &FitResult, model: &Model) -> Result<Value> {
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    // An interrupted fit may have computed no uncertainties: whether a parameter is
    // determined is then unknown.
    let interrupted = result.lm_stop.0 == "interrupted";
    let mut params = Map::new();
    for p in &result.params {
        let determined = if result.uncertainties_computed { json!(p.sigma.is_some()) } else { Value::Null };
        params.insert(
            p.name.clone(),
            json!({ "value": p.value, "sigma": p.sigma, "start": p.start, "determined": determined }),
        );
    }
    let landings = problem.landings(model);
    let mut captures = Vec::new();
    // Captures the fitted model does not explain (a second source, a wrong source position or
    // crop): a fit that "succeeds" on them is no fit.
    let mut warnings: Vec<String> = Vec::new();
    if interrupted {
        warnings.push(format!(
            "the fit was interrupted after {:.1} s: these values are its best point so far{}",
            result.seconds,
            if result.uncertainties_computed { "" } else { ", and their uncertainties were not computed" }
        ));
    }
    for (c, prep) in problem.captures.iter().enumerate() {
        let transfer = crate::captures::transfer_warning(&prep.capture, &prep.image);
        for w in transfer.into_iter().chain(crate::captures::undersampled_warning(&prep.capture, &prep.image)) {
            warnings.push(format!("capture {}: {w}", c + 1));
        }
    }
    let mut pngs: Vec<String> = Vec::new();
    for (c, prep) in problem.captures.iter().enumerate() {
        let fit = landings.as_ref().map(|l| problem.fit_capture(c, &l[c], result.shifts_px[c]));
        let image = prep.capture.image.display().to_string();
        let stem =
            prep.capture.image.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or(format!("capture{c}"));
        if let Some(f) = &fit {
            let name = format!("{:02}-{stem}.png", c + 1);
            write_capture_png(&dir.join(&name), prep, &f.model)?;
            pngs.push(name);
        }
        let scale_sum: f64 = fit.as_ref().map_or(1.0, |f| f.scale.iter().sum());
        if !(scale_sum > 0.0) || result.residuals[c] > 0.5 {
            warnings.push(format!(
                "capture {} ({image}): fitted intensity scale {scale_sum:.3e}, residual {:.3}: the model does not explain this capture (a second source, a wrong source position or crop?)",
                c + 1,
                result.residuals[c]
            ));
        }
        captures.push(json!({
            "image": image,
            "residual": result.residuals[c],
            "shift_px": [result.shifts_px[c].x, result.shifts_px[c].y],
            "scale": fit.as_ref().map(|f| f.scale.clone()),
            "background": fit.as_ref().map(|f| f.background.clone()),
            "clipped_pixels": prep.image.clipped,
            "hot_pixels": prep.image.hot,
        }));
    }
    let iterations: Map<String, Value> = result.evaluations.iter().map(|(k, v)| (k.clone(), json!(v))).collect();
    let stage_seconds: Map<String, Value> = result.stage_seconds.iter().map(|(k, v)| (k.clone(), json!(v))).collect();
    let report = json!({
        "manifest": problem.file,
        "start_lens": problem.source_label,
        "params": params,
        "camera": {
            "sensor_tilt_x_deg": model.camera.sensor_tilt_x_deg,
            "sensor_tilt_y_deg": model.camera.sensor_tilt_y_deg,
            "sensor_offset_mm": model.camera.sensor_offset_mm,
            "focus_scale": model.camera.focus_scale,
        },
        "correlations": { "names": result.params.iter().map(|p| p.name.clone()).collect::<Vec<_>>(), "matrix": result.correlations },
        "captures": captures,
        "warnings": warnings,
        "seconds": result.seconds,
        "iterations": iterations,
        "stage_seconds": stage_seconds,
        "lm_stop": {
            "reason": result.lm_stop.0,
            "iterations": result.lm_stop.1,
            "central_from_iteration": result.lm_central_from,
        },
        "history": result.history,
    });
    let text = serde_json::to_string_pretty(&report).unwrap_or_default();
    petzval_optics::write_atomic(&dir.join("fit.json"), text.as_bytes())?;
    write_convergence_svg(&dir.join("convergence.svg"), &result.history)?;
    remove_stale_capture_pngs(dir, &pngs);
    Ok(report)
}

/// Removes the capture PNGs (`NN-name.png`) an earlier fit left in a reused report folder that
/// this fit did not write, so the folder shows this fit alone. Other files are left alone;
/// a file that cannot be removed stays (it is not an error).
fn remove_stale_capture_pngs(dir: &Path, written: &[String]) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().to_string();
        let b = name.as_bytes();
        let ours =
            b.len() > 7 && b[0].is_ascii_digit() && b[1].is_ascii_digit() && b[2] == b'-' && name.ends_with(".png");
        if ours && !written.contains(&name) && entry.path().is_file() {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// measured | fitted | difference (mean over channels), one scale for the three panels; the
/// difference is drawn about mid-grey.
fn write_capture_png(path: &Path, prep: &crate::fit::Prepared, model: &[Vec<f64>]) -> Result<()> {
    let (w, h) = (prep.image.width, prep.image.height);
    let mean = |planes: &[Vec<f64>], k: usize| planes.iter().map(|p| p[k]).sum::<f64>() / planes.len() as f64;
    let measured: Vec<f64> = (0..w * h).map(|k| mean(&prep.image.channels, k)).collect();
    let fitted: Vec<f64> = (0..w * h).map(|k| mean(model, k)).collect();
    let lo = measured.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = measured.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = (hi - lo).max(1e-300);
    let mut img = image::GrayImage::new((3 * w + 4) as u32, h as u32);
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            let to8 = |v: f64| (255.0 * v).round().clamp(0.0, 255.0) as u8;
            img.put_pixel(x as u32, y as u32, image::Luma([to8((measured[k] - lo) / span)]));
            img.put_pixel((w + 2 + x) as u32, y as u32, image::Luma([to8((fitted[k] - lo) / span)]));
            let d = if prep.image.mask[k] { 0.5 + 0.5 * (measured[k] - fitted[k]) / span } else { 0.0 };
            img.put_pixel((2 * w + 4 + x) as u32, y as u32, image::Luma([to8(d)]));
        }
    }
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .map_err(|e| Error::Image { path: path.into(), message: e.to_string() })?;
    petzval_optics::write_atomic(path, buf.get_ref())?;
    Ok(())
}

/// log₁₀(objective) against seconds.
fn write_convergence_svg(path: &Path, history: &[(f64, f64)]) -> Result<()> {
    let (w, h, m) = (640.0, 360.0, 48.0);
    let pts: Vec<(f64, f64)> = history.iter().filter(|(_, f)| *f > 0.0).map(|(t, f)| (*t, f.log10())).collect();
    let t_max = pts.iter().map(|p| p.0).fold(1e-9, f64::max);
    let (y_min, y_max) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (y_min, y_max) = if y_min.is_finite() && y_max > y_min { (y_min, y_max) } else { (y_min - 1.0, y_min + 1.0) };
    let sx = |t: f64| m + (w - 2.0 * m) * t / t_max;
    let sy = |v: f64| h - m - (h - 2.0 * m) * (v - y_min) / (y_max - y_min);
    let poly: Vec<String> = pts.iter().map(|(t, v)| format!("{:.1},{:.1}", sx(*t), sy(*v))).collect();
    let svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n<polyline fill=\"none\" stroke=\"#1f5fa0\" stroke-width=\"2\" points=\"{}\"/>\n<text x=\"{m}\" y=\"{}\" font-size=\"12\">log10(objective) {y_max:.2} … {y_min:.2} over {t_max:.1} s</text>\n</svg>\n",
        poly.join(" "),
        m - 16.0
    );
    petzval_optics::write_atomic(path, svg.as_bytes())?;
    Ok(())
}
