//! `petzval bench ...`: benchmarks that print tables (results recorded in docs/performance.md).

use clap::Subcommand;
use glam::{DVec2, DVec3};
use petzval_renderer::{Error, Sensor};

mod bokeh;
mod dof;
mod instances;
mod lens;
mod lens_models;
mod render;
mod render_models;

use bokeh::bench_bokeh;
use dof::bench_dof;
use instances::bench_instances;
use lens::bench_lens;
use lens_models::bench_lens_models;
use render::bench_render;
use render_models::bench_render_models;

/// Timed runs per measurement in `bench lens-models` (the best is reported: the machine may be
/// shared, and interference only ever adds time).
pub(super) const REPEATS: usize = 5;

/// Benchmark subcommands.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// ns per traced ray for every library lens (all rays and passing rays) and the exit-pupil
    /// rejection rate, on one thread.
    Lens {
        /// Only this lens.
        #[arg(long)]
        lens: Option<String>,
        /// Rays per lens.
        #[arg(long, default_value_t = 400_000)]
        rays: usize,
        /// Stop every lens down to this f-number (a lens that cannot open that wide stays
        /// fully open); default: each lens wide open.
        #[arg(long)]
        fstop: Option<f64>,
        /// Print JSON lines instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Speed against error of every lens model (pinhole, thin, thick, LRTF at several
    /// resolutions, exact) for each library lens.
    LensModels {
        /// Only this lens.
        #[arg(long)]
        lens: Option<String>,
        /// Rays per lens and model.
        #[arg(long, default_value_t = 200_000)]
        rays: usize,
        /// LRTF resolutions.
        #[arg(long, default_value = "32,64,96,128")]
        resolutions: String,
        /// Print a JSON array instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Image-level error of every camera model (pinhole, thin, thick, LRTF at several
    /// resolutions) against the exact render of the built-in demo at equal spp and seed:
    /// relative RMSE, mean LDR-FLIP, render and bake seconds, and the noise floor (the exact
    /// model with another seed).
    RenderModels {
        /// Resolution WxH.
        #[arg(long, default_value = "480x320")]
        resolution: String,
        /// Samples per pixel (every model).
        #[arg(long, default_value_t = 64)]
        spp: u32,
        /// LRTF resolutions.
        #[arg(long, default_value = "32,64,96")]
        resolutions: String,
        /// Seed of every render (the noise floor uses seed + 1).
        #[arg(long, default_value_t = 0)]
        seed: u32,
        /// Write each render as a PNG into this directory.
        #[arg(long)]
        save: Option<std::path::PathBuf>,
        /// Print a JSON array instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Render cost by camera model on the built-in demo (ratio to pinhole), and primary-ray
    /// throughput, BVH build time and memory on a ~1M-triangle scene.
    Render {
        /// Resolution of the camera-model comparison.
        #[arg(long, default_value = "480x320")]
        resolution: String,
        /// Samples per pixel of the camera-model comparison.
        #[arg(long, default_value_t = 16)]
        spp: u32,
        /// Triangles in the throughput scene (about).
        #[arg(long, default_value_t = 1_000_000)]
        triangles: usize,
    },
    /// Every depth-of-field method (mc, multiview, ibrt, spread) against a converged Monte Carlo
    /// render on four scenes (the demo, a near occluder before highlights, the demo with a
    /// tilted sensor, all through a thin lens, and the demo through its real lens): time,
    /// relative RMSE and mean FLIP over a ladder of budgets, then error at equal time and time to
    /// equal error.
    Dof {
        /// Resolution WxH.
        #[arg(long, default_value = "240x160")]
        resolution: String,
        /// Samples per pixel of the Monte Carlo reference.
        #[arg(long, default_value_t = 2048)]
        reference_spp: u32,
        /// Write every render as a PNG into this directory.
        #[arg(long)]
        save: Option<std::path::PathBuf>,
        /// Methods to run (comma-separated; the Monte Carlo reference is always made, or read
        /// from the --save directory of an earlier run).
        #[arg(long, default_value = "mc,multiview,ibrt,spread")]
        methods: String,
        /// Instead, render the failure cases (wide angle, near objects, highlights outside the
        /// frame, tilt) beside Monte Carlo into this directory.
        #[arg(long)]
        failures: Option<std::path::PathBuf>,
    },
    /// Bokeh light paths (MIS with camera paths) against camera paths alone on the demo through
    /// its real lens and on a night street: time, relative RMSE against a converged reference,
    /// and time to equal error.
    Bokeh {
        /// Resolution WxH.
        #[arg(long, default_value = "240x160")]
        resolution: String,
        /// Samples per pixel of the reference (rendered with light paths).
        #[arg(long, default_value_t = 1024)]
        reference_spp: u32,
        /// The relative RMSE whose time the last table gives.
        #[arg(long, default_value_t = 0.05)]
        target: f64,
        /// Write every render as a PNG into this directory.
        #[arg(long)]
        save: Option<std::path::PathBuf>,
    },
    /// Memory of a scene of many instances of one mesh (mesh data, BLAS, instance records, TLAS)
    /// against one copy, a render of it, and the built-in demo flattened vs instanced.
    Instances {
        /// Copies of the mesh.
        #[arg(long, default_value_t = 10_000)]
        instances: usize,
        /// Triangles of the mesh (about).
        #[arg(long, default_value_t = 10_000)]
        triangles: usize,
        /// Resolution WxH of the renders.
        #[arg(long, default_value = "320x240")]
        resolution: String,
        /// Samples per pixel of the renders.
        #[arg(long, default_value_t = 4)]
        spp: u32,
        /// Demo renders per configuration (the fastest is reported).
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// Write the instanced render as this PNG.
        #[arg(long)]
        save: Option<std::path::PathBuf>,
    },
}

/// Runs a benchmark.
pub fn run(cmd: BenchCommand) -> Result<(), Error> {
    match cmd {
        BenchCommand::Lens { lens, rays, fstop, json } => bench_lens(lens, rays, fstop, json),
        BenchCommand::Render { resolution, spp, triangles } => bench_render(&resolution, spp, triangles),
        BenchCommand::Bokeh { resolution, reference_spp, target, save } => {
            bench_bokeh(&resolution, reference_spp, target, save.as_deref())
        }
        BenchCommand::Instances { instances, triangles, resolution, spp, repeats, save } => {
            bench_instances(instances, triangles, &resolution, spp, repeats, save.as_deref())
        }
        BenchCommand::Dof { resolution, reference_spp, save, methods, failures } => match failures {
            Some(dir) => dof::bench_dof_failures(&resolution, reference_spp, &dir),
            None => bench_dof(&resolution, reference_spp, save.as_deref(), &methods),
        },
        BenchCommand::LensModels { lens, rays, resolutions, json } => bench_lens_models(lens, rays, &resolutions, json),
        BenchCommand::RenderModels { resolution, spp, resolutions, seed, save, json } => {
            bench_render_models(&resolution, spp, &resolutions, seed, save.as_deref(), json)
        }
    }
}

/// A small deterministic generator (SplitMix64) for benchmark samples.
pub(super) struct SplitMix(u64);
impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn next2(&mut self) -> DVec2 {
        DVec2::new(self.next_f64(), self.next_f64())
    }
}

/// Up to `count` camera rays as the realistic camera draws them: (image position, film point,
/// rear-plane point from the exit-pupil bounds mixed with their defensive disc, 1 sample in
/// 128), drawn from `rng`; film points where nothing is drawn (outside the image circle, except
/// for the disc's share) are skipped.
pub(super) fn camera_ray_samples(
    sensor: &Sensor,
    bounds: &petzval_renderer::optics::pupil::ExitPupilBounds,
    film_z: f64,
    count: usize,
    rng: &mut SplitMix,
) -> Vec<(DVec2, DVec3, DVec3)> {
    let mut out = Vec::with_capacity(count);
    let mut guard = 0;
    while out.len() < count && guard < count * 50 {
        guard += 1;
        let u = rng.next2();
        let p = sensor.film_point(u, film_z);
        if let Some(s) = bounds.sample(DVec2::new(p.x, p.y), rng.next2()) {
            out.push((u, p, s.point));
        }
    }
    out
}

/// Parses `WxH`.
pub(super) fn parse_wxh(resolution: &str) -> Result<(u32, u32), Error> {
    resolution
        .split_once('x')
        .and_then(|(a, b)| Some((a.trim().parse::<u32>().ok()?, b.trim().parse::<u32>().ok()?)))
        .filter(|(w, h)| *w > 0 && *h > 0)
        .ok_or_else(|| Error::settings("resolution", format!("expected WxH such as 480x320, got '{resolution}'")))
}

/// Parses a comma-separated list of LRTF resolutions.
pub(super) fn parse_resolutions(list: &str) -> Result<Vec<u32>, Error> {
    list.split(',')
        .filter(|r| !r.trim().is_empty())
        .map(|r| {
            r.trim().parse::<u32>().ok().filter(|v| (8..=512).contains(v)).ok_or_else(|| {
                Error::settings(
                    "resolutions",
                    format!("expected comma-separated LRTF resolutions in 8..=512, got '{r}'"),
                )
            })
        })
        .collect()
}
