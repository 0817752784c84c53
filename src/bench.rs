//! `petzval bench ...`: benchmarks that print tables (results recorded in docs/performance.md).

use clap::Subcommand;
use glam::{DVec2, DVec3};
use petzval_renderer::optics::pupil::ExitPupilBounds;
use petzval_renderer::{load_lens, Error, Ray, Sensor, TraceDirection, LIBRARY};
use std::time::Instant;

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
        /// Print JSON lines instead of a table.
        #[arg(long)]
        json: bool,
    },
}

/// Runs a benchmark.
pub fn run(cmd: BenchCommand) -> Result<(), Error> {
    match cmd {
        BenchCommand::Lens { lens, rays, json } => bench_lens(lens, rays, json),
    }
}

/// A small deterministic generator (SplitMix64) for benchmark samples.
struct SplitMix(u64);
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

fn bench_lens(only: Option<String>, rays: usize, json: bool) -> Result<(), Error> {
    let names: Vec<String> = match only {
        Some(n) => vec![n],
        None => LIBRARY.iter().map(|e| e.name.to_string()).collect(),
    };
    if !json {
        println!("Exact trace, film → scene, primary wavelength, 1 thread, {rays} rays per lens; film points uniform over a 36×24 mm sensor");
        println!("(clamped to the lens's image circle), rear-plane points from the exit-pupil bounds, focus at infinity.");
        println!();
        println!("| lens | surfaces | ns/ray (all) | ns/ray (passing) | rejection (pupil bounds) | rejection (whole rear disc) | bounds build ms |");
        println!("|---|---|---|---|---|---|---|");
    }
    for name in names {
        let lens = load_lens(&name)?;
        let film_z = lens.last_vertex_z_mm() + lens.focus_image_distance_mm(None)?;
        let sensor = Sensor::default();
        let (r_max, _) = sensor.extent();
        let t0 = Instant::now();
        let bounds = ExitPupilBounds::compute(&lens, film_z, 0.0, r_max * 1.001);
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        // 1. Sample film points whose bounds are non-empty (inside the image circle).
        let mut rng = SplitMix(0x5eed);
        let mut samples: Vec<(DVec3, DVec3)> = Vec::with_capacity(rays);
        let mut guard = 0;
        while samples.len() < rays && guard < rays * 50 {
            guard += 1;
            let u = rng.next2();
            let p = sensor.film_point(u, film_z);
            if let Some(s) = bounds.sample(DVec2::new(p.x, p.y), rng.next2()) {
                samples.push((p, s.point));
            }
        }
        let wl = lens.primary_wavelength_nm();
        // 2. Time the traces.
        let t0 = Instant::now();
        let mut pass = 0usize;
        for (p, q) in &samples {
            if lens.trace(&Ray::new(*p, *q - *p), wl, TraceDirection::FilmToScene).is_some() {
                pass += 1;
            }
        }
        let secs = t0.elapsed().as_secs_f64();
        // 3. Rejection without bounds: uniform over the rear element's disc (1.5× radius square as pbrt).
        let rear = lens.rear_semi_diameter_mm();
        let mut pass_disc = 0usize;
        let n_disc = samples.len().min(100_000);
        for (p, _) in samples.iter().take(n_disc) {
            let d = petzval_renderer::optics::aperture::concentric_disk(rng.next2()) * rear;
            let q = DVec3::new(d.x, d.y, lens.last_vertex_z_mm());
            if lens.trace(&Ray::new(*p, q - *p), wl, TraceDirection::FilmToScene).is_some() {
                pass_disc += 1;
            }
        }
        let n = samples.len().max(1);
        let ns_all = secs * 1e9 / n as f64;
        let ns_pass = if pass > 0 { secs * 1e9 / pass as f64 } else { f64::INFINITY };
        let rej = 1.0 - pass as f64 / n as f64;
        let rej_disc = 1.0 - pass_disc as f64 / n_disc.max(1) as f64;
        if json {
            println!(
                "{}",
                serde_json::json!({"lens": name, "surfaces": lens.surfaces().len(), "ns_per_ray": ns_all, "ns_per_passing_ray": ns_pass,
                    "rejection_rate": rej, "rejection_rate_rear_disc": rej_disc, "bounds_build_ms": build_ms})
            );
        } else {
            println!(
                "| {name} | {} | {ns_all:.0} | {ns_pass:.0} | {:.1}% | {:.1}% | {build_ms:.0} |",
                lens.surfaces().len(),
                100.0 * rej,
                100.0 * rej_disc
            );
        }
    }
    Ok(())
}
