//! LRTF tables: accuracy against the exact trace, boundary handling, file round trip.

use glam::{DVec2, DVec3};
use petzval_optics::lrtf::{BakeOptions, LrtfLookup, LrtfTable};
use petzval_optics::pupil::ExitPupilBounds;
use petzval_optics::{library_lens, Lens, Ray, StopMode, TraceDirection};

/// Film rays sampled like the realistic camera does: film points over the sensor, rear points
/// in the exit-pupil bounds of the open stop.
fn camera_rays(lens: &Lens, count: usize, seed: u64) -> Vec<Ray> {
    let film_z = lens.last_vertex_z_mm() + lens.focus_image_distance_mm(None).unwrap();
    let bounds = ExitPupilBounds::compute(lens, film_z, 0.0, 21.7);
    let mut state = seed;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut rays = Vec::with_capacity(count);
    while rays.len() < count {
        let film = DVec3::new(36.0 * (rnd() - 0.5), 24.0 * (rnd() - 0.5), film_z);
        if let Some(s) = bounds.sample(DVec2::new(film.x, film.y), DVec2::new(rnd(), rnd())) {
            rays.push(Ray::new(film, s.point - film));
        }
    }
    rays
}

#[test]
fn lrtf_error_report_double_gauss() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    for res in [32u32, 96] {
        let t0 = std::time::Instant::now();
        let table = LrtfTable::bake(&lens, &BakeOptions { resolution: res, ..Default::default() }, &|_| {}).unwrap();
        let bake_s = t0.elapsed().as_secs_f64();
        let wl = lens.primary_wavelength_nm();
        let rays = camera_rays(&lens, 50_000, 7);
        let (mut n_both, mut mis, mut dir_err, mut max_dir, mut uncertain) = (0usize, 0usize, 0.0f64, 0.0f64, 0usize);
        for r in &rays {
            let exact = lens.trace_detailed(r, wl, TraceDirection::FilmToScene, StopMode::Apply).ok();
            let approx = match table.lookup(r, wl) {
                LrtfLookup::Hit(l) => {
                    (lens.aperture().transmission(l.stop_point.x, l.stop_point.y, lens.stop_semi_diameter_mm()) > 0.0)
                        .then_some(l)
                }
                LrtfLookup::Miss => None,
                LrtfLookup::Uncertain => {
                    uncertain += 1;
                    continue;
                }
            };
            match (exact, approx) {
                (Some(e), Some(a)) => {
                    n_both += 1;
                    let de = (e.ray.direction - a.ray.direction).length();
                    dir_err += de;
                    max_dir = max_dir.max(de);
                }
                (None, None) => {}
                _ => mis += 1,
            }
        }
        eprintln!(
            "res {res}: bake {bake_s:.2} s, {:.1} MiB, both {n_both}, uncertain {:.2}%, misclassified {:.3}%, mean dir err {:.4} mrad, max {:.4} mrad",
            table.data_bytes() as f64 / (1 << 20) as f64,
            100.0 * uncertain as f64 / rays.len() as f64,
            100.0 * mis as f64 / rays.len() as f64,
            1e3 * dir_err / n_both as f64,
            1e3 * max_dir
        );
        if res == 96 {
            // the targets for this lens: ≤ 0.1 % misclassified, mean image error ≤ 0.1 px
            // at 1920 px across 36 mm (EFL × angle), ≤ 64 MiB per wavelength
            let mean_px = lens.paraxial().efl_mm * (dir_err / n_both as f64) / (36.0 / 1920.0);
            assert!((mis as f64 / rays.len() as f64) < 1e-3, "misclassified {mis} of {}", rays.len());
            assert!(mean_px < 0.1, "mean image error {mean_px} px");
            assert!(table.data_bytes() < 64 << 20);
        }
    }
}

/// Saved tables load back identically; a table for another lens, a foreign file and a truncated
/// file are refused with a clear error; any f-number applies to a table baked with the stop open.
#[test]
fn lrtf_file_round_trip_and_refusals() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    let table = LrtfTable::bake(&lens, &BakeOptions { resolution: 24, ..Default::default() }, &|_| {}).unwrap();
    let dir = std::env::temp_dir().join(format!("petzval-lrtf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("dg.lrtf");
    table.save(&path).unwrap();
    let back = LrtfTable::load(&path, &lens).unwrap();
    assert_eq!(back.header, table.header);
    let rays = camera_rays(&lens, 2000, 5);
    let wl = lens.primary_wavelength_nm();
    for r in &rays {
        assert_eq!(format!("{:?}", back.lookup(r, wl)), format!("{:?}", table.lookup(r, wl)));
    }
    // the in-memory layout (entries replicated with their σy neighbour) gives back the file's
    // entries exactly
    back.save(&dir.join("again.lrtf")).unwrap();
    assert!(
        std::fs::read(&path).unwrap() == std::fs::read(dir.join("again.lrtf")).unwrap(),
        "save → load → save changed the file"
    );
    // stale: another lens
    let other = library_lens("wide-22mm").unwrap();
    let err = LrtfTable::load(&path, &other).unwrap_err().to_string();
    assert!(err.contains("baked for lens 'double-gauss-50mm'") && err.contains("re-bake"), "{err}");
    // foreign and truncated files
    std::fs::write(dir.join("junk.lrtf"), b"hello world, not a table").unwrap();
    assert!(LrtfTable::load(&dir.join("junk.lrtf"), &lens).unwrap_err().to_string().contains("bad magic"));
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(dir.join("cut.lrtf"), &bytes[..bytes.len() / 2]).unwrap();
    assert!(LrtfTable::load(&dir.join("cut.lrtf"), &lens).is_err());
    // the stop is applied at lookup: stopping down never adds rays
    let f8 = lens.stopped_down(8.0).unwrap();
    let pass = |l: &Lens| {
        rays.iter()
            .filter(|r| match table.lookup(r, wl) {
                LrtfLookup::Hit(h) => {
                    l.aperture().transmission(h.stop_point.x, h.stop_point.y, l.stop_semi_diameter_mm()) > 0.0
                }
                _ => false,
            })
            .count()
    };
    assert!(pass(&f8) < pass(&lens) / 4, "f/8 passes {} of the f/2 rays {}", pass(&f8), pass(&lens));
    // lenses with cylinders cannot be tabulated in 3-D
    assert!(
        LrtfTable::bake(&library_lens("schneider-anamorphic-31mm").unwrap(), &BakeOptions::default(), &|_| {}).is_err()
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The lookup this CPU runs (AVX2 + FMA where detected) gives the same bits as the baseline
/// build on 50 000 camera rays and on rays off the baked domain (reported: which one ran).
#[test]
fn the_run_time_simd_lookup_matches_the_baseline_bit_for_bit() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    let table = LrtfTable::bake(&lens, &BakeOptions { resolution: 32, ..Default::default() }, &|_| {}).unwrap();
    let wl = lens.primary_wavelength_nm();
    let mut rays = camera_rays(&lens, 50_000, 11);
    // and some that miss the dome or leave the domain
    for k in 0..2_000 {
        let a = k as f64 * 0.0137;
        rays.push(Ray::new(DVec3::new(30.0 * a.cos(), 30.0 * a.sin(), 60.0), DVec3::new(-a.sin(), a.cos(), -0.3)));
    }
    let mut hits = 0;
    for r in &rays {
        let (fast, base) = (table.lookup(r, wl), table.lookup_baseline(r, wl));
        assert_eq!(format!("{fast:?}"), format!("{base:?}"), "ray {r:?}");
        hits += matches!(fast, LrtfLookup::Hit(_)) as usize;
    }
    println!(
        "lookup with {:?}: {hits} of {} rays hit, all bit-identical",
        petzval_optics::lrtf::simd_level(),
        rays.len()
    );
    assert!(hits > 10_000);
}

/// The batched lookup (cells of every lane first, prefetched, then the blends) gives the same
/// bits as one lookup per ray, in the run-time and the baseline builds, with the lanes'
/// wavelengths mixed and with hits, misses and uncertain rays side by side in a batch.
#[test]
fn the_batched_lookup_matches_single_lookups_bit_for_bit() {
    use petzval_optics::lrtf::LRTF_BATCH;
    let lens = library_lens("double-gauss-50mm").unwrap();
    let options = BakeOptions { resolution: 32, wavelengths_nm: Some(vec![486.1, 587.6, 656.3]), ..Default::default() };
    let table = LrtfTable::bake(&lens, &options, &|_| {}).unwrap();
    let wls = [480.0, 587.6, 600.0, 656.3, 700.0];
    let mut rays = camera_rays(&lens, 40_000, 12);
    for k in 0..2_000 {
        let a = k as f64 * 0.0137;
        rays.push(Ray::new(DVec3::new(30.0 * a.cos(), 30.0 * a.sin(), 60.0), DVec3::new(-a.sin(), a.cos(), -0.3)));
    }
    // shuffle the off-domain rays in among the camera rays
    let n = rays.len();
    for i in 0..2_000 {
        rays.swap(n - 1 - i, (i * 7919) % (n - 2_000));
    }
    let (mut kinds, mut batches) = ([0usize; 3], 0);
    for chunk in rays.chunks(LRTF_BATCH) {
        let batch: [Ray; LRTF_BATCH] = std::array::from_fn(|i| *chunk.get(i).unwrap_or(&chunk[0]));
        let wl: [f64; LRTF_BATCH] = std::array::from_fn(|i| wls[(i + batches) % wls.len()]);
        let (fast, base) = (table.lookup_batch(&batch, &wl), table.lookup_batch_baseline(&batch, &wl));
        for i in 0..LRTF_BATCH {
            let one = table.lookup(&batch[i], wl[i]);
            assert_eq!(format!("{:?}", fast[i]), format!("{one:?}"), "lane {i} of batch {batches}");
            assert_eq!(format!("{:?}", base[i]), format!("{one:?}"), "lane {i} of batch {batches} (baseline)");
            kinds[match one {
                LrtfLookup::Hit(_) => 0,
                LrtfLookup::Miss => 1,
                LrtfLookup::Uncertain => 2,
            }] += 1;
        }
        batches += 1;
    }
    println!("{batches} batches over {} wavelengths: hits, misses, uncertain {kinds:?}", wls.len());
    assert!(kinds.iter().all(|&k| k > 100), "every outcome occurs: {kinds:?}");
}
