//! `petzval usd ...`: what a USD shot loads as (`info`), and writing a lens onto a camera
//! (`set-lens`).

use clap::Subcommand;
use std::path::PathBuf;

/// USD subcommands.
#[derive(Subcommand)]
pub enum UsdCommand {
    /// What the shot loads as: meshes, instances, cameras, lights, materials, warnings.
    Info {
        /// The shot (.usd, .usda, .usdc, .usdz).
        shot: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// Time code to read (default: the stage's startTimeCode, else the default values).
        #[arg(long, allow_hyphen_values = true)]
        frame: Option<f64>,
        /// List every instance with its transforms (JSON only; large for big scatters).
        #[arg(long)]
        instances: bool,
        /// Catmull-Clark levels for meshes whose subdivisionScheme is catmullClark; 0: the cage.
        #[arg(long, default_value_t = petzval_usd::subdiv::DEFAULT_LEVEL, value_parser = clap::value_parser!(u32).range(0..=8))]
        subdivision_level: u32,
    },
    /// Write a lens onto a camera as a new layer over the shot (PetzvalLensAPI).
    SetLens {
        /// The shot.
        shot: PathBuf,
        /// Camera prim path.
        #[arg(long)]
        camera: String,
        /// Library name or lens file (e.g. a lens-fit result).
        #[arg(long)]
        lens: String,
        /// The new layer (.usda).
        #[arg(short, long)]
        output: PathBuf,
        /// petzval:lensModel (auto, exact, lrtf, thick, thin, pinhole).
        #[arg(long)]
        lens_model: Option<String>,
        /// petzval:tiltX (degrees).
        #[arg(long, allow_hyphen_values = true)]
        tilt_x: Option<f64>,
        /// petzval:tiltY (degrees).
        #[arg(long, allow_hyphen_values = true)]
        tilt_y: Option<f64>,
        /// petzval:aperture:blades.
        #[arg(long)]
        blades: Option<i32>,
    },
}

/// Runs a `petzval usd` subcommand.
pub fn run(cmd: UsdCommand) -> Result<(), petzval_usd::Error> {
    match cmd {
        UsdCommand::Info { shot, json, frame, instances, subdivision_level } => {
            let s = petzval_usd::load_with(
                &shot,
                &petzval_usd::LoadOptions { time: frame, subdivision_level, ..Default::default() },
            )?;
            if json {
                println!("{}", serde_json::to_string_pretty(&s.info_json(instances)).unwrap_or_default());
                return Ok(());
            }
            println!("{}", s.file);
            println!(
                "  upAxis {}, metersPerUnit {}, time {}",
                if s.units.up_axis_z { "Z" } else { "Y" },
                s.units.meters_per_unit,
                s.time.map(|t| t.to_string()).unwrap_or_else(|| "default".into())
            );
            println!(
                "  {} meshes ({} triangles stored), {} instances ({} triangles instanced), {} materials",
                s.scene.meshes.len(),
                s.scene.meshes.iter().map(|m| m.triangle_count()).sum::<usize>(),
                s.scene.instances.len(),
                s.scene.instanced_triangle_count(),
                s.scene.materials.len()
            );
            let subdivided: Vec<_> = s.info.meshes.iter().filter(|m| m.subdivision_level.is_some()).collect();
            if let Some(level) = subdivided.first().and_then(|m| m.subdivision_level) {
                println!(
                    "  {} subdivision surfaces (catmullClark), refined {level} levels: {} triangles",
                    subdivided.len(),
                    subdivided.iter().map(|m| m.triangles).sum::<usize>()
                );
            }
            for m in &s.info.meshes {
                if let Some(c) = &m.curves {
                    println!(
                        "  curves {}: {} {} ({}), {} curves, {} tessellated ({} rings per span, {} sides): {} triangles{}",
                        m.prim,
                        if c.kind == "linear" { "linear".to_string() } else { format!("cubic {}", c.basis) },
                        c.wrap,
                        if c.widths_authored { "widths" } else { "no widths: 1 unit wide" },
                        c.curves,
                        c.tessellated,
                        c.rings_per_span,
                        c.sides,
                        m.triangles,
                        m.material.as_ref().map(|n| format!(", material {n}")).unwrap_or_default()
                    );
                }
            }
            for c in &s.cameras {
                println!(
                    "  camera {}: {:.2} mm, aperture {:.3} × {:.3} mm, f/{:.2}, focus {}{}",
                    c.path,
                    c.focal_length_mm,
                    c.horizontal_aperture_mm,
                    c.vertical_aperture_mm,
                    c.f_stop,
                    c.focus_distance_m.map(|f| format!("{f:.3} m")).unwrap_or_else(|| "unset".into()),
                    c.petzval.as_ref().and_then(|p| p.lens.as_ref()).map(|l| format!(", lens {l}")).unwrap_or_default()
                );
            }
            for l in &s.info.lights {
                println!("  light {} ({}) → {}: {:?}", l.prim, l.kind, l.renderer, l.value);
            }
            for w in &s.scene.warnings {
                println!("  warning: {w}");
            }
            Ok(())
        }
        UsdCommand::SetLens { shot, camera, lens, output, lens_model, tilt_x, tilt_y, blades } => {
            let attrs = petzval_usd::author::LensAttrs {
                lens_model,
                tilt_deg: if tilt_x.is_some() || tilt_y.is_some() {
                    Some((tilt_x.unwrap_or(0.0), tilt_y.unwrap_or(0.0)))
                } else {
                    None
                },
                blades,
                ..Default::default()
            };
            petzval_usd::author::set_lens(&shot, &camera, &lens, &attrs, &output)?;
            eprintln!("wrote {} (sublayers {}; {camera} uses {lens})", output.display(), shot.display());
            Ok(())
        }
    }
}
