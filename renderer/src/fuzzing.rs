//! Fuzzing (issue 12): the entry points of the renderer's input formats and the stable-Rust
//! mutation driver, in one place for both ways of fuzzing them:
//!
//! - the bounded runs in the test binaries (`renderer/tests/fuzz.rs`, `usd/tests/fuzz.rs`,
//!   `tests/cli/fuzz.rs`; in `tests/run`, `PETZVAL_FUZZ_ITERATIONS` inputs per entry point), which
//!   mutate the seeds of `fuzz/seeds.txt` with [`mutate`] and run them through [`run_campaign`];
//! - the cargo-fuzz targets in `fuzz/fuzz_targets/` (nightly, libFuzzer), which call the same
//!   functions on libFuzzer's inputs and panic on a [`Bug`].
//!
//! Each entry point takes the bytes of one input, loads it and, when it loads, uses it a little;
//! it returns [`Outcome::Loaded`], [`Outcome::Refused`] (the loader said no: fine) or a [`Bug`]
//! (non-finite or implausible output from an input that loaded). A panic is a bug too.
//!
//! | entry point | input | when it loads, it… |
//! |---|---|---|
//! | [`lens_toml`], [`lens_zmx`], [`lens_dat`] | a lens file | reports first-order data and `lens info`, traces a fan each way: all finite |
//! | [`lens_lentil_json`] | a lentil database | the same for its first three entries |
//! | [`gltf`] | `.gltf` or `.glb` (external files from `renderer/tests/data/gltf/`) | builds the BVH, casts rays: materials, lights, cameras, hits finite |
//! | [`lrtf`] | an LRTF table of `double-gauss-50mm` (the data checksum is repaired first, so mutations reach the table) | looks rays up: hits finite |
//!
//! Not part of the renderer's API (hidden from its docs); compiled always so that `cargo build`
//! and `cargo test` build the crate with the same features.

use crate::optics::import::{read_prescription_bytes, LensFormat};
use crate::optics::info::lens_info;
use crate::optics::lrtf::{LrtfLookup, LrtfTable};
use crate::scene::gltf::load_gltf_slice;
use crate::scene::{Light, Scene};
use crate::{library_lens, Lens, Ray, RenderScene, TraceDirection};
use glam::{DVec3, Vec3};
use std::cell::{Cell, RefCell};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// What one input did.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// It loaded and its use gave finite, plausible output.
    Loaded,
    /// The loader refused it (with this message): the expected end of most mutations.
    Refused(String),
}

/// A bug: an input that loaded gave non-finite or implausible output.
#[derive(Debug, Clone, PartialEq)]
pub struct Bug(pub String);

impl std::fmt::Display for Bug {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// The result of one entry point on one input.
pub type Verdict = std::result::Result<Outcome, Bug>;

/// `Err(Bug(what))` when `cond`.
pub fn bug_if(cond: bool, what: impl FnOnce() -> String) -> std::result::Result<(), Bug> {
    if cond {
        Err(Bug(what()))
    } else {
        Ok(())
    }
}

/// The repository's root (this crate lives in `renderer/`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."))
}

/// The seed files of `target` listed in `fuzz/seeds.txt` (paths from the repository root).
pub fn seed_files(target: &str) -> Vec<PathBuf> {
    let root = repo_root();
    let list = std::fs::read_to_string(root.join("fuzz/seeds.txt")).unwrap_or_default();
    list.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once(char::is_whitespace))
        .filter(|(t, _)| *t == target)
        .map(|(_, p)| root.join(p.trim()))
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Entry points

/// A TOML lens file (our format).
pub fn lens_toml(data: &[u8]) -> Verdict {
    lens_entry(data, LensFormat::Toml, "fuzz.toml")
}

/// A Zemax `.zmx` file.
pub fn lens_zmx(data: &[u8]) -> Verdict {
    lens_entry(data, LensFormat::Zemax, "fuzz.zmx")
}

/// A pbrt `.dat` table.
pub fn lens_dat(data: &[u8]) -> Verdict {
    lens_entry(data, LensFormat::Pbrt { name: "fuzz" }, "fuzz.dat")
}

/// A lentil JSON database: its first three entries (by the file's own keys; `0001` when the
/// text is not a JSON object). Loaded when any of them loads.
pub fn lens_lentil_json(data: &[u8]) -> Verdict {
    let ids: Vec<String> = match serde_json::from_slice::<serde_json::Value>(data) {
        Ok(serde_json::Value::Object(m)) if !m.is_empty() => m.keys().take(3).cloned().collect(),
        _ => vec!["0001".to_string()],
    };
    let mut first_refusal = None;
    let mut loaded = false;
    for id in &ids {
        match lens_entry(data, LensFormat::Lentil { id }, "fuzz.json") {
            Ok(Outcome::Loaded) => loaded = true,
            Ok(Outcome::Refused(m)) => {
                first_refusal.get_or_insert(m);
            }
            Err(b) => return Err(Bug(format!("entry '{id}': {b}"))),
        }
    }
    Ok(if loaded { Outcome::Loaded } else { Outcome::Refused(first_refusal.unwrap_or_default()) })
}

/// Folder that relative aperture images of a fuzzed TOML lens resolve against.
fn lens_base_dir() -> PathBuf {
    repo_root().join("renderer/optics/lenses")
}

fn lens_entry(data: &[u8], format: LensFormat, file: &str) -> Verdict {
    let lens = match read_prescription_bytes(data, format, file).and_then(|(p, map)| {
        let base = lens_base_dir();
        Lens::new(p, &map, Some(&base))
    }) {
        Ok(l) => l,
        Err(e) => return Ok(Outcome::Refused(e.to_string())),
    };
    use_lens(&lens)?;
    Ok(Outcome::Loaded)
}

/// Uses a loaded lens as `lens info` and a render would: first-order data (finite for a lens
/// that forms an image), the `lens info` report, and a fan of rays each way (every ray that
/// passes is finite).
pub fn use_lens(lens: &Lens) -> std::result::Result<(), Bug> {
    let forms_image = lens.check_forms_image().is_ok();
    if forms_image {
        let p = lens.paraxial();
        for (name, v) in
            [("efl", p.efl_mm), ("f-number", p.f_number), ("entrance pupil diameter", p.entrance_pupil_diameter_mm)]
        {
            bug_if(!v.is_finite(), || format!("{name} {v} of a lens that forms an image"))?;
        }
        for (name, v) in [
            ("bfl", p.bfl_mm),
            ("ffl", p.ffl_mm),
            ("entrance pupil z", p.entrance_pupil_z_mm),
            ("exit pupil z", p.exit_pupil_z_mm),
            ("exit pupil diameter", p.exit_pupil_diameter_mm),
            ("principal plane", p.rear_principal_z_mm),
        ] {
            bug_if(v.is_nan(), || format!("{name} is NaN"))?;
        }
        if let Ok(info) = lens_info(lens, None, None, (36.0, 24.0)) {
            // serde_json writes a non-finite number as null
            for key in ["efl_mm", "f_number", "image_distance_mm", "sensor_z_mm", "widest_f_number"] {
                bug_if(!info[key].is_number(), || format!("lens info: {key} is {} (non-finite)", info[key]))?;
            }
        }
    }
    let wl = lens.primary_wavelength_nm();
    bug_if(!(wl.is_finite() && wl > 0.0), || format!("primary wavelength {wl}"))?;
    let rear = lens.last_vertex_z_mm();
    let film_z = rear + lens.design_back_focus_mm().clamp(-1e6, 1e6);
    let finite = |t: &crate::Traced| t.ray.origin.is_finite() && t.ray.direction.is_finite();
    for k in 0..16 {
        let a = k as f64 * 0.7;
        let r = 0.25 * (k % 4) as f64;
        let o = DVec3::new(0.0, 0.0, film_z);
        let target = DVec3::new(a.cos() * 3.0 * r, a.sin() * 3.0 * r, rear);
        if let Some(t) = lens.trace(&Ray::new(o, target - o), wl, TraceDirection::FilmToScene) {
            bug_if(!finite(&t), || format!("non-finite ray film → scene: {:?}", t.ray))?;
        }
        let o = DVec3::new(0.0, 0.0, -1000.0);
        let target = DVec3::new(a.cos() * 2.0 * r, a.sin() * 2.0 * r, 0.0);
        if let Some(t) = lens.trace(&Ray::new(o, target - o), wl, TraceDirection::SceneToFilm) {
            bug_if(!finite(&t), || format!("non-finite ray scene → film: {:?}", t.ray))?;
        }
    }
    Ok(())
}

/// The folder of the glTF fixtures, against which a fuzzed file's external buffers and
/// textures resolve.
pub fn gltf_dir() -> PathBuf {
    repo_root().join("renderer/tests/data/gltf")
}

/// A `.gltf` or `.glb` file (external files resolve in [`gltf_dir`]).
pub fn gltf(data: &[u8]) -> Verdict {
    let scene = match load_gltf_slice(data, Some(&gltf_dir()), "fuzz.gltf") {
        Ok(s) => s,
        Err(e) => return Ok(Outcome::Refused(e.to_string())),
    };
    use_scene(scene)
}

/// Uses a loaded scene: its numbers are finite, the BVH builds, rays from its cameras and the
/// origin hit finite points.
pub fn use_scene(scene: Scene) -> Verdict {
    check_scene_values(&scene)?;
    let mut origins: Vec<(Vec3, glam::Mat3)> =
        scene.cameras.iter().take(2).map(|c| (c.to_world.translation.into(), c.to_world.matrix3.into())).collect();
    origins.push((Vec3::new(0.0, 0.5, 3.0), glam::Mat3::IDENTITY));
    let rs = match RenderScene::new(scene) {
        Ok(s) => s,
        Err(e) => return Ok(Outcome::Refused(e.to_string())),
    };
    bug_if(rs.triangle_count() > 50_000_000, || format!("implausible triangle count {}", rs.triangle_count()))?;
    for (o, basis) in origins {
        for k in 0..12 {
            let a = k as f32 * 0.9;
            let local = Vec3::new(0.4 * a.cos(), 0.4 * a.sin(), -1.0).normalize();
            let d = (basis * local).normalize_or_zero();
            if d == Vec3::ZERO || !o.is_finite() {
                continue;
            }
            if let Some(h) = rs.intersect(o, d, f32::INFINITY) {
                bug_if(
                    !(h.t.is_finite()
                        && h.position.is_finite()
                        && h.geometric_normal.is_finite()
                        && h.shading_normal.is_finite()
                        && h.uv0.is_finite()),
                    || format!("non-finite hit {h:?}"),
                )?;
            }
        }
    }
    Ok(Outcome::Loaded)
}

/// Every number of a loaded scene that shading uses is finite.
pub fn check_scene_values(scene: &Scene) -> std::result::Result<(), Bug> {
    for m in &scene.materials {
        let ok = m.base_color.is_finite()
            && m.emissive.is_finite()
            && [m.metallic, m.roughness, m.normal_scale, m.specular, m.ior, m.terminator_offset]
                .iter()
                .all(|v| v.is_finite())
            && (0.0..=1.0).contains(&m.transmission);
        bug_if(!ok, || format!("material '{}' has non-finite values: {m:?}", m.name))?;
    }
    for l in &scene.lights {
        let ok = match *l {
            Light::Point { position, intensity, range, radius_m, .. } => {
                position.is_finite() && intensity.is_finite() && range.is_none_or(|r| !r.is_nan()) && radius_m >= 0.0
            }
            Light::Spot { position, direction, intensity, inner_cone_rad, outer_cone_rad, range, radius_m, .. } => {
                position.is_finite()
                    && direction.is_finite()
                    && intensity.is_finite()
                    && inner_cone_rad.is_finite()
                    && outer_cone_rad.is_finite()
                    && range.is_none_or(|r| !r.is_nan())
                    && radius_m >= 0.0
            }
            Light::Directional { direction, irradiance, angle_rad } => {
                direction.is_finite() && irradiance.is_finite() && (0.0..std::f32::consts::PI).contains(&angle_rad)
            }
        };
        bug_if(!ok, || format!("light with non-finite values: {l:?}"))?;
    }
    for c in &scene.cameras {
        bug_if(!(c.to_world.is_finite() && c.yfov_rad.is_finite()), || {
            format!("camera '{}' is non-finite: {c:?}", c.name)
        })?;
    }
    for (i, inst) in scene.instances.iter().enumerate() {
        bug_if(!inst.object_to_world.is_finite(), || format!("instance {i} has a non-finite transform"))?;
    }
    Ok(())
}

/// The lens the LRTF entry point's tables belong to.
pub const LRTF_LENS: &str = "double-gauss-50mm";

fn lrtf_lens() -> &'static Lens {
    static LENS: OnceLock<Lens> = OnceLock::new();
    LENS.get_or_init(|| library_lens(LRTF_LENS).expect("the library lens loads"))
}

/// An LRTF table of [`LRTF_LENS`]. The header's data checksum is recomputed first when the
/// header parses, so that mutations of the table data and header fields reach the checks behind
/// it (a wrong checksum alone is refused, and is tested elsewhere).
pub fn lrtf(data: &[u8]) -> Verdict {
    let lens = lrtf_lens();
    let data = repair_lrtf_checksum(data);
    let table = match LrtfTable::from_bytes(&data, lens, "fuzz.lrtf") {
        Ok(t) => t,
        Err(e) => return Ok(Outcome::Refused(e.to_string())),
    };
    let film_z = lens.last_vertex_z_mm() + lens.design_back_focus_mm();
    for k in 0..24 {
        let a = k as f64 * 0.7;
        let r = 0.3 * (k % 5) as f64;
        let o = DVec3::new(r * 8.0 * a.cos(), r * 8.0 * a.sin(), film_z);
        let d = DVec3::new(0.02 * a.sin(), 0.02 * a.cos(), -1.0);
        for wl in [lens.primary_wavelength_nm(), 450.0, 650.0] {
            if let LrtfLookup::Hit(h) = table.lookup(&Ray::new(o, d), wl) {
                bug_if(
                    !(h.ray.origin.is_finite()
                        && h.ray.direction.is_finite()
                        && h.stop_point.is_finite()
                        && h.margin.is_finite()),
                    || format!("non-finite lookup {h:?}"),
                )?;
            }
        }
    }
    Ok(Outcome::Loaded)
}

/// `data` with the header's `data_checksum` set to the checksum of the data behind the header
/// (unchanged when the header does not parse).
pub fn repair_lrtf_checksum(data: &[u8]) -> Vec<u8> {
    let fix = || -> Option<Vec<u8>> {
        let hlen = u32::from_le_bytes(data.get(12..16)?.try_into().ok()?) as usize;
        let hend = 16usize.checked_add(hlen).filter(|e| *e <= data.len())?;
        let mut header: serde_json::Value = serde_json::from_slice(&data[16..hend]).ok()?;
        let obj = header.as_object_mut()?;
        obj.insert("data_checksum".into(), serde_json::Value::from(crate::optics::lrtf::fnv1a64(&data[hend..])));
        let header = serde_json::to_vec(&header).ok()?;
        let mut out = Vec::with_capacity(data.len() + 8);
        out.extend_from_slice(&data[..12]);
        out.extend_from_slice(&(header.len() as u32).to_le_bytes());
        out.extend_from_slice(&header);
        out.extend_from_slice(&data[hend..]);
        Some(out)
    };
    fix().unwrap_or_else(|| data.to_vec())
}

// ---------------------------------------------------------------------------------------------
// The stable mutation driver

/// SplitMix64: the same inputs on every machine.
#[derive(Debug, Clone)]
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `0..n` (0 for n = 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
    /// `n` random bytes.
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next_u64() as u8).collect()
    }
}

/// Values a number in a text input is replaced by.
pub const EXTREMES: [&str; 22] = [
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-300",
    "0",
    "-0",
    "1e12",
    "-1",
    "4294967296",
    "",
    "1e",
    "--",
    "1e39",
    "3.4e38",
    "-2147483649",
    "18446744073709551616",
    "0.5",
    "2",
    "100",
    "1e-7",
];

/// One mutation of `seed`: 1–4 of bit flips, byte insertions and deletions, duplicated chunks,
/// and (text) numbers replaced by [`EXTREMES`].
pub fn mutate(seed: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        if b.is_empty() {
            b.push(rng.next_u64() as u8);
        }
        match rng.below(7) {
            0 => {
                let k = rng.below(b.len());
                b[k] ^= 1 << rng.below(8);
            }
            1 => {
                let k = rng.below(b.len() + 1);
                b.insert(k, rng.next_u64() as u8);
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

/// `PETZVAL_FUZZ_ITERATIONS`, else `default`.
pub fn iterations(default: usize) -> usize {
    std::env::var("PETZVAL_FUZZ_ITERATIONS").ok().and_then(|v| v.trim().parse().ok()).unwrap_or(default)
}

/// The per-input time limit: an input that takes longer counts as a hang (and fails the run);
/// `PETZVAL_FUZZ_TIME_LIMIT_S` overrides it.
pub fn time_limit(default: Duration) -> Duration {
    std::env::var("PETZVAL_FUZZ_TIME_LIMIT_S")
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .map(Duration::from_secs_f64)
        .unwrap_or(default)
}

/// A failing input of a campaign.
#[derive(Debug, Clone)]
pub struct Failure {
    /// Its index in the campaign.
    pub index: usize,
    /// Panic message, bug, or "hang: N s".
    pub what: String,
    /// Where it was kept.
    pub kept: PathBuf,
}

/// The figures of one campaign.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// Entry point.
    pub name: String,
    /// Inputs run.
    pub inputs: usize,
    /// Inputs that loaded.
    pub loaded: usize,
    /// Inputs the loader refused.
    pub refused: usize,
    /// Inputs that panicked out of the entry point (a crash of the program): must be 0.
    pub panics: usize,
    /// Inputs whose panic a loader's own guard caught and reported as an error (the glTF and USD
    /// loaders guard their dependencies so): not a crash, but a dependency bug, and a crash under
    /// libFuzzer, whose panic hook aborts.
    pub contained_panics: usize,
    /// Inputs slower than the time limit.
    pub hangs: usize,
    /// Inputs that loaded and gave non-finite or implausible output.
    pub bugs: usize,
    /// The per-input time limit.
    pub time_limit: Duration,
    /// The slowest input.
    pub slowest: Duration,
    /// Wall time of the campaign.
    pub wall: Duration,
    /// The failing inputs (kept on disk).
    pub failures: Vec<Failure>,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "fuzz {}: {} inputs, {} loaded, {} refused, {} panics ({} more contained by a loader's guard), {} hangs (> {:.1} s), {} non-finite/implausible outputs; slowest input {:.1} ms, {:.1} s in all",
            self.name,
            self.inputs,
            self.loaded,
            self.refused,
            self.panics,
            self.contained_panics,
            self.hangs,
            self.time_limit.as_secs_f64(),
            self.bugs,
            self.slowest.as_secs_f64() * 1e3,
            self.wall.as_secs_f64()
        )
    }
}

thread_local! {
    static CAPTURING: Cell<bool> = const { Cell::new(false) };
    static PANIC_MESSAGE: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// A panic hook that records the message (with its location) of panics inside a campaign on
/// this thread instead of printing them, and leaves every other panic to the previous hook.
fn install_panic_capture() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if CAPTURING.with(Cell::get) {
                let msg = info
                    .payload()
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| info.payload().downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "(no message)".into());
                let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
                PANIC_MESSAGE.with(|m| *m.borrow_mut() = Some(format!("{msg}{at}")));
            } else {
                previous(info);
            }
        }));
    });
}

/// Where failing inputs of `name` are kept.
pub fn failure_dir(name: &str) -> PathBuf {
    std::env::temp_dir().join("petzval-fuzz-failures").join(name)
}

/// Runs `count` inputs made by `next_input` through `entry`, catching panics and timing each
/// input against `limit`. A watchdog ends the process (after keeping the input) when one input
/// runs for ten times the limit (at least a minute): a real hang would otherwise never return.
/// Failing inputs are written to [`failure_dir`] with the extension `ext`; with
/// `PETZVAL_FUZZ_KEEP_IN_FLIGHT` set, every input is written there (`in-flight.EXT`) before it
/// runs, so the one that aborted the process (an allocation failure) is kept too; with
/// `PETZVAL_FUZZ_DUMP_REFUSED=TEXT`, refused inputs whose message contains TEXT are kept.
pub fn run_campaign(
    name: &str,
    count: usize,
    limit: Duration,
    ext: &str,
    next_input: &mut dyn FnMut(&mut Rng, usize) -> Vec<u8>,
    entry: &dyn Fn(&[u8]) -> Verdict,
) -> Report {
    install_panic_capture();
    let start = Instant::now();
    let mut rng = Rng(0x5EED ^ fnv(name.as_bytes()));
    let mut report = Report { name: name.to_string(), time_limit: limit, ..Report::default() };
    let keep_dir = failure_dir(name);
    let keep_in_flight = std::env::var_os("PETZVAL_FUZZ_KEEP_IN_FLIGHT").is_some();
    // refused inputs whose message contains this are kept too (to find the input behind a class)
    let dump = std::env::var("PETZVAL_FUZZ_DUMP_REFUSED").ok().filter(|d| !d.is_empty());
    let in_flight = keep_dir.join(format!("in-flight.{ext}"));
    if keep_in_flight {
        let _ = std::fs::create_dir_all(&keep_dir);
    }
    // watchdog: the current input and when it started (ms since `start`, u64::MAX = idle)
    let current: Arc<Mutex<Vec<u8>>> = Arc::new(Mutex::new(Vec::new()));
    let started_ms = Arc::new(AtomicU64::new(u64::MAX));
    let done = Arc::new(AtomicBool::new(false));
    let hard = (limit * 10).max(Duration::from_secs(60));
    let watchdog = {
        let (current, started_ms, done, keep_dir, name, ext) =
            (current.clone(), started_ms.clone(), done.clone(), keep_dir.clone(), name.to_string(), ext.to_string());
        std::thread::spawn(move || {
            while !done.load(Ordering::SeqCst) {
                std::thread::sleep(Duration::from_millis(200));
                let s = started_ms.load(Ordering::SeqCst);
                if s != u64::MAX && start.elapsed().as_millis() as u64 > s + hard.as_millis() as u64 {
                    let _ = std::fs::create_dir_all(&keep_dir);
                    let kept = keep_dir.join(format!("hang.{ext}"));
                    if let Ok(input) = current.lock() {
                        let _ = std::fs::write(&kept, &*input);
                    }
                    eprintln!(
                        "fuzz {name}: an input ran for over {} s (kept in {}): ending",
                        hard.as_secs(),
                        kept.display()
                    );
                    std::process::abort();
                }
            }
        })
    };
    for i in 0..count {
        let input = next_input(&mut rng, i);
        if let Ok(mut c) = current.lock() {
            c.clear();
            c.extend_from_slice(&input);
        }
        if keep_in_flight {
            // an abort (allocation failure) ends the process before anything can be kept
            let _ = std::fs::write(&in_flight, &input);
        }
        let t0 = Instant::now();
        started_ms.store(start.elapsed().as_millis() as u64, Ordering::SeqCst);
        CAPTURING.with(|c| c.set(true));
        let result = catch_unwind(AssertUnwindSafe(|| entry(&input)));
        CAPTURING.with(|c| c.set(false));
        started_ms.store(u64::MAX, Ordering::SeqCst);
        let took = t0.elapsed();
        report.slowest = report.slowest.max(took);
        report.inputs += 1;
        // a panic caught inside a loader (the glTF loader turns the gltf crate's panics into
        // errors) is still a panic: under libFuzzer any panic aborts
        let caught = PANIC_MESSAGE.with(|m| m.borrow_mut().take());
        let failure = match (result, caught) {
            (Err(_), msg) => {
                report.panics += 1;
                Some(format!("panic: {}", msg.unwrap_or_else(|| "(on another thread: see stderr)".into())))
            }
            (Ok(_), Some(msg)) => {
                report.contained_panics += 1;
                if report.contained_panics <= 20 {
                    eprintln!("fuzz {name}: input {i}: a loader's guard caught a panic: {msg}");
                }
                None
            }
            (Ok(Ok(Outcome::Loaded)), None) => {
                report.loaded += 1;
                None
            }
            (Ok(Ok(Outcome::Refused(m))), None) => {
                report.refused += 1;
                if dump.as_deref().is_some_and(|d| m.contains(d)) {
                    let _ = std::fs::create_dir_all(&keep_dir);
                    let _ = std::fs::write(keep_dir.join(format!("refused-{i}.{ext}")), &input);
                    eprintln!("fuzz {name}: input {i} refused: {m}");
                }
                None
            }
            (Ok(Err(bug)), None) => {
                report.bugs += 1;
                Some(format!("bug: {bug}"))
            }
        };
        let failure = match failure {
            None if took > limit => {
                report.hangs += 1;
                Some(format!("hang: {:.2} s (limit {:.2} s)", took.as_secs_f64(), limit.as_secs_f64()))
            }
            f => f,
        };
        if let Some(what) = failure {
            let _ = std::fs::create_dir_all(&keep_dir);
            let kept = keep_dir.join(format!("case-{i}.{ext}"));
            let _ = std::fs::write(&kept, &input);
            eprintln!("fuzz {name}: input {i}: {what} (kept in {})", kept.display());
            report.failures.push(Failure { index: i, what, kept });
        }
    }
    done.store(true, Ordering::SeqCst);
    let _ = watchdog.join();
    report.wall = start.elapsed();
    report
}

/// Runs `entry` on one kept input (a regression case): `Err` with what went wrong on a panic
/// or a bug.
pub fn check_case(entry: &dyn Fn(&[u8]) -> Verdict, input: &[u8]) -> std::result::Result<Outcome, String> {
    install_panic_capture();
    CAPTURING.with(|c| c.set(true));
    let result = catch_unwind(AssertUnwindSafe(|| entry(input)));
    CAPTURING.with(|c| c.set(false));
    match (result, PANIC_MESSAGE.with(|m| m.borrow_mut().take())) {
        (Ok(Ok(o)), None) => Ok(o),
        (Ok(Err(b)), None) => Err(format!("bug: {b}")),
        (_, msg) => Err(format!("panic: {}", msg.unwrap_or_else(|| "(on another thread: see stderr)".into()))),
    }
}

/// Mutations of the seeds, in turn: input `i` mutates seed `i mod seeds`.
pub fn mutations_of(seeds: Vec<Vec<u8>>) -> impl FnMut(&mut Rng, usize) -> Vec<u8> {
    assert!(!seeds.is_empty(), "no seeds");
    move |rng, i| mutate(&seeds[i % seeds.len()], rng)
}

fn fnv(bytes: &[u8]) -> u64 {
    crate::optics::lrtf::fnv1a64(bytes)
}
