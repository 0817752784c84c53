//! The command line's fuzzing entry point (issue 12), shared by the bounded run in the CLI's test
//! binary (`tests/cli/fuzz.rs`) and the cargo-fuzz target `fuzz/fuzz_targets/cli_flags.rs`; the
//! driver and the conventions ([`Outcome`], [`Bug`]) are `petzval_renderer::fuzzing`'s.
//!
//! [`cli_flags`] turns its bytes into a command line ([`argv_from_bytes`]: a subcommand, then up
//! to eight real flags of `petzval render`, each with a value drawn from values that flag takes
//! and from extremes — `nan`, `inf`, `1e300`, `-1`, huge integers, empty strings, Unicode, paths
//! to folders, devices, missing and foreign files — or raw bytes), and [`check_argv`] parses it
//! with the real clap definitions and runs every check `petzval render` makes before loading
//! anything ([`crate::render_cmd::preflight`]). Accepted = [`Outcome::Loaded`]. It must never
//! panic; that an accepted command line renders is checked on a sample by [`render_small`].
//!
//! Not part of the crate's API (hidden from its docs).

use crate::render_cmd::{self, RenderArgs};
use crate::{Cli, Command};
use clap::Parser;
use petzval_renderer::fuzzing::{repo_root, Bug, Outcome, Verdict};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The kind of value a flag takes (which list its values come from).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// A real number.
    Float,
    /// A whole number.
    Int,
    /// `--resolution`.
    Resolution,
    /// A lens name or file.
    Lens,
    /// `--lens-model`.
    LensModel,
    /// `--aperture`.
    Aperture,
    /// `-o`.
    OutExr,
    /// `--png`.
    OutPng,
    /// `--lrtf-file`.
    LrtfFile,
    /// `--tonemap`.
    Tonemap,
    /// `--aovs`.
    Aovs,
    /// `--natural-vignetting`.
    OnOff,
    /// `--frames`.
    Frames,
    /// `--environment`.
    Environment,
    /// `--camera`, `--settings`.
    Name,
    /// `--data-window`.
    DataWindow,
    /// `--aspect-conform`.
    Conform,
    /// `--purposes`.
    Purposes,
    /// A flag without a value.
    Switch,
    /// The scene (positional).
    Scene,
}

/// The flags of `petzval render` (and a few that are not), with the kind of value each takes.
const FLAGS: &[(&str, Kind)] = &[
    ("-o", Kind::OutExr),
    ("--output", Kind::OutExr),
    ("--png", Kind::OutPng),
    ("--no-png", Kind::Switch),
    ("--lens", Kind::Lens),
    ("--lens-model", Kind::LensModel),
    ("--tolerance", Kind::Float),
    ("--lrtf-file", Kind::LrtfFile),
    ("--fstop", Kind::Float),
    ("--focus", Kind::Float),
    ("--tilt-x", Kind::Float),
    ("--tilt-y", Kind::Float),
    ("--shift-x", Kind::Float),
    ("--shift-y", Kind::Float),
    ("--aperture", Kind::Aperture),
    ("--focal-length", Kind::Float),
    ("--ortho-scale", Kind::Float),
    ("--pixel-aspect", Kind::Float),
    ("--sensor-width", Kind::Float),
    ("--spp", Kind::Int),
    ("--resolution", Kind::Resolution),
    ("--seed", Kind::Int),
    ("--threads", Kind::Int),
    ("--time-limit", Kind::Float),
    ("--camera", Kind::Name),
    ("--frame", Kind::Float),
    ("--fps", Kind::Float),
    ("--frames", Kind::Frames),
    ("--settings", Kind::Name),
    ("--environment", Kind::Environment),
    ("--environment-strength", Kind::Float),
    ("--max-depth", Kind::Int),
    ("--spectral", Kind::Switch),
    ("--exposure", Kind::Float),
    ("--tonemap", Kind::Tonemap),
    ("--aovs", Kind::Aovs),
    ("--natural-vignetting", Kind::OnOff),
    ("--filter-width", Kind::Float),
    ("--data-window", Kind::DataWindow),
    ("--aspect-conform", Kind::Conform),
    ("--purposes", Kind::Purposes),
    ("--no-dof", Kind::Switch),
    ("SCENE", Kind::Scene),
    ("--no-such-flag", Kind::Float),
    ("-x", Kind::Switch),
    ("--", Kind::Scene),
    ("--help", Kind::Switch),
];

/// `--data-window`: crops, overscan, edges through pixel centres, empty, inverted, too far.
const DATA_WINDOWS: &[&str] = &[
    "0,0,1,1",
    "0.25,0.25,0.75,0.75",
    "-0.25,-0.25,1.25,1.25",
    "0.5,0,0.5,1",
    "1,1,0,0",
    "0.3,0,0.31,1",
    "-4,-4,5,5",
    "-5,0,1,1",
    "0,0,1",
    "0,0,1,1,1",
    "a,b,c,d",
    "nan,0,1,1",
    "0,0,inf,1",
    "0.999,0.999,1,1",
];

/// `--aspect-conform`: UsdRender's tokens and near misses.
const CONFORMS: &[&str] = &[
    "expandAperture",
    "cropAperture",
    "adjustApertureWidth",
    "adjustApertureHeight",
    "adjustPixelAspectRatio",
    "expand",
    "CROPAPERTURE",
];

/// `--purposes`.
const PURPOSES: &[&str] =
    &["default,render", "proxy", "default,proxy,guide", "render", "", ",", "final", "default,,render"];

/// Numbers: typical values of the flags and extremes.
const FLOATS: &[&str] = &[
    "0.5", "1", "1.4", "2", "2.8", "4", "8", "16", "22", "0.25", "3", "10", "-3", "-10", "45", "59", "60", "61", "100",
    "1000", "1e6", "0.001", "0.1", "5", "-5", "36", "24", "1.5",
];

/// Whole numbers.
const INTS: &[&str] = &["0", "1", "2", "3", "4", "8", "16", "64", "255", "256", "1024", "1025", "007", "5"];

/// Values no flag should take quietly.
const EXTREMES: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "infinity",
    "-0",
    "0",
    "1e300",
    "-1e300",
    "1e-300",
    "5e-324",
    "1e39",
    "-1e39",
    "3.4e38",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "-2147483649",
    "",
    "1e",
    " 2",
    "2 ",
    "+2",
    "0x10",
    "1_0",
    "2,8",
    "٣",
    "1e-7",
    "-1e-7",
    "9007199254740993",
];

const RESOLUTIONS: &[&str] = &[
    "16x12",
    "24x16",
    "1x1",
    "2x1",
    "1x2",
    "32x32",
    "12x24",
    "960x640",
    "0x0",
    "0x10",
    "10x0",
    "x",
    "16",
    "16x",
    "x16",
    "16x12x3",
    "-1x5",
    "16X12",
    " 16 x 12 ",
    "4294967295x1",
    "4294967296x1",
    "100000x100000",
    "10001x10000",
    "65536x65536",
    "1x100000000",
    "１６x１２",
];

const LENS_MODELS: &[&str] = &[
    "auto",
    "exact",
    "thick",
    "thin",
    "pinhole",
    "lrtf:8",
    "lrtf:16",
    "lrtf",
    "lrtf:32",
    "lrtf:7",
    "lrtf:257",
    "lrtf:0",
    "lrtf:-1",
    "lrtf:",
    "lrtf:4294967296",
    "AUTO",
    "",
    "lrtf:nan",
];

const TONEMAPS: &[&str] = &["srgb", "filmic", "SRGB", "", "aces"];
const AOVS: &[&str] =
    &["depth", "normal", "albedo", "depth,normal,albedo", "", "depth,,normal", " depth ", "z", "depth,depth"];
const ON_OFF: &[&str] = &["on", "off", "ON", "yes", ""];
const FRAMES: &[&str] = &[
    "1-3",
    "1001-1010",
    "1-100x5",
    "-5--1",
    "3-1",
    "1-1",
    "1-100001",
    "1-3x0",
    "1-3x-1",
    "x",
    "",
    "1-",
    "-",
    "9223372036854775807-9223372036854775807",
    "-9223372036854775808-9223372036854775807",
    "1-3x9223372036854775807",
];
const NAMES: &[&str] = &["Camera", "Camera.001", "", "/Cam", "/World/Cam", "/Render/Settings", "nonexistent", "/"];
const UNICODE: &[&str] = &["é", "日本語", "\u{202e}abc", "\u{0}", "\u{feff}1", "🙂", "\n", "-", "--", "=", " "];

/// Files and folders the flag values point at: a folder of this process's own, with files of
/// every kind the flags read (and some they must refuse).
pub struct Fixtures {
    /// The folder.
    pub dir: PathBuf,
}

/// The fixtures, made on first use: `sub/` (a folder), `existing.exr` (an empty file),
/// `sub.exr/` (a folder named like an EXR), `dg.lrtf` (a table of `double-gauss-50mm`) and
/// `env.exr` (a small environment map).
pub fn fixtures() -> &'static Fixtures {
    static F: OnceLock<Fixtures> = OnceLock::new();
    F.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("petzval-fuzz-cli-{}", std::process::id()));
        let _ = std::fs::create_dir_all(dir.join("sub"));
        let _ = std::fs::create_dir_all(dir.join("sub.exr"));
        let _ = std::fs::write(dir.join("existing.exr"), b"");
        let lens = petzval_renderer::library_lens("double-gauss-50mm").expect("library lens");
        let options = petzval_renderer::optics::lrtf::BakeOptions { resolution: 8, ..Default::default() };
        if let Ok(t) = petzval_renderer::optics::lrtf::LrtfTable::bake(&lens, &options, &|_| {}) {
            let _ = t.save(&dir.join("dg.lrtf"));
        }
        let n = 8 * 4;
        let env = petzval_renderer::film::Image {
            width: 8,
            height: 4,
            rgba: (0..n).map(|i| [0.2 + 0.05 * (i % 8) as f32, 0.3, 0.4, 1.0]).collect(),
            depth: vec![1.0; n],
            normal: vec![[0.0, 0.0, 1.0]; n],
            albedo: vec![[0.5; 3]; n],
        };
        let no_layers = petzval_renderer::film::ExrLayers { depth: false, normal: false, albedo: false };
        let _ = petzval_renderer::film::write_exr(&dir.join("env.exr"), &env, no_layers, &Vec::new());
        Fixtures { dir }
    })
}

impl Fixtures {
    fn path(&self, rel: &str) -> String {
        self.dir.join(rel).display().to_string()
    }
}

fn repo(rel: &str) -> String {
    repo_root().join(rel).display().to_string()
}

/// The values of `kind` (files and folders as paths).
fn values(kind: Kind) -> Vec<String> {
    let f = fixtures();
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    match kind {
        Kind::Float => s(FLOATS),
        Kind::Int => s(INTS),
        Kind::Resolution => s(RESOLUTIONS),
        Kind::LensModel => s(LENS_MODELS),
        Kind::Tonemap => s(TONEMAPS),
        Kind::Aovs => s(AOVS),
        Kind::OnOff => s(ON_OFF),
        Kind::Frames => s(FRAMES),
        Kind::DataWindow => s(DATA_WINDOWS),
        Kind::Conform => s(CONFORMS),
        Kind::Purposes => s(PURPOSES),
        Kind::Name => s(NAMES),
        Kind::Switch => vec![String::new()],
        Kind::Lens => {
            let mut v = s(&[
                "thin",
                "pinhole",
                "double-gauss-50mm",
                "fisheye-10mm",
                "aspheric-fisheye-10mm",
                "telephoto-250mm",
                "wide-22mm",
                "schneider-anamorphic-31mm",
                "biconvex-singlet-50mm",
                "THIN",
                "nonexistent-lens",
                "",
                "/dev/zero",
                "/dev/null",
                "/",
            ]);
            v.extend([
                repo("renderer/optics/lenses/cooke-speed-panchro-25mm.toml"),
                repo("renderer/optics/tests/data/zmx/double_gauss.zmx"),
                repo("renderer/optics/tests/data/pbrt/wide.22mm.dat"),
                repo("renderer/optics/tests/data/lentil/lentil-subset.json#0001"),
                repo("renderer/optics/tests/data/lentil/lentil-subset.json#9999"),
                repo("renderer/tests/data/gltf/box.glb"),
                f.path("sub"),
                f.path("missing.toml"),
                f.path("existing.exr"),
            ]);
            v
        }
        Kind::Aperture => {
            let mut v = s(&[
                "circle",
                "blades:6",
                "blades:3",
                "blades:2",
                "blades:0",
                "blades:5:15",
                "blades:5:nan",
                "blades:5:inf",
                "blades:5:1e300",
                "blades:6:10:3",
                "blades:",
                "blades:4294967296",
                "blades:1000000",
                "image:",
                "image:/dev/zero",
                "square",
                "",
            ]);
            v.extend([
                format!("image:{}", repo("renderer/tests/data/gltf/checker.png")),
                format!("image:{}", f.path("missing.png")),
                format!("image:{}", f.path("sub")),
                format!("image:{}", f.path("env.exr")),
                format!("image:{}", f.path("existing.exr")),
            ]);
            v
        }
        Kind::OutExr => {
            let mut v: Vec<String> = [
                "out.exr",
                "sub/out.exr",
                "missing/out.exr",
                "sub",
                "out.png",
                "out.####.exr",
                "out.EXR",
                ".exr",
                "é日本.exr",
                "existing.exr",
                "sub.exr",
            ]
            .iter()
            .map(|r| f.path(r))
            .collect();
            v.extend(s(&["", "/", "/dev/null", "/dev/zero.exr", "x.exr/"]));
            v
        }
        Kind::OutPng => {
            let mut v: Vec<String> = ["out.png", "out.exr", "sub", "missing/x.png", "é.png", "out.####.png"]
                .iter()
                .map(|r| f.path(r))
                .collect();
            v.extend(s(&["", "/dev/null", "/"]));
            v
        }
        Kind::LrtfFile => {
            let mut v: Vec<String> =
                ["dg.lrtf", "missing.lrtf", "existing.exr", "sub"].iter().map(|r| f.path(r)).collect();
            v.extend(s(&["/dev/zero", ""]));
            v
        }
        Kind::Environment => {
            let mut v = s(&[
                "0.5",
                "1,1,1",
                "0.2,0.3,0.4",
                "-1",
                "nan",
                "inf,0,0",
                "1,2",
                "1e39",
                "1,1,1,1",
                "",
                "/dev/zero.exr",
            ]);
            v.extend(["env.exr", "missing.exr", "existing.exr", "sub.exr"].iter().map(|r| f.path(r)));
            v
        }
        Kind::Scene => {
            let mut v = vec![
                repo("renderer/tests/data/gltf/box.glb"),
                repo("renderer/tests/data/gltf/camera.gltf"),
                repo("usd/tests/data/fuzz/seeds/shot.usda"),
                f.path("missing.glb"),
                f.path("missing.usda"),
                f.path("sub"),
            ];
            v.extend(s(&["/dev/zero", "", "scene.txt"]));
            v
        }
    }
}

/// Every kind, in the order of [`value_table`].
const KINDS: [Kind; 20] = [
    Kind::Float,
    Kind::Int,
    Kind::Resolution,
    Kind::Lens,
    Kind::LensModel,
    Kind::Aperture,
    Kind::OutExr,
    Kind::OutPng,
    Kind::LrtfFile,
    Kind::Tonemap,
    Kind::Aovs,
    Kind::OnOff,
    Kind::Frames,
    Kind::Environment,
    Kind::Name,
    Kind::Switch,
    Kind::Scene,
    Kind::DataWindow,
    Kind::Conform,
    Kind::Purposes,
];

/// The values of every kind, made once.
fn value_table() -> &'static Vec<Vec<String>> {
    static T: OnceLock<Vec<Vec<String>>> = OnceLock::new();
    T.get_or_init(|| KINDS.iter().map(|k| values(*k)).collect())
}

/// `kind`'s row of [`value_table`] (every kind has one: `every_kind_has_its_values`).
fn kind_index(kind: Kind) -> usize {
    KINDS.iter().position(|k| *k == kind).unwrap_or(0)
}

/// Reads the input one byte at a time (0 once it runs out).
struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Bytes<'_> {
    fn next(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }
    fn pick<'v>(&mut self, v: &'v [String]) -> &'v str {
        if v.is_empty() {
            return "";
        }
        let i = (usize::from(self.next()) << 8 | usize::from(self.next())) % v.len();
        &v[i]
    }
    fn more(&self) -> bool {
        self.pos < self.data.len()
    }
}

/// The command line `data` describes (see the module docs); `argv[0]` is `petzval`.
pub fn argv_from_bytes(data: &[u8]) -> Vec<String> {
    let mut b = Bytes { data, pos: 0 };
    let table = value_table();
    let mut argv = vec!["petzval".to_string()];
    match b.next() % 32 {
        28 => argv.extend(["lens".into(), "info".into()]),
        29 => argv.extend(["lrtf".into(), "bake".into()]),
        30 => argv.extend(["usd".into(), "info".into()]),
        31 => {}
        _ => argv.push("render".into()),
    }
    let n = b.next() % 9;
    for _ in 0..n {
        if !b.more() {
            break;
        }
        let (flag, kind) = FLAGS[usize::from(b.next()) % FLAGS.len()];
        let value = match b.next() % 10 {
            0..=5 => b.pick(&table[kind_index(kind)]).to_string(),
            6 => EXTREMES[usize::from(b.next()) % EXTREMES.len()].to_string(),
            7 => UNICODE[usize::from(b.next()) % UNICODE.len()].to_string(),
            8 => b.pick(&table[kind_index(Kind::Float)]).to_string(),
            _ => {
                let len = usize::from(b.next() % 12);
                let raw: Vec<u8> = (0..len).map(|_| b.next()).collect();
                String::from_utf8_lossy(&raw).into_owned()
            }
        };
        let switch = kind == Kind::Switch;
        match (b.next() % 8, switch, flag) {
            (_, _, "SCENE") => argv.push(value),
            (_, true, _) => argv.push(flag.to_string()),
            (0..=4, _, _) => argv.extend([flag.to_string(), value]),
            (5, _, _) => argv.push(format!("{flag}={value}")),
            (6, _, _) => argv.push(flag.to_string()),
            _ => argv.push(value),
        }
    }
    argv
}

/// Parses `argv` with the real clap definitions; for `render`, runs every check before loading
/// ([`render_cmd::check_flags`]). `Loaded` = accepted.
pub fn check_argv(argv: &[String]) -> Verdict {
    let cli = match Cli::try_parse_from(argv) {
        Ok(c) => c,
        Err(e) => return Ok(Outcome::Refused(e.kind().to_string())),
    };
    match cli.command {
        Command::Render(args) => match render_cmd::check_flags(*args) {
            Ok(()) => Ok(Outcome::Loaded),
            Err(e) => {
                // a NaN in the message that the command line did not contain was computed: the
                // error reports garbage instead of naming the problem ("cannot focus … (NaN m)")
                let msg = e.to_string();
                let typed = argv.iter().any(|a| a.to_ascii_lowercase().contains("nan"));
                if msg.contains("NaN") && !typed {
                    return Err(Bug(format!("an error reports a computed NaN: {msg}")));
                }
                Ok(Outcome::Refused(msg))
            }
        },
        // the other subcommands: parsing only (running them is their own work)
        _ => Ok(Outcome::Loaded),
    }
}

/// The flag fuzzer's entry point: [`argv_from_bytes`] then [`check_argv`].
pub fn cli_flags(data: &[u8]) -> Verdict {
    check_argv(&argv_from_bytes(data))
}

/// Why [`render_small`] did not render.
#[derive(Debug, Clone, PartialEq)]
pub enum NotRendered {
    /// Not a render of the built-in demo, or costly (an LRTF bake above 32³): not spot-checked.
    Skipped(String),
    /// Accepted, but refused once shrunk to the spot check's size (by the checks, not a bug).
    ShrunkRefused(String),
    /// Accepted by the checks, then failed while rendering: a bug.
    Failed(String),
}

/// Renders an accepted `render` command line of the built-in demo small (the long side 24 px,
/// 1 sample, path depth ≤ 3, one thread's worth of work) into `out_dir`, through the real
/// `petzval render` code; returns the EXR written. The flags that only name outputs, the time
/// limit and the thread count are replaced; everything else is as given.
pub fn render_small(argv: &[String], out_dir: &Path) -> Result<PathBuf, NotRendered> {
    let cli = Cli::try_parse_from(argv).map_err(|e| NotRendered::Skipped(format!("does not parse: {}", e.kind())))?;
    let Command::Render(args) = cli.command else { return Err(NotRendered::Skipped("not a render".into())) };
    let mut args: RenderArgs = *args;
    if args.scene.is_some() {
        return Err(NotRendered::Skipped("a scene file, not the demo".into()));
    }
    if args.camera.is_some() {
        return Err(NotRendered::Skipped("--camera names a scene camera (checked when the scene loads)".into()));
    }
    if args.lens_model.strip_prefix("lrtf:").and_then(|r| r.parse::<u32>().ok()).is_some_and(|r| r > 32)
        || (args.lrtf_file.is_none() && args.lens_model == "lrtf")
    {
        return Err(NotRendered::Skipped("bakes a large LRTF table".into()));
    }
    let (w, h) = render_cmd::parse_resolution(&args.resolution).map_err(|e| NotRendered::Skipped(e.to_string()))?;
    let long = w.max(h).max(1) as f64;
    let scale = (24.0 / long).min(1.0);
    let (w, h) = (((w as f64 * scale).round() as u32).max(1), ((h as f64 * scale).round() as u32).max(1));
    args.resolution = format!("{w}x{h}");
    args.spp = 1;
    args.max_depth = args.max_depth.min(3);
    args.time_limit = None;
    args.threads = None;
    args.frames = None;
    args.frame = None;
    args.output = out_dir.join("spot.exr");
    args.png = None;
    args.no_png = true;
    render_cmd::check_flags(args.clone()).map_err(|e| NotRendered::ShrunkRefused(e.to_string()))?;
    let _ = std::fs::remove_file(&args.output);
    let out = args.output.clone();
    render_cmd::run(args).map_err(|e| NotRendered::Failed(e.to_string()))?;
    if !out.is_file() {
        return Err(NotRendered::Failed(format!("{} was not written", out.display())));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every flag's kind has its own row of values: a kind missing from `KINDS` would silently
    /// draw the numbers' row.
    #[test]
    fn every_kind_has_its_values() {
        for (flag, kind) in FLAGS {
            assert!(KINDS.contains(kind), "{flag}: its kind is not in KINDS");
        }
    }
}
