//! Bounded mutation fuzzing of the input entry points (issue 12): the four lens formats (our
//! TOML, Zemax .zmx, pbrt .dat, lentil JSON), glTF (.gltf and .glb) and LRTF tables. Each seed
//! file is mutated deterministically (bit flips, byte insertions and deletions, chunk
//! duplication, numbers replaced by extreme values), loaded, and, when it loads, used a little
//! (a lens traces a ray fan and reports first-order data; a scene builds its BVH). The run fails
//! on any panic, and on non-finite output from an input that loaded.
//!
//! `PETZVAL_FUZZ_ITERATIONS` sets the mutations per entry point (default 300, about 10 s in
//! all in release); the long campaign in docs/reliability.md ran 100 000 per entry point.
//! Crashes found are kept as regression cases in `tests/data/fuzz/` (none so far).

use glam::DVec3;
use petzval_renderer::optics::lrtf::{BakeOptions, LrtfTable};
use petzval_renderer::scene::gltf::load_gltf;
use petzval_renderer::{library_lens, load_lens_file, Lens, Ray, RenderScene, TraceDirection};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

/// SplitMix64: the same mutations on every machine.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const EXTREMES: [&str; 14] =
    ["nan", "inf", "-inf", "1e308", "-1e308", "1e-300", "0", "-0", "1e12", "-1", "4294967296", "", "1e", "--"];

/// One mutation of `seed` (text-aware when the seed is text: numbers become extremes).
fn mutate(seed: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        if b.is_empty() {
            b.push(rng.next() as u8);
        }
        match rng.below(6) {
            0 => {
                let k = rng.below(b.len());
                b[k] ^= 1 << rng.below(8);
            }
            1 => {
                let k = rng.below(b.len() + 1);
                b.insert(k, rng.next() as u8);
            }
            2 => {
                let k = rng.below(b.len());
                let n = 1 + rng.below(16.min(b.len() - k));
                b.drain(k..k + n);
            }
            3 => {
                let k = rng.below(b.len());
                let n = 1 + rng.below(64.min(b.len() - k));
                let chunk = b[k..k + n].to_vec();
                let at = rng.below(b.len() + 1);
                b.splice(at..at, chunk);
            }
            _ => {
                // a number in the text becomes an extreme value
                let starts: Vec<usize> = (0..b.len())
                    .filter(|&i| b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_alphanumeric()))
                    .collect();
                if starts.is_empty() {
                    continue;
                }
                let s = starts[rng.below(starts.len())];
                let mut e = s;
                while e < b.len() && (b[e].is_ascii_digit() || b".eE+-".contains(&b[e])) {
                    e += 1;
                }
                let with = EXTREMES[rng.below(EXTREMES.len())].as_bytes();
                b.splice(s..e, with.iter().copied());
            }
        }
    }
    b
}

fn iterations() -> usize {
    std::env::var("PETZVAL_FUZZ_ITERATIONS").ok().and_then(|v| v.parse().ok()).unwrap_or(300)
}

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// Loads a mutated lens file and uses it; `Err` = the loader refused it (fine).
fn use_lens(path: &Path) -> Result<(), String> {
    let lens: Lens = load_lens_file(path).map_err(|e| e.to_string())?;
    e_if(lens.check_forms_image().is_ok() && !lens.paraxial().efl_mm.is_finite(), "non-finite EFL")?;
    // a fan of rays from the film: every ray that passes is finite
    let film_z = lens.last_vertex_z_mm() + lens.design_back_focus_mm().clamp(-1e6, 1e6);
    for k in 0..16 {
        let a = k as f64 * 0.7;
        let o = DVec3::new(0.0, 0.0, film_z);
        let target = DVec3::new(a.cos() * 3.0, a.sin() * 3.0, lens.last_vertex_z_mm());
        if let Some(t) = lens.trace(&Ray::new(o, target - o), lens.primary_wavelength_nm(), TraceDirection::FilmToScene)
        {
            e_if(!(t.ray.origin.is_finite() && t.ray.direction.is_finite()), "non-finite traced ray")?;
        }
    }
    Ok(())
}

fn e_if(cond: bool, what: &str) -> Result<(), String> {
    if cond {
        Err(format!("BUG: {what}"))
    } else {
        Ok(())
    }
}

/// Runs `count` mutations of every seed through `check`; panics and "BUG:" results fail.
fn campaign(name: &str, seeds: &[PathBuf], count: usize, check: &dyn Fn(&Path) -> Result<(), String>) {
    let dir = std::env::temp_dir().join(format!("petzval-fuzz-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut rng = Rng(0x5EED ^ name.len() as u64);
    let (mut refused, mut loaded) = (0, 0);
    let mut failures = Vec::new();
    let seeds: Vec<(PathBuf, Vec<u8>)> = seeds.iter().map(|p| (p.clone(), std::fs::read(p).unwrap())).collect();
    for i in 0..count {
        let (seed_path, seed) = &seeds[i % seeds.len()];
        let bytes = mutate(seed, &mut rng);
        let ext = seed_path.extension().and_then(|e| e.to_str()).unwrap_or("bin");
        let path = dir.join(format!("case.{ext}"));
        std::fs::write(&path, &bytes).unwrap();
        match catch_unwind(AssertUnwindSafe(|| check(&path))) {
            Ok(Ok(())) => loaded += 1,
            Ok(Err(e)) if e.starts_with("BUG:") => failures.push((i, e, bytes)),
            Ok(Err(_)) => refused += 1,
            Err(_) => failures.push((i, "panic".to_string(), bytes)),
        }
    }
    for (i, what, bytes) in &failures {
        let keep =
            dir.join(format!("failure-{i}.{}", seeds[0].0.extension().and_then(|e| e.to_str()).unwrap_or("bin")));
        std::fs::write(&keep, bytes).unwrap();
        eprintln!("{name}: case {i}: {what} (kept in {})", keep.display());
    }
    println!("fuzz {name}: {count} inputs, {loaded} loaded, {refused} refused, {} failures", failures.len());
    assert!(failures.is_empty(), "{name}: {} failing inputs (see stderr)", failures.len());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn lens_files_never_panic() {
    let optics = "optics/tests/data";
    let mut seeds: Vec<PathBuf> = ["pbrt/dgauss.50mm.dat", "pbrt/fisheye.10mm.dat", "zmx/cooke_triplet.zmx"]
        .iter()
        .map(|p| data(&format!("{optics}/{p}")))
        .collect();
    seeds.push(data("optics/tests/data/zmx/double_gauss.zmx"));
    seeds.push(data("optics/lenses/double-gauss-50mm.toml"));
    seeds.push(data("optics/lenses/aspheric-fisheye-10mm.toml"));
    campaign("lens", &seeds, iterations(), &use_lens);
}

#[test]
fn lentil_json_never_panics() {
    let seeds = [data("optics/tests/data/lentil/lentil-subset.json")];
    campaign("lentil", &seeds, iterations() / 3 + 1, &|p: &Path| {
        // the JSON holds many lenses: load the first few by index; loaded if any loads
        let mut any = false;
        for id in 0..3 {
            let with_id = PathBuf::from(format!("{}#{id}", p.display()));
            match use_lens(&with_id) {
                Ok(()) => any = true,
                Err(e) if e.starts_with("BUG:") => return Err(e),
                Err(_) => {}
            }
        }
        if any {
            Ok(())
        } else {
            Err("refused".into())
        }
    });
}

#[test]
fn gltf_files_never_panic() {
    let dir = data("tests/data/gltf");
    let seeds: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")))
        .collect();
    assert!(seeds.len() >= 5, "{seeds:?}");
    // the seeds reference buffers and textures next to them: copy those into the case folder
    let cases = std::env::temp_dir().join(format!("petzval-fuzz-gltf-{}", std::process::id()));
    std::fs::create_dir_all(&cases).unwrap();
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let p = e.path();
        if p.is_file() && !matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")) {
            std::fs::copy(&p, cases.join(e.file_name())).unwrap();
        }
    }
    campaign("gltf", &seeds, iterations(), &|p: &Path| {
        let scene = load_gltf(p).map_err(|e| e.to_string())?;
        let scene = RenderScene::new(scene).map_err(|e| e.to_string())?;
        e_if(scene.triangle_count() > 50_000_000, "implausible triangle count")
    });
}

#[test]
fn lrtf_tables_never_panic() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    let options = BakeOptions { resolution: 8, ..BakeOptions::default() };
    let table = LrtfTable::bake(&lens, &options, &|_| {}).unwrap();
    let seed = std::env::temp_dir().join(format!("petzval-fuzz-seed-{}.lrtf", std::process::id()));
    table.save(&seed).unwrap();
    campaign("lrtf", std::slice::from_ref(&seed), iterations(), &|p: &Path| {
        let t = LrtfTable::load(p, &lens).map_err(|e| e.to_string())?;
        // a table that loads must look rays up without panicking
        let o = DVec3::new(0.0, 0.0, lens.last_vertex_z_mm() + lens.design_back_focus_mm());
        let _ = t.lookup(&Ray::new(o, DVec3::new(0.01, 0.0, -1.0)), lens.primary_wavelength_nm());
        Ok(())
    });
    let _ = std::fs::remove_file(&seed);
}

/// Inputs the campaign found that crashed, kept as regression cases (`tests/data/fuzz/`): each
/// loads or is refused without a panic.
#[test]
fn kept_crash_cases_do_not_panic() {
    let dir = data("tests/data/fuzz");
    let mut cases = 0;
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let p = e.path();
        if !matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")) {
            continue;
        }
        cases += 1;
        let outcome = catch_unwind(AssertUnwindSafe(|| load_gltf(&p).map(|s| RenderScene::new(s).map(|_| ()))));
        assert!(outcome.is_ok(), "{} panics", p.display());
    }
    assert!(cases >= 2);
}
