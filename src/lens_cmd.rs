//! `petzval lens ...`: list, info, export, trace and draw.

use clap::{Subcommand, ValueEnum};
use glam::DVec3;
use petzval_renderer::optics::draw;
use petzval_renderer::{load_lens, Error, Lens, Ray, StopMode, TraceDirection, LIBRARY};
use serde_json::{json, Value};
use std::io::{BufRead, Write};
use std::path::PathBuf;

/// Lens subcommands.
#[derive(Subcommand)]
pub enum LensCommand {
    /// List the embedded lens library.
    List,
    /// First-order data (paraxial), pupils, field of view.
    Info {
        /// Library name or lens file (.toml, .dat, .zmx, FILE.json#ID).
        lens: String,
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// Stop down (or open) to this f-number.
        #[arg(long)]
        fstop: Option<f64>,
        /// Focus distance in metres from the entrance pupil (default: infinity).
        #[arg(long)]
        focus: Option<f64>,
        /// Wavelength of the analysis (default: the lens's primary wavelength).
        #[arg(long)]
        wavelength: Option<f64>,
        /// Sensor width × height in mm for the field of view.
        #[arg(long, default_value = "36x24")]
        sensor: String,
    },
    /// The resolved prescription (indices at one wavelength), or our TOML format.
    Export {
        /// Library name or lens file.
        lens: String,
        /// JSON with resolved indices (default: our TOML format).
        #[arg(long)]
        json: bool,
        /// Stop down to this f-number.
        #[arg(long)]
        fstop: Option<f64>,
        /// Wavelength for the indices.
        #[arg(long)]
        wavelength: Option<f64>,
    },
    /// Trace rays read from stdin (`[ox,oy,oz,dx,dy,dz]` per line, mm, lens frame).
    Trace {
        /// Library name or lens file.
        lens: String,
        /// Direction of travel.
        #[arg(long, value_enum, default_value = "scene-to-film")]
        direction: Direction,
        /// Wavelength.
        #[arg(long)]
        wavelength: Option<f64>,
        /// Stop down to this f-number.
        #[arg(long)]
        fstop: Option<f64>,
        /// Ignore the stop opening (only its housing clips).
        #[arg(long)]
        open_stop: bool,
    },
    /// Draw the cross-section with a ray fan for three field angles as SVG.
    Draw {
        /// Library name or lens file.
        lens: String,
        /// Output SVG file.
        #[arg(short, long)]
        output: PathBuf,
        /// Stop down to this f-number.
        #[arg(long)]
        fstop: Option<f64>,
        /// Focus distance in metres (default: infinity).
        #[arg(long)]
        focus: Option<f64>,
    },
}

/// Ray direction for `trace`.
#[derive(Clone, Copy, ValueEnum)]
pub enum Direction {
    /// Scene (front) to film (back).
    SceneToFilm,
    /// Film (back) to scene (front).
    FilmToScene,
}

/// Loads a lens and applies `--fstop`.
pub fn open_lens(name: &str, fstop: Option<f64>) -> Result<Lens, Error> {
    let lens = load_lens(name)?;
    match fstop {
        Some(n) => Ok(lens.stopped_down(n)?),
        None => Ok(lens),
    }
}

fn parse_sensor(s: &str) -> Result<(f64, f64), Error> {
    let bad = || Error::Camera { field: "sensor".into(), message: format!("expected WIDTHxHEIGHT in mm, got '{s}'") };
    let (w, h) = s.split_once('x').ok_or_else(bad)?;
    let (w, h): (f64, f64) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
    if !(w > 0.0 && h > 0.0 && w.is_finite() && h.is_finite()) {
        return Err(bad());
    }
    Ok((w, h))
}

/// Runs a lens subcommand.
pub fn run(cmd: LensCommand) -> Result<(), Error> {
    match cmd {
        LensCommand::List => {
            for e in LIBRARY {
                let lens = load_lens(e.name)?;
                let p = lens.paraxial();
                println!(
                    "{:<34} f = {:>7.2} mm  f/{:<5.2} {:>2} surfaces  {}",
                    e.name,
                    p.efl_mm,
                    p.f_number,
                    lens.surfaces().len(),
                    lens.prescription().lens.source.lines().next().unwrap_or("")
                );
            }
            Ok(())
        }
        LensCommand::Info { lens, json, fstop, focus, wavelength, sensor } => {
            check_wavelength(wavelength)?;
            let lens = open_lens(&lens, fstop)?;
            let sensor = parse_sensor(&sensor)?;
            let info = petzval_renderer::optics::info::lens_info(&lens, focus, wavelength, sensor)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&info).unwrap_or_default());
            } else {
                print_info(&info);
            }
            Ok(())
        }
        LensCommand::Export { lens, json, fstop, wavelength } => {
            check_wavelength(wavelength)?;
            let lens = open_lens(&lens, fstop)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&export_json(&lens, wavelength)).unwrap_or_default());
            } else {
                print!("{}", petzval_renderer::optics::prescription::to_toml(lens.prescription()));
            }
            Ok(())
        }
        LensCommand::Trace { lens, direction, wavelength, fstop, open_stop } => {
            check_wavelength(wavelength)?;
            let lens = open_lens(&lens, fstop)?;
            trace_stdin(&lens, direction, wavelength, open_stop)
        }
        LensCommand::Draw { lens, output, fstop, focus } => {
            let lens = open_lens(&lens, fstop)?;
            let image_distance = lens.focus_image_distance_mm(focus.map(|m| m * 1e3))?;
            let svg = draw::section_svg(&lens, lens.last_vertex_z_mm() + image_distance);
            petzval_renderer::write_atomic(&output, svg.as_bytes())?;
            eprintln!("wrote {}", output.display());
            Ok(())
        }
    }
}

fn print_info(v: &Value) {
    let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    println!("{}  ({})", v["name"].as_str().unwrap_or(""), v["file"].as_str().unwrap_or(""));
    println!("  source            {}", v["source"].as_str().unwrap_or(""));
    println!("  wavelength        {:.2} nm", f("wavelength_nm"));
    println!("  EFL               {:.4} mm", f("efl_mm"));
    if (f("efl_x_mm") - f("efl_mm")).abs() > 1e-6 {
        println!(
            "  EFL (x meridian)  {:.4} mm  (anamorphic squeeze {:.3})",
            f("efl_x_mm"),
            f("efl_mm") / f("efl_x_mm")
        );
    }
    println!("  BFL / FFL         {:.4} / {:.4} mm", f("bfl_mm"), f("ffl_mm"));
    println!(
        "  f-number          f/{:.3}  (widest f/{:.3}, working f/{:.3})",
        f("f_number"),
        f("widest_f_number"),
        f("working_f_number")
    );
    println!(
        "  entrance pupil    z = {:.4} mm, diameter {:.4} mm",
        v["entrance_pupil"]["z_mm"].as_f64().unwrap_or(0.0),
        v["entrance_pupil"]["diameter_mm"].as_f64().unwrap_or(0.0)
    );
    println!(
        "  exit pupil        z = {:.4} mm, diameter {:.4} mm",
        v["exit_pupil"]["z_mm"].as_f64().unwrap_or(0.0),
        v["exit_pupil"]["diameter_mm"].as_f64().unwrap_or(0.0)
    );
    println!(
        "  principal planes  H z = {:.4} mm, H' z = {:.4} mm",
        v["principal_planes"]["front_z_mm"].as_f64().unwrap_or(0.0),
        v["principal_planes"]["back_z_mm"].as_f64().unwrap_or(0.0)
    );
    println!("  sensor plane      z = {:.4} mm (image distance {:.4} mm)", f("sensor_z_mm"), f("image_distance_mm"));
    println!(
        "  surfaces          {} (stop: surface {})",
        v["surface_count"],
        v["stop_index"].as_u64().unwrap_or(0) + 1
    );
    println!("  Petzval sum       {:.6} /mm", f("petzval_sum_per_mm"));
    let fov = &v["field_of_view_deg"];
    let angle =
        |k: &str| fov[k].as_f64().map(|a| format!("{a:.2}°")).unwrap_or_else(|| "beyond the image circle".into());
    println!(
        "  field of view     {} h × {} v, {} diagonal (paraxial {:.2}°) on {}×{} mm",
        angle("horizontal"),
        angle("vertical"),
        angle("diagonal"),
        fov["paraxial_diagonal"].as_f64().unwrap_or(0.0),
        v["sensor_mm"][0],
        v["sensor_mm"][1]
    );
    println!("  image circle      radius {:.2} mm, {} across", f("image_circle_radius_mm"), angle("image_circle"));
}

fn export_json(lens: &Lens, wavelength: Option<f64>) -> Value {
    let wl = wavelength.unwrap_or(lens.primary_wavelength_nm());
    let surfaces: Vec<Value> = lens
        .surfaces()
        .iter()
        .enumerate()
        .map(|(i, s)| {
            json!({
                "z_mm": s.z_mm,
                "thickness_mm": s.thickness_mm,
                "radius_mm": if s.shape.curvature_per_mm == 0.0 { 0.0 } else { 1.0 / s.shape.curvature_per_mm },
                "conic": s.shape.conic,
                "aspheric_r2": s.shape.a2,
                "aspheric": s.shape.aspheric,
                "aspheric_odd": s.shape.aspheric_odd,
                "cylinder": s.shape.cylinder.map(|c| format!("{c:?}").to_lowercase()),
                "semi_diameter_mm": if s.is_stop { s.housing_semi_diameter_mm } else { s.semi_diameter_mm },
                "index_before": lens.index_before(i, wl),
                "index_after": lens.index_after(i, wl),
                "is_stop": s.is_stop,
            })
        })
        .collect();
    json!({
        "name": lens.name(),
        "wavelength_nm": wl,
        "stop_index": lens.stop_index(),
        "stop_semi_diameter_mm": lens.stop_semi_diameter_mm(),
        "image_distance_mm": lens.design_back_focus_mm(),
        "surfaces": surfaces,
    })
}

fn trace_stdin(lens: &Lens, direction: Direction, wavelength: Option<f64>, open_stop: bool) -> Result<(), Error> {
    let wl = wavelength.unwrap_or(lens.primary_wavelength_nm());
    let dir = match direction {
        Direction::SceneToFilm => TraceDirection::SceneToFilm,
        Direction::FilmToScene => TraceDirection::FilmToScene,
    };
    let stop = if open_stop { StopMode::Open } else { StopMode::Apply };
    let stdin = std::io::stdin();
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for (n, line) in stdin.lock().lines().enumerate() {
        let line = line.map_err(|e| Error::io("<stdin>", e))?;
        if line.trim().is_empty() {
            continue;
        }
        let v: Vec<f64> = serde_json::from_str(&line)
            .map_err(|e| Error::settings(format!("<stdin>:{}: ray", n + 1), e.to_string()))?;
        if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
            return Err(Error::settings(
                format!("<stdin>:{}: ray", n + 1),
                "expected [ox, oy, oz, dx, dy, dz] with finite numbers",
            ));
        }
        let d = DVec3::new(v[3], v[4], v[5]);
        if d.length() == 0.0 {
            return Err(Error::settings(format!("<stdin>:{}: ray", n + 1), "zero direction"));
        }
        let ray = Ray::new(DVec3::new(v[0], v[1], v[2]), d);
        let result = match lens.trace_detailed(&ray, wl, dir, stop) {
            Ok(t) => json!({
                "ok": true,
                "origin": [t.ray.origin.x, t.ray.origin.y, t.ray.origin.z],
                "direction": [t.ray.direction.x, t.ray.direction.y, t.ray.direction.z],
                "stop_point": [t.stop_point.x, t.stop_point.y],
                "transmission": t.transmission,
            }),
            Err(a) => json!({ "ok": false, "absorbed": format!("{a:?}") }),
        };
        writeln!(out, "{result}").map_err(|e| Error::io("<stdout>", e))?;
    }
    Ok(())
}

/// `--wavelength`: finite and in the visible range the lens format allows (380–780 nm).
fn check_wavelength(w: Option<f64>) -> Result<(), Error> {
    match w {
        Some(w) if !(w.is_finite() && (380.0..=780.0).contains(&w)) => {
            Err(Error::settings("wavelength", format!("{w} nm is outside 380..780 nm")))
        }
        _ => Ok(()),
    }
}
