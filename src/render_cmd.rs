//! `petzval render`: scene file (or the built-in demo) → camera → integrator → film → EXR/PNG.

use clap::Args;
use glam::{DAffine3, DVec2};
use indicatif::{ProgressBar, ProgressStyle};
use petzval_renderer::camera::host::{self, ConformPolicy, FilmBack, HostCamera, SensorFit, Shift};
use petzval_renderer::film::{
    write_exr_framed, write_png, ExrFrame, ExrLayers, Metadata, PixelFilter, PixelWindow, ToneMap,
};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{CameraRig, RenderSettings};
use petzval_renderer::scene::{demo, gltf, Environment, Scene, SceneCamera};
use petzval_renderer::shot;
use petzval_renderer::{bokeh, dof};
use petzval_renderer::{Aperture, ApertureShape, Camera, Error, LensModel};
use std::path::PathBuf;
use std::time::Duration;

/// Options of `petzval render`.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// Scene file (.gltf, .glb, or a USD shot: .usd, .usda, .usdc, .usdz). Without one, the
    /// built-in demo is rendered.
    pub scene: Option<PathBuf>,
    /// Output EXR file.
    #[arg(short, long, default_value = DEFAULT_OUTPUT)]
    pub output: PathBuf,
    /// Also write a PNG preview (default: the EXR path with .png).
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Do not write the PNG preview.
    #[arg(long)]
    pub no_png: bool,
    /// Lens: a library name, a lens file, `thin` or `pinhole` (default: thin for scene files, the demo's lens for the demo).
    #[arg(long)]
    pub lens: Option<String>,
    /// Lens model: auto (the cheapest model within --tolerance of the exact trace at this
    /// resolution), exact (trace every surface), lrtf[:RESOLUTION] (a ray transfer table,
    /// default resolution 96), thick, thin or pinhole.
    #[arg(long, default_value = "auto")]
    pub lens_model: String,
    /// Error budget of --lens-model auto, in pixels at the render's resolution.
    #[arg(long, default_value_t = 0.25)]
    pub tolerance: f64,
    /// Use this baked LRTF table (`petzval lrtf bake`) with --lens-model lrtf.
    #[arg(long)]
    pub lrtf_file: Option<PathBuf>,
    /// f-number (default: 2.8 for thin, the lens's own for real lenses).
    #[arg(long)]
    pub fstop: Option<f64>,
    /// Focus distance in metres from the camera (default: autofocus on the image centre).
    #[arg(long)]
    pub focus: Option<f64>,
    /// Sensor tilt about the horizontal axis (degrees) [default: 0; the built-in demo's own
    /// −6° without a scene file; a USD camera's own].
    #[arg(long, allow_hyphen_values = true)]
    pub tilt_x: Option<f64>,
    /// Sensor tilt about the vertical axis (degrees) [default: 0, or a USD camera's own].
    #[arg(long, allow_hyphen_values = true)]
    pub tilt_y: Option<f64>,
    /// Sensor shift right (mm).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub shift_x: f64,
    /// Sensor shift up (mm).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub shift_y: f64,
    /// Aperture: circle, blades:N[:ROTATION_DEG] or image:PATH.
    #[arg(long)]
    pub aperture: Option<String>,
    /// Focal length for thin/pinhole (default: from the scene camera's field of view).
    #[arg(long)]
    pub focal_length: Option<f64>,
    /// Orthographic camera spanning this many metres across the larger image side (Blender's
    /// Orthographic Scale) [default: a glTF or USD orthographic camera's own; else perspective].
    #[arg(long)]
    pub ortho_scale: Option<f64>,
    /// Pixel aspect ratio, width over height of one pixel (default 1, or a USD shot's
    /// RenderSettings `pixelAspectRatio`).
    #[arg(long)]
    pub pixel_aspect: Option<f64>,
    /// Sensor width (mm); spans the larger image dimension.
    #[arg(long, default_value_t = 36.0)]
    pub sensor_width: f64,
    /// Samples per pixel.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Resolution WxH.
    #[arg(long, default_value = DEFAULT_RESOLUTION)]
    pub resolution: String,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Stop after this many seconds (the last pass finishes first).
    #[arg(long)]
    pub time_limit: Option<f64>,
    /// Scene camera by name, or a USD camera prim path (default: the first).
    #[arg(long)]
    pub camera: Option<String>,
    /// Frame to render: a USD time code (default: the stage's startTimeCode, else the default
    /// values), or for glTF the node animations at FRAME / --fps seconds (as Blender's exporter
    /// writes frame F at F / fps; default: the nodes' own transforms).
    #[arg(long, allow_hyphen_values = true)]
    pub frame: Option<f64>,
    /// Frames per second of a glTF file's animation (glTF stores seconds): --frame F renders
    /// its nodes at F / FPS seconds. Blender's default scene rate is 24.
    #[arg(long, default_value_t = 24.0)]
    pub fps: f64,
    /// Catmull-Clark levels for USD meshes whose subdivisionScheme is catmullClark (Blender's
    /// "Best Match" export of a Subdivision modifier); 0 renders the cage.
    #[arg(long, default_value_t = petzval_usd::subdiv::DEFAULT_LEVEL, value_parser = clap::value_parser!(u32).range(0..=8))]
    pub subdivision_level: u32,
    /// Frames START-END[xSTEP] (inclusive; USD time codes, or glTF frames as --frame),
    /// rendered one after another; `-o` names each
    /// frame with a run of `#` (`out.####.exr` → `out.1001.exr`).
    #[arg(long)]
    pub frames: Option<String>,
    /// The pixels to render, in normalised device coordinates XMIN,YMIN,XMAX,YMAX ((0,0) the
    /// frame's bottom-left corner, (1,1) its top-right; a pixel is in when its centre is), as
    /// UsdRender's dataWindowNDC: a crop inside 0,0,1,1, overscan beyond it. The EXR's data
    /// window holds them in the frame's display window (default: a USD shot's dataWindowNDC,
    /// else the whole frame).
    #[arg(long, allow_hyphen_values = true)]
    pub data_window: Option<String>,
    /// How a USD camera's aperture is fitted to the image's aspect: expandAperture,
    /// cropAperture, adjustApertureWidth, adjustApertureHeight or adjustPixelAspectRatio
    /// (UsdRender's aspectRatioConformPolicy; default: the shot's, else expandAperture).
    #[arg(long)]
    pub aspect_conform: Option<String>,
    /// The USD geometry purposes rendered, comma-separated among default, render, proxy and
    /// guide (default: a USD shot's includedPurposes, else default,render).
    #[arg(long)]
    pub purposes: Option<String>,
    /// No depth of field (UsdRender's disableDepthOfField, which a USD shot's settings may also
    /// ask for): a thin lens renders as a pinhole; a real lens keeps its stop (noted).
    #[arg(long)]
    pub no_dof: bool,
    /// USD RenderSettings prim (default: the stage's renderSettingsPrimPath): its camera,
    /// resolution and first product's productName, unless --camera, --resolution or -o say
    /// otherwise.
    #[arg(long)]
    pub settings: Option<String>,
    /// Environment: R,G,B radiance or an equirectangular .exr.
    #[arg(long)]
    pub environment: Option<String>,
    /// Environment strength multiplier.
    #[arg(long, default_value_t = 1.0)]
    pub environment_strength: f32,
    /// Maximum path depth.
    #[arg(long, default_value_t = 8)]
    pub max_depth: u32,
    /// Trace one wavelength per camera ray (lens dispersion); default: on only for dispersive lenses with --spectral.
    #[arg(long)]
    pub spectral: bool,
    /// PNG exposure in stops.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f32,
    /// PNG tone mapping.
    #[arg(long, default_value = "srgb")]
    pub tonemap: String,
    /// Extra EXR channels: comma-separated depth,normal,albedo (default: depth, or what a USD
    /// shot's RenderVars ask for).
    #[arg(long)]
    pub aovs: Option<String>,
    /// Natural vignetting (cos⁴) for thin and pinhole cameras: on (physical) or off (as Cycles).
    #[arg(long, default_value = "on")]
    pub natural_vignetting: String,
    /// Pixel filter width as Blender's filter_width: a Blackman–Harris filter spanning twice
    /// this many pixels, as Cycles does (0 = a 1-pixel box).
    #[arg(long, default_value_t = 1.5)]
    pub filter_width: f32,
    /// Bokeh light paths: light traced from emissive surfaces through the lens onto the film,
    /// this many per pixel per sample, combined with camera paths by MIS so that small bright
    /// defocused emitters converge (any lens model, not the pinhole; --method mc; 0 = off).
    /// They serve emitters small against their blur, by the share the lens sees; large, nearly
    /// sharp emitters are left to camera paths. auto: 1 where the camera has a lens and the scene has emissive
    /// surfaces, else 0.
    #[arg(long, default_value = "auto")]
    pub bokeh_paths: String,
    /// Adaptive sampling's noise threshold, as Cycles' "Noise Threshold" (same test, same
    /// scale, same schedule): a pixel stops taking samples once its error estimate over its 3×3
    /// neighbourhood passes, tested every 16 samples from just past --adaptive-min-samples;
    /// --spp becomes the most a pixel takes. 0 = off (--method mc only).
    #[arg(long, default_value_t = 0.0)]
    pub adaptive_threshold: f32,
    /// Samples every pixel takes before adaptive sampling may stop it (0 = auto, as Cycles:
    /// max(4, ⌈16 / threshold^0.3⌉), 64 at 0.01).
    #[arg(long, default_value_t = 0)]
    pub adaptive_min_samples: u32,
    /// Depth-of-field method: mc (Monte Carlo through the lens, the reference), multiview
    /// (pinhole views through pupil samples), ibrt (rays traced against depth-peeled layers) or
    /// spread (PSFs spread from the layers). --spp stays the camera rays per pixel.
    #[arg(long, default_value = "mc")]
    pub method: String,
    /// Depth-peeled layers of the preview methods (ibrt, spread, multiview's shading).
    #[arg(long, default_value_t = 4)]
    pub layers: usize,
    /// Path samples per texel and layer when the preview methods shade their layers.
    #[arg(long, default_value_t = 4)]
    pub layer_spp: u32,
    /// Layer texels across one image pixel (1..=4).
    #[arg(long, default_value_t = 2)]
    pub layer_texels: u32,
    /// Extra layer frame on each side, as a fraction of the image's (room for blur from outside
    /// the frame).
    #[arg(long, default_value_t = 0.15)]
    pub layer_margin: f64,
}

/// The depth-of-field method and its preview settings, checked.
fn method_settings(args: &RenderArgs) -> Result<(dof::Method, dof::PreviewSettings), Error> {
    let method: dof::Method = args.method.parse()?;
    let layers = dof::LayerSettings {
        count: args.layers,
        spp: args.layer_spp,
        margin: args.layer_margin,
        texels_per_pixel: args.layer_texels,
        ..dof::LayerSettings::default()
    };
    layers.validate()?;
    Ok((method, dof::PreviewSettings { layers }))
}

fn settings_err(field: &str, message: String) -> Error {
    Error::settings(field, message)
}

fn camera_err(field: &str, message: String) -> Error {
    Error::camera(field, message)
}

/// `--resolution`'s `WxH`.
pub fn parse_resolution(s: &str) -> Result<(u32, u32), Error> {
    let bad = || settings_err("resolution", format!("expected WxH such as 1920x1080, got '{s}'"));
    let (w, h) = s.split_once('x').ok_or_else(bad)?;
    Ok((w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?))
}

fn parse_environment(s: &str, strength: f32) -> Result<Environment, Error> {
    if s.to_ascii_lowercase().ends_with(".exr") {
        return petzval_renderer::scene::environment::load_environment_exr(std::path::Path::new(s), strength, 0.0);
    }
    let v: Vec<f32> = s
        .split(',')
        .map(|c| c.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| settings_err("environment", format!("expected R,G,B or FILE.exr, got '{s}'")))?;
    let c = match v.as_slice() {
        [g] => glam::Vec3::splat(*g),
        [r, g, b] => glam::Vec3::new(*r, *g, *b),
        _ => return Err(settings_err("environment", format!("expected R,G,B or FILE.exr, got '{s}'"))),
    };
    if !c.is_finite() || c.min_element() < 0.0 {
        return Err(settings_err("environment", format!("must be finite and non-negative, got '{s}'")));
    }
    // the scene's own check (`Scene::check_values`), here before anything loads
    let limit = petzval_renderer::limits::MAX_RADIANCE;
    let radiance = c * strength;
    if !(radiance.is_finite() && radiance.max_element() <= limit) {
        return Err(settings_err(
            "environment",
            format!(
                "radiance '{s}' × --environment-strength {strength} is outside 0…{limit:e} (the brightest value petzval renders)"
            ),
        ));
    }
    Ok(Environment::Constant(radiance))
}

/// Where the outputs go, checked before the render.
struct Outputs {
    /// The preview PNG.
    png: PathBuf,
    /// Its tone mapping.
    tone: ToneMap,
    /// EXR channels beyond RGBA.
    layers: ExrLayers,
}

/// The output paths, tone mapping and channels, checked before anything is loaded: the folders
/// exist, the EXR path is not a PNG and the preview never overwrites the EXR.
fn check_outputs(args: &RenderArgs) -> Result<Outputs, Error> {
    let folder_of = |p: &std::path::Path| match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let ext = |p: &std::path::Path| p.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if ext(&args.output).as_deref() != Some("exr") {
        return Err(settings_err(
            "output",
            format!("'{}' must be an .exr file (the preview PNG goes to --png)", args.output.display()),
        ));
    }
    let png = args.png.clone().unwrap_or_else(|| args.output.with_extension("png"));
    let same = |a: &std::path::Path, b: &std::path::Path| {
        let abs = |p: &std::path::Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        abs(a) == abs(b) || (a.exists() && b.exists() && a.canonicalize().ok() == b.canonicalize().ok())
    };
    if !args.no_png && same(&png, &args.output) {
        return Err(settings_err("png", format!("'{}' is the EXR output itself", png.display())));
    }
    let mut paths = vec![("output", args.output.clone())];
    if !args.no_png {
        paths.push(("png", png.clone()));
    }
    for (field, p) in paths {
        let dir = folder_of(&p);
        if !dir.is_dir() {
            return Err(settings_err(field, format!("the folder '{}' does not exist", dir.display())));
        }
        if p.is_dir() {
            return Err(settings_err(field, format!("'{}' is a folder", p.display())));
        }
    }
    let tone = match args.tonemap.as_str() {
        "srgb" => ToneMap::Srgb,
        "filmic" => ToneMap::Filmic,
        t => return Err(settings_err("tonemap", format!("expected srgb or filmic, got '{t}'"))),
    };
    let mut layers = ExrLayers { depth: false, normal: false, albedo: false };
    for a in args.aovs.as_deref().unwrap_or(DEFAULT_AOVS).split(',').map(str::trim).filter(|a| !a.is_empty()) {
        match a {
            "depth" => layers.depth = true,
            "normal" => layers.normal = true,
            "albedo" => layers.albedo = true,
            other => return Err(settings_err("aovs", format!("unknown channel '{other}' (depth, normal, albedo)"))),
        }
    }
    Ok(Outputs { png, tone, layers })
}

/// The numeric flags, checked before anything is loaded: finite and in range (a NaN or infinite
/// value would otherwise give a black or infinite image with exit code 0).
fn check_numbers(args: &RenderArgs) -> Result<(), Error> {
    let finite_in = |field: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && v >= lo && v <= hi {
            Ok(())
        } else {
            Err(settings_err(field, format!("must be a number in [{lo}, {hi}], got {v}")))
        }
    };
    finite_in("exposure", args.exposure as f64, -64.0, 64.0)?;
    finite_in("environment-strength", args.environment_strength as f64, 0.0, 1e6)?;
    finite_in("filter-width", args.filter_width as f64, 0.0, 16.0)?;
    if args.bokeh_paths != "auto" {
        let v: f64 = args.bokeh_paths.parse().map_err(|_| {
            settings_err("bokeh-paths", format!("must be auto or a number of light paths, got '{}'", args.bokeh_paths))
        })?;
        finite_in("bokeh-paths", v, 0.0, 64.0)?;
    }
    if !(args.tolerance.is_finite() && args.tolerance > 0.0) {
        return Err(settings_err("tolerance", format!("must be a positive number of pixels, got {}", args.tolerance)));
    }
    Ok(())
}

/// The longest `--time-limit` (one year), so the duration is representable.
const MAX_TIME_LIMIT_S: f64 = 365.0 * 86_400.0;

/// The most `--threads` (as the Python module allows).
const MAX_THREADS: usize = 1024;

/// `START-END[xSTEP]` → the frames (at most 100 000).
fn parse_frames(s: &str) -> Result<Vec<i64>, Error> {
    let bad = || settings_err("frames", format!("expected START-END[xSTEP] such as 1001-1010 or 1-100x5, got '{s}'"));
    let (range, step) = match s.split_once('x') {
        Some((r, st)) => (r, st.trim().parse::<i64>().map_err(|_| bad())?),
        None => (s, 1),
    };
    // a negative start: the '-' separating START and END is the last one after a digit
    let cut = range.char_indices().skip(1).find(|&(i, c)| c == '-' && range.as_bytes()[i - 1].is_ascii_digit());
    let (a, b) = match cut {
        Some((i, _)) => (&range[..i], &range[i + 1..]),
        None => (range, range),
    };
    let (a, b): (i64, i64) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
    if step <= 0 || b < a {
        return Err(bad());
    }
    let n = (b - a) / step + 1;
    if n > 100_000 {
        return Err(settings_err("frames", format!("{n} frames is more than 100000")));
    }
    Ok((0..n).map(|k| a + k * step).collect())
}

/// `path` with its first run of `#` replaced by `frame`, zero-padded to the run's length.
fn frame_path(path: &std::path::Path, frame: f64) -> PathBuf {
    let s = path.to_string_lossy().to_string();
    let Some(start) = s.find('#') else { return path.to_path_buf() };
    let len = s[start..].chars().take_while(|&c| c == '#').count();
    let f = if frame.fract() == 0.0 {
        let w = len + usize::from(frame < 0.0);
        format!("{:0w$}", frame as i64, w = w)
    } else {
        format!("{frame}")
    };
    PathBuf::from(format!("{}{}{}", &s[..start], f, &s[start + len..]))
}

/// The USD shot's RenderSettings applied to `args` where the command line left the defaults.
fn apply_render_settings(args: &mut RenderArgs) -> Result<Vec<RenderArgs>, Error> {
    let Some(path) = args.scene.clone().filter(|p| petzval_usd::is_usd_path(p)) else {
        if args.settings.is_some() {
            return Err(settings_err("settings", "--settings applies to USD shots only".into()));
        }
        return Ok(Vec::new());
    };
    let time =
        args.frame.or_else(|| args.frames.as_deref().and_then(|f| parse_frames(f).ok()?.first().map(|&f| f as f64)));
    let rs =
        petzval_usd::render_settings::read(&path, time, args.settings.as_deref()).map_err(|e| usd_error(&path, e))?;
    let Some(rs) = rs else { return Ok(Vec::new()) };
    for w in &rs.warnings {
        eprintln!("warning: {w}");
    }
    // further products: each its own render of the same shot, with the command line's options
    let others: Vec<RenderArgs> = rs
        .others
        .iter()
        .map(|o| {
            let mut a = args.clone();
            apply_settings(&mut a, o);
            a
        })
        .collect();
    apply_settings(args, &rs);
    Ok(others)
}

/// A USD error as the renderer's: its own when it is one, else a scene error naming the shot
/// once (the USD error names its layer; when that is the shot itself, relative or absolute, the
/// name is not repeated).
fn usd_error(path: &std::path::Path, e: petzval_usd::Error) -> Error {
    if let petzval_usd::Error::Renderer(e) = e {
        return e;
    }
    let file = path.display().to_string();
    let message = e.to_string();
    let absolute = std::fs::canonicalize(path).map(|p| p.display().to_string()).unwrap_or_default();
    let rest = [&file, &absolute]
        .iter()
        .filter(|f| !f.is_empty())
        .find_map(|f| message.strip_prefix(&format!("{f}: ")))
        .unwrap_or(&message);
    Error::scene(file, "", rest.to_string())
}

/// One product's settings onto the options the command line left at their defaults.
fn apply_settings(args: &mut RenderArgs, rs: &petzval_usd::render_settings::RenderSettings) {
    if args.camera.is_none() {
        args.camera = rs.camera.clone();
    }
    if args.resolution == DEFAULT_RESOLUTION {
        args.resolution = format!("{}x{}", rs.resolution.0, rs.resolution.1);
    }
    if let Some(name) = &rs.product_name {
        if args.output == std::path::Path::new(DEFAULT_OUTPUT) {
            args.output = PathBuf::from(name);
        }
    }
    if args.pixel_aspect.is_none() {
        args.pixel_aspect = Some(rs.pixel_aspect);
    }
    if args.aspect_conform.is_none() {
        args.aspect_conform = Some(rs.aspect_conform.clone());
    }
    if let (None, Some([x0, y0, x1, y1])) = (&args.data_window, rs.data_window_ndc) {
        args.data_window = Some(format!("{x0},{y0},{x1},{y1}"));
    }
    if args.purposes.is_none() {
        args.purposes = Some(rs.included_purposes.join(","));
    }
    args.no_dof |= rs.disable_depth_of_field;
    if !rs.vars.is_empty() && args.aovs.is_none() {
        // the RenderVars choose the EXR's channels unless --aovs was given
        args.aovs = Some(rs.aovs.join(","));
    }
    eprintln!(
        "render settings {}{}: camera {}, {}, output {}",
        rs.path,
        rs.product_path.as_deref().map(|p| format!(" ({p})")).unwrap_or_default(),
        args.camera.as_deref().unwrap_or("(first)"),
        args.resolution,
        args.output.display()
    );
}

/// `--data-window`'s four numbers.
fn parse_ndc(s: &str) -> Result<[f64; 4], Error> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| settings_err("data_window", format!("'{s}' must be four numbers XMIN,YMIN,XMAX,YMAX")))?;
    <[f64; 4]>::try_from(v)
        .map_err(|_| settings_err("data_window", format!("'{s}' must be four numbers XMIN,YMIN,XMAX,YMAX")))
}

/// `--purposes`: the USD geometry purposes rendered (default: default and render).
fn parse_purposes(s: Option<&str>) -> Result<petzval_usd::Purposes, Error> {
    let Some(s) = s else { return Ok(petzval_usd::Purposes::default()) };
    let names: Vec<&str> = s.split(',').map(str::trim).filter(|n| !n.is_empty()).collect();
    if let Some(bad) = names.iter().find(|n| !matches!(**n, "default" | "render" | "proxy" | "guide")) {
        return Err(settings_err(
            "purposes",
            format!("'{bad}' is not a purpose (default, render, proxy, guide) in '{s}'"),
        ));
    }
    Ok(petzval_usd::Purposes::from_names(&names))
}

/// `--resolution`'s default.
const DEFAULT_RESOLUTION: &str = "960x640";
/// `-o`'s default.
const DEFAULT_OUTPUT: &str = "render.exr";
/// `--aovs`'s default.
const DEFAULT_AOVS: &str = "depth";

/// Runs `petzval render` (every frame of `--frames` in turn).
pub fn run(mut args: RenderArgs) -> Result<(), Error> {
    let others = apply_render_settings(&mut args)?;
    args.settings = None;
    run_product(args)?;
    for mut a in others {
        if crate::signals::interrupted() {
            break;
        }
        // a further RenderProduct of the shot: its settings are applied already
        a.settings = None;
        run_product(a)?;
    }
    Ok(())
}

/// Renders one product of the shot (every frame of `--frames` in turn).
fn run_product(args: RenderArgs) -> Result<(), Error> {
    if let Some(frames) = check_frames(&args)? {
        for f in frames {
            let mut a = args.clone();
            a.frames = None;
            a.frame = Some(f as f64);
            eprintln!("== frame {f}");
            run_frame(a)?;
            if crate::signals::interrupted() {
                // the interrupted frame was written (complete=false); no further frame starts
                eprintln!("interrupted: frames after {f} not rendered");
                break;
            }
        }
        return Ok(());
    }
    run_frame(args)
}

fn run_frame(mut args: RenderArgs) -> Result<(), Error> {
    if let Some(f) = args.frame {
        args.output = frame_path(&args.output, f);
        args.png = args.png.as_ref().map(|p| frame_path(p, f));
        // a farm's frame renders write into a shot folder that may not exist yet
        if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty() && !d.exists()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
    }
    // Check every flag before loading anything.
    let Preflight { width, height, outputs, environment } = preflight(&args)?;
    if let Some(t) = args.threads {
        let _ = rayon::ThreadPoolBuilder::new().num_threads(t).build_global();
    }
    // 1. Scene (file or demo) and the shot's defaults.
    let mut usd_cam: Option<(String, petzval_usd::UsdCamera, Option<f64>)> = None;
    let (mut scene, demo_shot): (Scene, Option<demo::DemoShot>) = match &args.scene {
        Some(path) if petzval_usd::is_usd_path(path) => {
            let usd_err = |e: petzval_usd::Error| usd_error(path, e);
            let options = petzval_usd::LoadOptions {
                time: args.frame,
                subdivision_level: args.subdivision_level,
                purposes: parse_purposes(args.purposes.as_deref())?,
            };
            let shot = petzval_usd::load_with(path, &options).map_err(usd_err)?;
            let cam = shot.camera(args.camera.as_deref()).map_err(usd_err)?.clone();
            usd_cam = Some((shot.file.clone(), cam, shot.time));
            (shot.scene, None)
        }
        Some(path) => {
            // a frame of a glTF file's animation: its time in seconds
            let time_s = args.frame.map(|f| f / args.fps);
            (gltf::load_gltf_at(path, time_s)?, None)
        }
        None => {
            let (s, shot) = demo::demo_scene();
            (s, Some(shot))
        }
    };
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(env) = environment {
        scene.environment = env;
    }
    let scene_cam: SceneCamera = match (&args.camera, &usd_cam) {
        (_, Some((_, c, _))) => SceneCamera {
            name: c.path.clone(),
            to_world: glam::Affine3A::from_mat4(c.to_world.as_mat4()),
            yfov_rad: 0.5,
            aspect_ratio: None,
            ortho_scale_m: None,
            znear: c.clipping_range_m.0 as f32,
            zfar: Some(c.clipping_range_m.1 as f32),
        },
        (Some(name), None) => scene.cameras.iter().find(|c| &c.name == name).cloned().ok_or_else(|| {
            let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
            let file = args.scene.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "the demo".into());
            camera_err(&file, format!("--camera: no camera named '{name}' (cameras: {})", names.join(", ")))
        })?,
        (None, None) => scene.cameras.first().cloned().ok_or_else(|| {
            let file = args.scene.as_ref().map(|p| p.display().to_string()).unwrap_or_else(|| "the demo".into());
            camera_err(&file, "the scene has no camera; add one in the scene file".into())
        })?,
    };
    let to_world = match &usd_cam {
        Some((_, c, _)) => DAffine3::from_mat4(c.to_world),
        None => DAffine3::from_cols_array(&scene_cam.to_world.to_cols_array().map(|v| v as f64)),
    };
    let t0 = std::time::Instant::now();
    let warned = scene.warnings.len();
    let render_scene = RenderScene::new(scene)?;
    // what building the render scene found (triangles skipped, ...)
    for w in render_scene.scene().warnings.iter().skip(warned) {
        eprintln!("warning: {w}");
    }
    eprintln!("scene: {} triangles, BVH built in {:.2} s", render_scene.triangle_count(), t0.elapsed().as_secs_f64());
    // 2. The camera as the host conventions describe it (the sensor width spans the larger
    //    image dimension, Blender's automatic fit; shift in mm), focused as given, the demo's
    //    focus, or autofocus on what the image centre sees.
    let focus_m = match (host::focus_distance_m(args.focus)?, &demo_shot) {
        (Some(f), _) => Some(f),
        (None, _) if args.focus.is_some() => None,
        (None, Some(d)) => Some(d.focus_distance_m),
        (None, None) if usd_cam.as_ref().is_some_and(|u| u.1.focus_distance_m.is_some()) => {
            usd_cam.as_ref().and_then(|u| u.1.focus_distance_m)
        }
        (None, None) => {
            // what the camera sees: within a USD camera's clippingRange or a glTF one's znear/zfar
            let clip = match &usd_cam {
                Some((_, c, _)) => c.clipping_range_m,
                None if args.scene.is_some() => {
                    (scene_cam.znear as f64, scene_cam.zfar.map_or(f64::INFINITY, |f| f as f64))
                }
                None => (0.0, f64::INFINITY),
            };
            let f = shot::autofocus_clipped_m(&render_scene, &to_world, clip);
            match f {
                Some(f) => eprintln!("autofocus: {f:.3} m (the surface at the image centre)"),
                None => eprintln!("autofocus: nothing at the image centre, focusing at infinity"),
            }
            f
        }
    };
    let mut flags_camera = flags_host_camera(&args, demo_shot.as_ref(), focus_m)?;
    // A glTF camera clips at its znear and zfar, as Blender and Cycles clip at the camera's
    // clip start and end (the USD camera brings its clippingRange).
    if usd_cam.is_none() && args.scene.is_some() {
        flags_camera.clip_m = (scene_cam.znear as f64, scene_cam.zfar.map_or(f64::INFINITY, |f| f as f64));
    }
    if !matches!(flags_camera.lens.as_str(), "thin" | "pinhole") && args.focal_length.is_some() {
        eprintln!(
            "note: --focal-length is ignored for a real lens; '{}' brings its own focal length",
            flags_camera.lens
        );
    }
    // An orthographic scene camera stays orthographic unless the flags ask for a focal length;
    // it has no depth of field unless --fstop asks (an aperture of radius 1/(2N) m, as Cycles).
    if let (None, None, Some(s)) = (args.ortho_scale, args.focal_length, scene_cam.ortho_scale_m) {
        flags_camera.ortho_scale_m = Some(s as f64);
    }
    if flags_camera.ortho_scale_m.is_some() && args.fstop.is_none() {
        flags_camera.f_number = None;
    }
    // Focal length for thin/pinhole: given, else from the scene camera's field of view.
    if args.focal_length.is_none() && flags_camera.ortho_scale_m.is_none() {
        let sensor = flags_camera.film_back.sensor(width, height, flags_camera.tilt_deg)?;
        flags_camera.focal_length_mm =
            host::focal_length_from_yfov_mm(scene_cam.yfov_rad as f64, width, height, &sensor)?;
    }
    let host_camera = match &usd_cam {
        Some((_, c, _)) => usd_host_camera(c, &args, focus_m, (width, height))?,
        None => {
            if args.aspect_conform.is_some() {
                eprintln!("note: --aspect-conform applies to a USD camera's aperture; this camera's sensor is fitted by its own rule");
            }
            flags_camera
        }
    };
    // No depth of field: a thin lens becomes a pinhole; a real lens's stop is its own.
    let mut host_camera = host_camera;
    if args.no_dof {
        if host_camera.lens == "thin" {
            host_camera.f_number = None;
        } else if host_camera.lens != "pinhole" {
            eprintln!(
                "note: --no-dof (disableDepthOfField) keeps '{}' at its stop: a real lens's depth of field is its optics",
                host_camera.lens
            );
        }
    }
    let model = host_camera.lens_model;
    let mut spec = host_camera.camera_spec(width, height)?;
    // 3. The data window: a crop of the frame, or overscan rendered on the sensor extended
    //    by the frame's pixel pitch (the frame's pixels stay where they were on the film).
    let window = match &args.data_window {
        Some(w) => PixelWindow::from_ndc(parse_ndc(w)?, width, height, "data_window")?,
        None => PixelWindow::full(width, height),
    };
    let outer = window.union_with_frame(width, height);
    if !window.inside(width, height) {
        spec.sensor = spec.sensor.extended_to(width, height, [outer.x0, outer.y0, outer.x1, outer.y1]);
    }
    let (render_w, render_h) = (outer.width(), outer.height());
    // 4. The camera: auto picks the cheapest model within the error budget for this shot.
    let t0 = std::time::Instant::now();
    let built = shot::build_for_scene(&spec, &render_scene, &to_world, render_w, render_h, args.spp, args.spectral)?;
    if model == LensModel::Auto {
        eprintln!(
            "lens model: {} (auto, {:.2} s to decide) — {}",
            built.choice.model,
            t0.elapsed().as_secs_f64(),
            built.choice.reason
        );
        for c in &built.choice.candidates {
            // A candidate never built (an LRTF whose bake would cost more than it saves) has no
            // measured error or speed: dashes, not inf/NaN.
            let num = |v: f64, width: usize, prec: usize| {
                if v.is_finite() {
                    format!("{v:>width$.prec$}")
                } else {
                    format!("{:>width$}", "—")
                }
            };
            eprintln!(
                "  {:<9} max {} px  mean {} px  vignetting {} %  {} ns/ray  est. {} s  {}",
                c.model.to_string(),
                num(c.max_error_px, 9, 3),
                num(c.mean_error_px, 9, 3),
                num(c.irradiance_error * 100.0, 6, 2),
                num(c.ns_per_ray, 7, 1),
                num(c.estimated_seconds, 8, 2),
                if c.meets { "meets".to_string() } else { c.note.clone() }
            );
        }
    } else if matches!(model, LensModel::Lrtf { .. }) && args.lrtf_file.is_none() {
        eprintln!("lrtf: table baked in {:.2} s", t0.elapsed().as_secs_f64());
    }
    for w in &built.warnings {
        eprintln!("warning: {w}");
    }
    let (camera, lens_label, focal_mm, f_number) =
        (built.camera, built.lens_label, built.focal_length_mm, built.f_number);
    let rig = CameraRig { camera, to_world };
    if let Some(p) = rig.camera.focus_plane() {
        if let Some(j) = p.hinge_distance_m {
            eprintln!(
                "tilted focus plane: hinge line {j:.3} m from the lens, {:.1}° to the sensor",
                p.angle_to_sensor_deg
            );
        }
    }
    // 4. Render with a progress bar; Ctrl-C stops and keeps what converged.
    // Model only what the scene needs: one wavelength per ray only where the lens disperses.
    let dispersive = rig.camera.is_dispersive();
    let spectral = args.spectral && dispersive;
    if args.spectral && !dispersive {
        eprintln!(
            "note: --spectral ignored: the {} has no dispersion, so RGB transport is exact here",
            if matches!(&rig.camera, Camera::Exact(_)) { "lens" } else { "camera model" }
        );
    }
    let settings = RenderSettings {
        width: render_w,
        height: render_h,
        crop: (window != outer).then(|| window.crop_in(&outer)),
        pixel_origin: [outer.x0 as i32, outer.y0 as i32],
        spp: args.spp,
        seed: args.seed,
        max_depth: args.max_depth,
        spectral,
        time_limit: args.time_limit.map(Duration::from_secs_f64),
        clip_start_m: host_camera.clip_m.0,
        clip_end_m: host_camera.clip_m.1,
        filter: if args.filter_width > 0.0 {
            PixelFilter::BlackmanHarris { width_px: 2.0 * args.filter_width }
        } else {
            PixelFilter::Box { width_px: 1.0 }
        },
        adaptive_threshold: args.adaptive_threshold,
        adaptive_min_samples: args.adaptive_min_samples,
        ..RenderSettings::default()
    };
    let (method, preview) = method_settings(&args)?;
    let settings = RenderSettings {
        bokeh_paths: match args.bokeh_paths.as_str() {
            "auto" if method == dof::Method::Mc => bokeh::auto_paths(&render_scene, &rig.camera),
            "auto" => 0.0,
            v => v.parse().unwrap_or(0.0),
        },
        ..settings
    };
    settings.validate()?;
    if settings.bokeh_paths > 0.0 {
        eprintln!(
            "bokeh light paths: {} per pixel per sample for emitters blurred enough to need them (--bokeh-paths)",
            settings.bokeh_paths
        );
    }
    crate::signals::enter(crate::signals::Phase::Rendering);
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {percent}% ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let progress = |f: f32| {
        bar.set_position((f * 1000.0) as u64);
        !crate::signals::interrupted()
    };
    let result = dof::render_method(method, &render_scene, &rig, &settings, &preview, &progress, None)?;
    bar.finish_and_clear();
    crate::signals::enter(crate::signals::Phase::Writing);
    let pixels = window.width() as u64 * window.height() as u64;
    let mean_spp = result.camera_rays as f64 / pixels.max(1) as f64;
    if let Some(min_spp) = settings.adaptive_min_spp() {
        eprintln!(
            "adaptive sampling: threshold {}, at least {min_spp} spp: {mean_spp:.1} spp on average",
            settings.adaptive_threshold
        );
    }
    eprintln!(
        "rendered {}x{} at {} spp in {:.2} s ({}, {:.2} M camera rays/s){}",
        width,
        height,
        result.spp_done,
        result.seconds,
        lens_label,
        result.camera_rays as f64 / result.seconds / 1e6,
        if result.complete { "" } else { " — stopped early" }
    );
    if window != PixelWindow::full(width, height) {
        eprintln!(
            "data window: {}x{} pixels from ({}, {}) of the {width}x{height} frame{}",
            window.width(),
            window.height(),
            window.x0,
            window.y0,
            if window.inside(width, height) { " (a crop)" } else { " (overscan)" }
        );
    }
    if result.light_paths > 0 {
        eprintln!(
            "bokeh light paths traced: {} ({:.2} per camera ray), {:.1} % of them reached the film",
            result.light_paths,
            result.light_paths as f64 / result.camera_rays.max(1) as f64,
            100.0 * result.light_paths_landed as f64 / result.light_paths as f64
        );
    }
    if result.dropped_samples > 0 {
        eprintln!("warning: {} non-finite samples were dropped", result.dropped_samples);
    }
    // 5. Output with metadata.
    let s = rig.camera.sensor();
    let ortho_window_m = match &rig.camera {
        Camera::Orthographic(c) => Some(c.window_m()),
        _ => None,
    };
    let metadata: Metadata = vec![
        ("lens".into(), lens_label.clone()),
        ("lensModel".into(), built.choice.model.to_string()),
        ("lensModelReason".into(), built.choice.reason.clone()),
        ("lensModelTolerancePx".into(), format!("{}", args.tolerance)),
        // an orthographic camera has no focal length (its rays are parallel): "inf"
        ("focalLengthMM".into(), ortho_window_m.map_or_else(|| format!("{focal_mm:.4}"), |_| "inf".into())),
        ("fNumber".into(), format!("{f_number:.4}")),
        ("focusDistanceM".into(), focus_m.map(|f| format!("{f:.4}")).unwrap_or_else(|| "inf".into())),
        ("tiltXDeg".into(), format!("{}", s.tilt_x_deg)),
        ("tiltYDeg".into(), format!("{}", s.tilt_y_deg)),
        ("shiftXMM".into(), format!("{}", s.shift_mm.x)),
        ("shiftYMM".into(), format!("{}", s.shift_mm.y)),
        ("sensorMM".into(), format!("{:.3}x{:.3}", s.width_mm, s.height_mm)),
        ("pixelAspectRatio".into(), format!("{}", host_camera.film_back.pixel_aspect)),
        ("spp".into(), format!("{}", result.spp_done)),
        ("sppRequested".into(), format!("{}", args.spp)),
        ("sppMean".into(), format!("{mean_spp:.3}")),
        ("adaptiveThreshold".into(), format!("{}", settings.adaptive_threshold)),
        ("seed".into(), format!("{}", args.seed)),
        ("spectral".into(), format!("{spectral}")),
        (
            "complete".into(),
            if result.complete { "true".into() } else { "false: stopped early, partially converged".into() },
        ),
        ("renderSeconds".into(), format!("{:.3}", result.seconds)),
        ("dofMethod".into(), method.to_string()),
    ];
    let mut metadata = metadata;
    if let Some((w, h)) = ortho_window_m {
        // Blender's Orthographic Scale is the fitted side; the window's both sides are given
        metadata.push(("orthoWindowM".into(), format!("{w:.6}x{h:.6}")));
    }
    if let Some((file, c, time)) = &usd_cam {
        metadata.push(("usdShot".into(), file.clone()));
        metadata.push(("usdCamera".into(), c.path.clone()));
        metadata.push(("usdFrame".into(), time.map(|t| t.to_string()).unwrap_or_else(|| "default".into())));
    }
    if window != PixelWindow::full(width, height) {
        let [x0, y0, x1, y1] = [window.x0, window.y0, window.x1, window.y1];
        metadata.push(("dataWindowPx".into(), format!("{x0},{y0},{x1},{y1}")));
    }
    if let Some(p) = usd_cam.as_ref().and(args.aspect_conform.as_ref()) {
        metadata.push(("aspectConform".into(), p.clone()));
    }
    let frame = ExrFrame {
        display_width: width,
        display_height: height,
        origin_x: window.x0 as i32,
        origin_y: window.y0 as i32,
        pixel_aspect: host_camera.film_back.pixel_aspect as f32,
    };
    write_exr_framed(&args.output, &result.image, outputs.layers, &metadata, &frame)?;
    eprintln!("wrote {}", args.output.display());
    if !args.no_png {
        write_png(&outputs.png, &result.image, args.exposure, outputs.tone)?;
        eprintln!("wrote {}", outputs.png.display());
    }
    crate::signals::finish_writing();
    Ok(())
}

/// The USD camera prim's host camera with the command line's explicit options on top
/// (`--lens`, `--lens-model` other than auto, `--fstop`, `--focus`, `--focal-length`,
/// non-zero `--tilt-*`/`--shift-*`, `--aperture`, `--lrtf-file`, `--tolerance` other than
/// 0.25). Without a focus distance on the prim, `focus_m` (the autofocus) is used.
fn usd_host_camera(
    c: &petzval_usd::UsdCamera,
    args: &RenderArgs,
    focus_m: Option<f64>,
    (width, height): (u32, u32),
) -> Result<HostCamera, Error> {
    let mut h = c.host_camera().map_err(|e| match e {
        petzval_usd::Error::Renderer(e) => e,
        e => camera_err("usd", e.to_string()),
    })?;
    h.film_back.pixel_aspect = args.pixel_aspect.unwrap_or(1.0);
    if let Some(p) = &args.aspect_conform {
        h.film_back = p.parse::<ConformPolicy>()?.apply(h.film_back, width, height);
    }
    if let Some(l) = &args.lens {
        h.lens = l.clone();
    }
    if args.lens_model != "auto" {
        h.lens_model = args.lens_model.parse()?;
    }
    if args.lrtf_file.is_some() {
        h.lrtf_file = args.lrtf_file.clone();
        if h.lens_model == LensModel::Auto {
            h.lens_model = LensModel::Lrtf { resolution: petzval_renderer::camera::DEFAULT_LRTF_RESOLUTION };
        }
    }
    if args.tolerance != 0.25 {
        h.tolerance_px = args.tolerance;
    }
    if args.fstop.is_some() {
        h.f_number = args.fstop;
    }
    h.focus_distance_m = focus_m;
    if let Some(f) = args.focal_length {
        h.focal_length_mm = f;
    }
    if args.tilt_x.is_some() || args.tilt_y.is_some() {
        h.tilt_deg = DVec2::new(args.tilt_x.unwrap_or(0.0), args.tilt_y.unwrap_or(0.0));
    }
    if args.shift_x != 0.0 || args.shift_y != 0.0 {
        h.film_back.shift = Shift::Mm(DVec2::new(args.shift_x, args.shift_y));
    }
    if let Some(a) = &args.aperture {
        h.aperture = Some(host::parse_aperture(a)?);
    }
    h.natural_vignetting = host::parse_on_off("natural_vignetting", &args.natural_vignetting)?;
    if let Some(s) = args.ortho_scale {
        // the larger side spans it, whatever the stage's aperture policy
        h.film_back.fit = SensorFit::Auto;
        h.ortho_scale_m = Some(s);
    }
    Ok(h)
}

/// `--frames`, checked: not with `--frame`, `-o` names the frame with `#`, the range parses.
fn check_frames(args: &RenderArgs) -> Result<Option<Vec<i64>>, Error> {
    let Some(fr) = &args.frames else { return Ok(None) };
    if args.frame.is_some() {
        return Err(settings_err("frames", "give --frame or --frames, not both".into()));
    }
    if !args.output.to_string_lossy().contains('#') {
        return Err(settings_err("frames", "-o must name the frame with #### (e.g. out.####.exr)".into()));
    }
    parse_frames(fr).map(Some)
}

/// The host camera the flags describe (with the demo's lens, f-number, tilt and blades for the
/// demo where the flags leave them), focused at `focus_m`; thin and pinhole get `--focal-length`
/// or 50 mm (the render replaces the latter by the scene camera's field of view).
fn flags_host_camera(
    args: &RenderArgs,
    demo_shot: Option<&demo::DemoShot>,
    focus_m: Option<f64>,
) -> Result<HostCamera, Error> {
    // the demo's lens, tilt and stop belong to its perspective shot, not to an orthographic view
    let demo_shot = demo_shot.filter(|_| args.ortho_scale.is_none());
    // an explicit --tilt-x (0 too) wins over the demo's own tilt
    let tilt_x = args.tilt_x.unwrap_or_else(|| demo_shot.map(|d| d.tilt_x_deg).unwrap_or(0.0));
    let film_back = FilmBack {
        width_mm: args.sensor_width,
        height_mm: args.sensor_width,
        fit: SensorFit::Auto,
        shift: Shift::Mm(DVec2::new(args.shift_x, args.shift_y)),
        pixel_aspect: args.pixel_aspect.unwrap_or(1.0),
    };
    let lens = args.lens.clone().or_else(|| demo_shot.map(|d| d.lens.to_string())).unwrap_or_else(|| "thin".into());
    let aperture = match (&args.aperture, demo_shot) {
        (Some(a), _) => Some(host::parse_aperture(a)?),
        (None, Some(d)) => Some(Aperture {
            shape: ApertureShape::Blades { count: d.blades, curvature: 0.0 },
            rotation_rad: d.blade_rotation_deg.to_radians(),
            anamorphic_ratio: 1.0,
        }),
        (None, None) => None,
    };
    // The demo's f-number belongs to its lens; another lens opens to its own.
    let fstop = args.fstop.or_else(|| demo_shot.filter(|_| args.lens.is_none()).map(|d| d.f_number));
    let mut model: LensModel = args.lens_model.parse()?;
    if args.lrtf_file.is_some() && model == LensModel::Auto {
        model = LensModel::Lrtf { resolution: petzval_renderer::camera::DEFAULT_LRTF_RESOLUTION };
    }
    Ok(HostCamera {
        f_number: if lens == "thin" { Some(fstop.unwrap_or(2.8)) } else { fstop },
        lens,
        lens_model: model,
        tolerance_px: args.tolerance,
        focal_length_mm: args.focal_length.unwrap_or(50.0),
        film_back,
        tilt_deg: DVec2::new(tilt_x, args.tilt_y.unwrap_or(0.0)),
        focus_distance_m: focus_m,
        aperture,
        clip_m: (0.0, f64::INFINITY),
        natural_vignetting: host::parse_on_off("natural_vignetting", &args.natural_vignetting)?,
        lrtf_file: args.lrtf_file.clone(),
        ortho_scale_m: args.ortho_scale,
    })
}

/// What [`preflight`] checked and made.
pub struct Preflight {
    /// Frame width (px).
    pub width: u32,
    /// Frame height (px).
    pub height: u32,
    /// Where the outputs go.
    outputs: Outputs,
    /// `--environment`, loaded (None: the scene's own).
    environment: Option<Environment>,
}

/// Every check of the flags that needs no scene, run before anything is loaded (`run_frame`
/// starts with it; the flag fuzzer calls it alone): numbers finite and in range, the output
/// paths, `--frames`, the environment, and the camera the flags describe — its numbers, the
/// lens, mask and table files it names, and [`petzval_renderer::CameraSpec::check`] (a focus the
/// lens cannot reach, a tilted sensor cutting into the rear element, a table of another lens),
/// so these are refused here, not after the scene has loaded.
/// What needs the scene is checked when it loads: the scene file, `--camera`, a USD shot's own
/// camera, and autofocus.
pub fn preflight(args: &RenderArgs) -> Result<Preflight, Error> {
    check_frames(args)?;
    if !(args.fps.is_finite() && args.fps > 0.0) {
        return Err(settings_err("fps", format!("must be a positive number of frames per second, got {}", args.fps)));
    }
    if let Some(f) = args.frame.filter(|f| !f.is_finite()) {
        return Err(settings_err("frame", format!("must be a finite number, got {f}")));
    }
    if let Some(t) = args.time_limit {
        // Duration::from_secs_f64 panics on negative, NaN and huge values: refuse them here.
        if !(t.is_finite() && t > 0.0 && t <= MAX_TIME_LIMIT_S) {
            return Err(settings_err(
                "time-limit",
                format!("must be a number of seconds in (0, {MAX_TIME_LIMIT_S}], got {t}"),
            ));
        }
    }
    if let Some(t) = args.threads {
        if t == 0 {
            return Err(settings_err("threads", "must be at least 1".into()));
        }
        if t > MAX_THREADS {
            return Err(settings_err("threads", format!("{t} is more than the {MAX_THREADS} a render may use")));
        }
    }
    let (width, height) = parse_resolution(&args.resolution)?;
    let outputs = check_outputs(args)?;
    check_numbers(args)?;
    RenderSettings { width, height, spp: args.spp, max_depth: args.max_depth, ..RenderSettings::default() }
        .validate()?;
    // the data window, and the frame its overscan makes (within the same limits)
    if let Some(w) = &args.data_window {
        let outer = PixelWindow::from_ndc(parse_ndc(w)?, width, height, "data_window")?.union_with_frame(width, height);
        let (w, h) = (outer.width(), outer.height());
        RenderSettings { width: w, height: h, spp: args.spp, max_depth: args.max_depth, ..RenderSettings::default() }
            .validate()
            .map_err(|e| settings_err("data_window", format!("its overscan makes a {w}x{h} frame: {e}")))?;
    }
    if let Some(p) = &args.aspect_conform {
        p.parse::<ConformPolicy>()?;
    }
    parse_purposes(args.purposes.as_deref())?;
    if args.frame.is_some_and(|f| !f.is_finite()) {
        return Err(settings_err("frame", format!("must be a finite time code, got {}", args.frame.unwrap_or(0.0))));
    }
    let environment =
        args.environment.as_deref().map(|e| parse_environment(e, args.environment_strength)).transpose()?;
    // The camera: the demo's focus for the demo; a scene's autofocus is not known yet (infinity
    // stands in).
    let demo_shot = args.scene.is_none().then(demo::demo_shot);
    let focus_m = match host::focus_distance_m(args.focus)? {
        Some(f) => Some(f),
        None if args.focus.is_some() => None,
        None => demo_shot.as_ref().map(|d| d.focus_distance_m),
    };
    // A USD shot's camera may carry its own lens (PetzvalLensAPI): it is checked once the stage
    // is read, still before rendering.
    if !args.scene.as_deref().is_some_and(petzval_usd::is_usd_path) {
        flags_host_camera(args, demo_shot.as_ref(), focus_m)?.camera_spec(width, height)?.check()?;
    }
    Ok(Preflight { width, height, outputs, environment })
}

/// Every check `petzval render` makes before loading anything, without rendering (the flag
/// fuzzer's entry point): a USD shot's RenderSettings applied, `--frames`, then [`preflight`]
/// for the first frame. (A frame render creates a missing output folder before its checks; this
/// creates nothing, so it refuses that folder.)
pub fn check_flags(mut args: RenderArgs) -> Result<(), Error> {
    apply_render_settings(&mut args)?;
    args.settings = None;
    if let Some(frames) = check_frames(&args)? {
        args.frames = None;
        args.frame = frames.first().map(|&f| f as f64);
    }
    if let Some(f) = args.frame {
        args.output = frame_path(&args.output, f);
        args.png = args.png.as_ref().map(|p| frame_path(p, f));
    }
    method_settings(&args)?;
    preflight(&args).map(|_| ())
}
