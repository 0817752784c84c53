//! `petzval lrtf ...`: bake and inspect lens ray transfer tables.

use clap::Subcommand;
use indicatif::{ProgressBar, ProgressStyle};
use petzval_renderer::optics::lrtf::{BakeOptions, LrtfTable};
use petzval_renderer::optics::lrtf_scene::SceneToFilmTable;
use petzval_renderer::Error;
use std::path::PathBuf;

/// LRTF subcommands.
#[derive(Subcommand)]
pub enum LrtfCommand {
    /// Bake a table for a lens (stop open; any f-number and stop shape apply at render time).
    Bake {
        /// Library name or lens file.
        lens: String,
        /// Output file.
        #[arg(short, long)]
        output: PathBuf,
        /// Samples along the radial and σx axes (σy gets half).
        #[arg(long, default_value_t = 96)]
        resolution: u32,
        /// Film radius the table must cover (mm).
        #[arg(long, default_value_t = 30.0)]
        max_film_radius: f64,
        /// Wavelengths in nm, comma separated (default: primary, or the design wavelengths for
        /// dispersive lenses).
        #[arg(long)]
        wavelengths: Option<String>,
        /// film-to-scene (rendering) or scene-to-film (where light from the scene lands on the
        /// film, for lens-fit; covers the lens's field plus 5°).
        #[arg(long, default_value = "film-to-scene")]
        direction: String,
    },
    /// Print a table's header after checking it belongs to LENS.
    Info {
        /// Library name or lens file the table was baked for.
        lens: String,
        /// Table file.
        file: PathBuf,
    },
}

/// Runs an LRTF subcommand.
pub fn run(cmd: LrtfCommand) -> Result<(), Error> {
    match cmd {
        LrtfCommand::Bake { lens, output, resolution, max_film_radius, wavelengths, direction } => {
            if !(max_film_radius.is_finite() && max_film_radius > 0.0 && max_film_radius <= 1000.0) {
                return Err(Error::settings(
                    "max-film-radius",
                    format!("must be a radius in (0, 1000] mm, got {max_film_radius}"),
                ));
            }
            let lens = petzval_renderer::load_lens(&lens)?;
            let wavelengths_nm = match wavelengths {
                None => None,
                Some(w) => Some(
                    w.split(',')
                        .map(|v| v.trim().parse::<f64>().ok().filter(|x| (380.0..=780.0).contains(x)))
                        .collect::<Option<Vec<f64>>>()
                        .ok_or_else(|| {
                            Error::settings("--wavelengths", format!("expected numbers in 380..780 nm, got '{w}'"))
                        })?,
                ),
            };
            if !(8..=512).contains(&resolution) {
                return Err(Error::settings("--resolution", format!("{resolution} must be in 8..=512")));
            }
            let bar = ProgressBar::new(1000);
            bar.set_style(
                ProgressStyle::with_template("baking {spinner} [{elapsed_precise}] {wide_bar} {percent}% ETA {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            let t0 = std::time::Instant::now();
            let table = match direction.as_str() {
                "film-to-scene" => {
                    let opts = BakeOptions {
                        resolution,
                        max_film_radius_mm: max_film_radius,
                        min_film_distance_mm: None,
                        wavelengths_nm,
                    };
                    LrtfTable::bake(&lens, &opts, &|f| bar.set_position((f * 1000.0) as u64))?
                }
                "scene-to-film" => {
                    if wavelengths_nm.is_some() {
                        return Err(Error::settings(
                            "--wavelengths",
                            "scene-to-film tables use the lens's own wavelengths",
                        ));
                    }
                    SceneToFilmTable::bake(&lens, resolution, 5.0, &|f| bar.set_position((f * 1000.0) as u64))?.table
                }
                d => {
                    return Err(Error::settings(
                        "--direction",
                        format!("expected film-to-scene or scene-to-film, got '{d}'"),
                    ))
                }
            };
            bar.finish_and_clear();
            table.save(&output)?;
            eprintln!(
                "baked {} ({direction}) at {}×{}×{} × {} wavelength(s) in {:.2} s: {:.1} MiB → {}",
                lens.name(),
                table.header.resolution,
                table.header.resolution,
                table.header.resolution_y,
                table.header.wavelengths_nm.len(),
                t0.elapsed().as_secs_f64(),
                table.data_bytes() as f64 / (1 << 20) as f64,
                output.display()
            );
            Ok(())
        }
        LrtfCommand::Info { lens, file } => {
            let lens = petzval_renderer::load_lens(&lens)?;
            // a film → scene table of the lens, or a scene → film one (of the reversed lens)
            let table = match LrtfTable::load(&file, &lens) {
                Ok(t) => t,
                Err(e) => match SceneToFilmTable::load(&file, &lens) {
                    Ok(t) => t.table,
                    Err(_) => return Err(e.into()),
                },
            };
            println!("{}", serde_json::to_string_pretty(&table.header).unwrap_or_default());
            Ok(())
        }
    }
}
