//! `petzval bench dof`: every depth-of-field method (mc, multiview, ibrt, spread) against a
//! converged Monte Carlo reference on three scenes, as a ladder of budgets: time, relative RMSE
//! and mean LDR-FLIP per run, then each method's error at MC's time and its time to MC's error.

use super::*;
use glam::{Vec2, Vec3, Vec4};
use petzval_renderer::dof::{self, LayerSettings, Method, PreviewSettings};
use petzval_renderer::film::metrics::{flip_mean, relative_rmse};
use petzval_renderer::film::{write_png, Image, ToneMap};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{CameraRig, RenderSettings};
use petzval_renderer::scene::{demo, Environment, Material, Mesh, Scene};
use petzval_renderer::{library_lens, Aperture, ApertureShape, Camera, Error, ExactCamera, ThinCamera};

/// One scene of the comparison.
pub(super) struct BenchScene {
    /// Its name in the tables.
    pub(super) name: &'static str,
    /// The scene.
    pub(super) scene: RenderScene,
    /// The camera.
    pub(super) rig: CameraRig,
}

/// One run: a method at one budget.
struct Run {
    scene: &'static str,
    method: Method,
    budget: String,
    seconds: f64,
    rel_rmse: f64,
    flip: f64,
}

/// The demo's camera as a 50 mm thin lens at f/2 with the demo's six blades and focus
/// (every method supports it), with the demo's sensor tilt or none.
fn demo_scene(w: u32, h: u32, tilt: bool) -> Result<BenchScene, Error> {
    let (scene, shot) = demo::demo_scene();
    let cam = scene.cameras.first().cloned().ok_or_else(|| Error::settings("scene", "the demo has no camera"))?;
    let to_world = glam::DAffine3::from_cols_array(&cam.to_world.to_cols_array().map(|v| v as f64));
    let aspect = w as f64 / h as f64;
    let sensor = Sensor {
        width_mm: 36.0,
        height_mm: 36.0 / aspect,
        tilt_x_deg: if tilt { shot.tilt_x_deg.signum() * shot.tilt_x_deg.abs().max(4.0) } else { 0.0 },
        ..Sensor::default()
    };
    let aperture = Aperture {
        shape: ApertureShape::Blades { count: shot.blades, curvature: 0.0 },
        rotation_rad: shot.blade_rotation_deg.to_radians(),
        anamorphic_ratio: 1.0,
    };
    let camera = ThinCamera::new(sensor, 50.0, 2.0, Some(shot.focus_distance_m), aperture)?;
    Ok(BenchScene {
        name: if tilt { "demo, tilted sensor" } else { "demo" },
        scene: RenderScene::new(scene)?,
        rig: CameraRig { camera: Camera::Thin(camera), to_world },
    })
}

/// The demo as `petzval render` shoots it: its real lens (double Gauss, exact trace), f-number,
/// blades, focus and tilted sensor.
pub(super) fn demo_real_lens(w: u32, h: u32) -> Result<BenchScene, Error> {
    let mut s = demo_scene(w, h, true)?;
    let (_, shot) = demo::demo_scene();
    let aspect = w as f64 / h as f64;
    let sensor = Sensor { width_mm: 36.0, height_mm: 36.0 / aspect, tilt_x_deg: shot.tilt_x_deg, ..Sensor::default() };
    let lens = library_lens(shot.lens)?.stopped_down(shot.f_number)?.with_aperture(Aperture {
        shape: ApertureShape::Blades { count: shot.blades, curvature: 0.0 },
        rotation_rad: shot.blade_rotation_deg.to_radians(),
        anamorphic_ratio: 1.0,
    });
    s.rig.camera = Camera::Exact(ExactCamera::new(sensor, lens, Some(shot.focus_distance_m))?);
    s.name = "demo, real lens";
    Ok(s)
}

/// An axis-aligned box.
pub(super) fn cuboid(lo: Vec3, hi: Vec3, material: u32) -> Mesh {
    let mut m = Mesh::default();
    let faces: [(Vec3, [Vec3; 4]); 6] = [
        (Vec3::Z, [Vec3::new(lo.x, lo.y, hi.z), Vec3::new(hi.x, lo.y, hi.z), hi, Vec3::new(lo.x, hi.y, hi.z)]),
        (Vec3::NEG_Z, [Vec3::new(hi.x, lo.y, lo.z), lo, Vec3::new(lo.x, hi.y, lo.z), Vec3::new(hi.x, hi.y, lo.z)]),
        (Vec3::X, [Vec3::new(hi.x, lo.y, hi.z), Vec3::new(hi.x, lo.y, lo.z), Vec3::new(hi.x, hi.y, lo.z), hi]),
        (Vec3::NEG_X, [lo, Vec3::new(lo.x, lo.y, hi.z), Vec3::new(lo.x, hi.y, hi.z), Vec3::new(lo.x, hi.y, lo.z)]),
        (Vec3::Y, [Vec3::new(lo.x, hi.y, hi.z), hi, Vec3::new(hi.x, hi.y, lo.z), Vec3::new(lo.x, hi.y, lo.z)]),
        (Vec3::NEG_Y, [lo, Vec3::new(hi.x, lo.y, lo.z), Vec3::new(hi.x, lo.y, hi.z), Vec3::new(lo.x, lo.y, hi.z)]),
    ];
    for (n, q) in faces {
        let base = m.positions.len() as u32;
        m.positions.extend_from_slice(&q);
        m.normals.extend_from_slice(&[n; 4]);
        m.tangents.extend_from_slice(&[Vec4::ZERO; 4]);
        m.uv0.extend_from_slice(&[Vec2::ZERO; 4]);
        m.indices.push([base, base + 1, base + 2]);
        m.indices.push([base, base + 2, base + 3]);
        m.material_ids.extend_from_slice(&[material; 2]);
    }
    m
}

/// A near object occluding bright highlights: a dark lattice 0.6 m from the camera, far out of
/// focus, in front of a grid of small bright emitters 8 m away (in focus) above a grey floor.
fn occluder_scene() -> Result<BenchScene, Error> {
    occluder_scene_shot(8.0, 0.0)
}

/// The occluder scene focused at `focus_m`, the camera turned `yaw_deg` to the left.
fn occluder_scene_shot(focus_m: f64, yaw_deg: f64) -> Result<BenchScene, Error> {
    let grey =
        |v: f32| Material { base_color: Vec4::new(v, v, v, 1.0), roughness: 0.8, specular: 0.2, ..Material::default() };
    let lamp = Material { emissive: Vec3::new(40.0, 30.0, 18.0), double_sided: true, ..grey(0.0) };
    let mut mesh = Mesh::default();
    mesh.append(&cuboid(Vec3::new(-20.0, -1.61, -30.0), Vec3::new(20.0, -1.6, 2.0), 0), 0);
    mesh.append(&cuboid(Vec3::new(-20.0, -2.0, -12.0), Vec3::new(20.0, 8.0, -11.9), 0), 0);
    for i in 0..9 {
        for j in 0..5 {
            let c = Vec3::new(-2.4 + 0.6 * i as f32, -0.9 + 0.45 * j as f32, -8.0);
            mesh.append(&cuboid(c - Vec3::splat(0.035), c + Vec3::splat(0.035), 1), 0);
        }
    }
    for i in 0..3 {
        let x = -0.11 + 0.11 * i as f32;
        mesh.append(&cuboid(Vec3::new(x - 0.012, -0.5, -0.62), Vec3::new(x + 0.012, 0.5, -0.6), 2), 0);
    }
    mesh.append(&cuboid(Vec3::new(-0.5, 0.03, -0.62), Vec3::new(0.5, 0.05, -0.6), 2), 0);
    let scene = Scene {
        materials: vec![grey(0.5), lamp, grey(0.04)],
        environment: Environment::Constant(Vec3::new(0.02, 0.025, 0.04)),
        ..Scene::world(mesh)
    };
    let sensor = Sensor { width_mm: 36.0, height_mm: 24.0, ..Sensor::default() };
    let camera = ThinCamera::new(sensor, 50.0, 2.0, Some(focus_m), Aperture::default())?;
    Ok(BenchScene {
        name: "near occluder, highlights",
        scene: RenderScene::new(scene)?,
        rig: CameraRig {
            camera: Camera::Thin(camera),
            to_world: glam::DAffine3::from_rotation_y(yaw_deg.to_radians()),
        },
    })
}

/// Runs the comparison and prints its tables.
pub(super) fn bench_dof(
    resolution: &str,
    reference_spp: u32,
    save: Option<&std::path::Path>,
    methods: &str,
) -> Result<(), Error> {
    let (w, h) = parse_wxh(resolution)?;
    let methods: Vec<Method> = methods.split(',').map(|m| m.trim().parse()).collect::<Result<_, _>>()?;
    if let Some(dir) = save {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let scenes = [demo_scene(w, h, false)?, occluder_scene()?, demo_scene(w, h, true)?, demo_real_lens(w, h)?];
    let base = RenderSettings { width: w, height: h, ..RenderSettings::default() };
    let mut runs: Vec<Run> = Vec::new();
    for s in &scenes {
        // 1. The reference: Monte Carlo, converged.
        let reference = reference_image(s, &base, reference_spp, save)?;
        eprintln!("{}: reference {} spp in {:.1} s", s.name, reference_spp, reference.1);
        if let Some(dir) = save {
            write_png(&dir.join(format!("{}-reference.png", slug(s.name))), &reference.0, 0.0, ToneMap::Srgb)?;
        }
        // 2. Each method over a ladder of budgets.
        let ladder: Vec<(Method, String, RenderSettings, PreviewSettings)> = budgets(&base);
        let mut images: Vec<(Method, String, f64, Image)> = Vec::new();
        for (method, budget, settings, preview) in ladder {
            if !methods.contains(&method) {
                continue;
            }
            match render_one(s, method, &settings, Some(&preview)) {
                Ok((image, seconds)) => {
                    let rel_rmse = relative_rmse(&reference.0, &image)?;
                    let flip = flip_mean(&reference.0, &image, 0.0)?;
                    eprintln!("{}: {method} {budget}: {seconds:.2} s, rel. RMSE {rel_rmse:.4}, FLIP {flip:.4}", s.name);
                    if let Some(dir) = save {
                        let name = format!("{}-{method}-{}.png", slug(s.name), slug(&budget));
                        write_png(&dir.join(name), &image, 0.0, ToneMap::Srgb)?;
                    }
                    runs.push(Run { scene: s.name, method, budget: budget.clone(), seconds, rel_rmse, flip });
                    images.push((method, budget, seconds, image));
                }
                Err(e) => eprintln!("{}: {method} {budget}: not run: {e}", s.name),
            }
        }
        // 3. The image strip at about equal time.
        if let Some(dir) = save {
            write_strip(dir, s.name, &reference.0, &images)?;
        }
    }
    print_tables(&runs, w, h, reference_spp);
    Ok(())
}

/// Writes `DIR/strip-SCENE.png`: the reference, then each method (in `Method` order) at the budget
/// whose time is nearest to Monte Carlo's at 64 spp, left to right; prints which runs it shows.
fn write_strip(
    dir: &std::path::Path,
    scene: &str,
    reference: &Image,
    images: &[(Method, String, f64, Image)],
) -> Result<(), Error> {
    let target = images.iter().find(|r| r.0 == Method::Mc && r.1 == "64 spp").or(images.first()).map_or(0.0, |r| r.2);
    let mut shown: Vec<&Image> = vec![reference];
    let mut caption = vec!["reference".to_string()];
    for method in [Method::Mc, Method::Multiview, Method::Ibrt, Method::Spread] {
        let nearest = images
            .iter()
            .filter(|r| r.0 == method)
            .min_by(|a, b| (a.2 - target).abs().total_cmp(&(b.2 - target).abs()));
        if let Some((_, budget, seconds, image)) = nearest {
            shown.push(image);
            caption.push(format!("{method} {budget} ({seconds:.1} s)"));
        }
    }
    let file = dir.join(format!("strip-{}.png", slug(scene)));
    write_png(&file, &strip(&shown), 0.0, ToneMap::Srgb)?;
    eprintln!("{}: strip {}: {}", scene, file.display(), caption.join(" | "));
    Ok(())
}

/// The Monte Carlo reference of a scene, read from `DIR/NAME-WxH-SPPspp.rgba` when a previous
/// run with `--save DIR` left it there (raw little-endian f32 RGBA after a u32 width and height),
/// else rendered (and left there). Its time is 0 when it was read.
fn reference_image(
    s: &BenchScene,
    base: &RenderSettings,
    spp: u32,
    save: Option<&std::path::Path>,
) -> Result<(Image, f64), Error> {
    let (w, h) = (base.width, base.height);
    let cache = save.map(|d| d.join(format!("{}-{w}x{h}-{spp}spp.rgba", slug(s.name))));
    if let Some(path) = &cache {
        if let Ok(bytes) = std::fs::read(path) {
            let n = (w * h) as usize;
            if bytes.len() == 8 + 16 * n && bytes[..8] == [w.to_le_bytes(), h.to_le_bytes()].concat()[..] {
                let f = |i: usize| f32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
                let rgba = (0..n).map(|p| [0, 1, 2, 3].map(|c| f(8 + 16 * p + 4 * c))).collect();
                let image = Image {
                    width: w,
                    height: h,
                    rgba,
                    depth: vec![f32::INFINITY; n],
                    normal: vec![[0.0; 3]; n],
                    albedo: vec![[0.0; 3]; n],
                };
                return Ok((image, 0.0));
            }
        }
    }
    let reference = render_one(s, Method::Mc, &RenderSettings { spp, seed: 99, ..base.clone() }, None)?;
    if let Some(path) = &cache {
        let mut bytes = [w.to_le_bytes(), h.to_le_bytes()].concat();
        for p in &reference.0.rgba {
            for c in p {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        petzval_renderer::write_atomic(path, &bytes).map_err(Error::Optics)?;
    }
    Ok(reference)
}

fn slug(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '-' }).collect()
}

/// The budgets: MC and multiview by samples per pixel (views), IBRT by the layers' shading
/// samples and the lens rays per pixel, spread by the layers' shading samples.
fn budgets(base: &RenderSettings) -> Vec<(Method, String, RenderSettings, PreviewSettings)> {
    let mut out = Vec::new();
    let layers = |spp: u32| PreviewSettings { layers: LayerSettings { spp, ..LayerSettings::default() } };
    for spp in [4u32, 16, 64, 256] {
        out.push((
            Method::Mc,
            format!("{spp} spp"),
            RenderSettings { spp, ..base.clone() },
            PreviewSettings::default(),
        ));
    }
    for spp in [16u32, 64, 256] {
        out.push((Method::Multiview, format!("{spp} views"), RenderSettings { spp, ..base.clone() }, layers(4)));
    }
    for (layer_spp, rays) in [(1u32, 64u32), (4, 256), (16, 1024)] {
        let st = RenderSettings { spp: rays, ..base.clone() };
        out.push((Method::Ibrt, format!("{layer_spp} layer spp, {rays} rays"), st, layers(layer_spp)));
    }
    for layer_spp in [1u32, 4, 16] {
        let st = RenderSettings { spp: 1, ..base.clone() };
        out.push((Method::Spread, format!("{layer_spp} layer spp"), st, layers(layer_spp)));
    }
    out
}

fn render_one(
    s: &BenchScene,
    method: Method,
    settings: &RenderSettings,
    preview: Option<&PreviewSettings>,
) -> Result<(Image, f64), Error> {
    let preview = preview.copied().unwrap_or_default();
    let r = dof::render_method(method, &s.scene, &s.rig, settings, &preview, &|_| true, None)?;
    Ok((r.image, r.seconds))
}

/// The runs, then each preview run against Monte Carlo at equal time and at equal error.
fn print_tables(runs: &[Run], w: u32, h: u32, reference_spp: u32) {
    println!(
        "Depth-of-field methods against Monte Carlo ({reference_spp} spp, seed 99), {w}x{h}, {} threads; thin lens 50 mm f/2 with the demo's blades and focus, except 'demo, real lens' (the demo's double Gauss traced exactly, its f-number and tilt). FLIP: mean LDR-FLIP of the sRGB previews at 67 px/degree.",
        rayon::current_num_threads()
    );
    println!();
    println!("| scene | method | budget | seconds | rel. RMSE | mean FLIP |");
    println!("|---|---|---|---|---|---|");
    for r in runs {
        println!(
            "| {} | {} | {} | {:.2} | {:.4} | {:.4} |",
            r.scene, r.method, r.budget, r.seconds, r.rel_rmse, r.flip
        );
    }
    println!();
    println!(
        "Each preview run against Monte Carlo on the same scene: MC's error in the same time, and MC's time to the \
         same error (log-log between MC's runs; '~' where it is extrapolated beyond them with error ∝ time^-1/2)."
    );
    println!();
    println!("| scene | method | budget | seconds | rel. RMSE | MC's rel. RMSE in that time | MC's time to that rel. RMSE (s) | speed-up at equal error |");
    println!("|---|---|---|---|---|---|---|---|");
    for r in runs.iter().filter(|r| r.method != Method::Mc) {
        let mut mc: Vec<&Run> = runs.iter().filter(|m| m.scene == r.scene && m.method == Method::Mc).collect();
        mc.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        let (Some(first), Some(last)) = (mc.first(), mc.last()) else { continue };
        let (err_at, err_mark) = match interpolate(&mc, r.seconds, |m| m.seconds, |m| m.rel_rmse) {
            Some(e) => (e, ""),
            None if r.seconds > last.seconds => (last.rel_rmse * (last.seconds / r.seconds).sqrt(), "~"),
            None => (first.rel_rmse * (first.seconds / r.seconds).sqrt(), "~"),
        };
        let (time_to, time_mark) = match time_to_error(&mc, r.rel_rmse) {
            Some(t) if r.rel_rmse <= first.rel_rmse => (t, ""),
            _ if r.rel_rmse > first.rel_rmse => (first.seconds * (first.rel_rmse / r.rel_rmse).powi(2), "~"),
            _ => (last.seconds * (last.rel_rmse / r.rel_rmse).powi(2), "~"),
        };
        println!(
            "| {} | {} | {} | {:.2} | {:.4} | {err_mark}{err_at:.4} | {time_mark}{time_to:.2} | {time_mark}{:.2}× |",
            r.scene,
            r.method,
            r.budget,
            r.seconds,
            r.rel_rmse,
            time_to / r.seconds
        );
    }
}

/// y at x along the ladder (log-log), None outside its range.
fn interpolate(ladder: &[&Run], x: f64, fx: impl Fn(&Run) -> f64, fy: impl Fn(&Run) -> f64) -> Option<f64> {
    for pair in ladder.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let (xa, xb) = (fx(a), fx(b));
        if xa <= x && x <= xb && xb > xa {
            let t = (x.ln() - xa.ln()) / (xb.ln() - xa.ln());
            return Some((fy(a).ln() + t * (fy(b).ln() - fy(a).ln())).exp());
        }
    }
    None
}

/// The first time along the ladder at which the error falls to `target` (log-log between runs).
fn time_to_error(ladder: &[&Run], target: f64) -> Option<f64> {
    if let Some(first) = ladder.first() {
        if first.rel_rmse <= target {
            return Some(first.seconds);
        }
    }
    for pair in ladder.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if a.rel_rmse > target && b.rel_rmse <= target {
            let t = (target.ln() - a.rel_rmse.ln()) / (b.rel_rmse.ln() - a.rel_rmse.ln());
            return Some((a.seconds.ln() + t * (b.seconds.ln() - a.seconds.ln())).exp());
        }
    }
    None
}

/// One failure case: a scene and camera where a method breaks, its settings, and what to see.
struct Failure {
    name: &'static str,
    what: &'static str,
    scene: BenchScene,
    method: Method,
    preview: PreviewSettings,
    spp: u32,
}

/// Renders each failure case with the method and with Monte Carlo, side by side (method left,
/// MC right) as `DIR/failure-NAME.png`, and prints a table of their errors against MC.
pub(super) fn bench_dof_failures(resolution: &str, reference_spp: u32, dir: &std::path::Path) -> Result<(), Error> {
    let (w, h) = parse_wxh(resolution)?;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let layers = |count: usize, margin: f64| PreviewSettings {
        layers: LayerSettings { count, margin, spp: 8, ..LayerSettings::default() },
    };
    let fisheye = |method: Method, name: &'static str| -> Result<Failure, Error> {
        let mut s = demo_scene(w, h, false)?;
        let lens = library_lens("fisheye-10mm")?;
        let aspect = w as f64 / h as f64;
        let sensor = Sensor { width_mm: 36.0, height_mm: 36.0 / aspect, ..Sensor::default() };
        s.rig.camera = Camera::Exact(ExactCamera::new(sensor, lens, Some(1.0))?);
        Ok(Failure {
            name,
            what: "a 156° fisheye: ±78° still fits the ±80° planar frame, but its tangent grid spends the texels on the rim",
            scene: s,
            method,
            preview: layers(4, 0.15),
            spp: 64,
        })
    };
    let mut cases = vec![
        fisheye(Method::Ibrt, "wide-angle-ibrt")?,
        Failure {
            name: "near-object-one-layer-ibrt",
            what: "one layer: the blurred near lattice hides the lamps and floor behind it, which no layer holds",
            scene: occluder_scene()?,
            method: Method::Ibrt,
            preview: layers(1, 0.15),
            spp: 64,
        },
        Failure {
            name: "outside-frame-ibrt",
            what: "no layer margin: the lamps just beyond the edge of the frame, far out of focus, blur into it in MC only",
            scene: occluder_scene_shot(0.6, 37.0)?,
            method: Method::Ibrt,
            preview: layers(4, 0.0),
            spp: 64,
        },
        Failure {
            name: "tilt-ibrt",
            what: "not a failure: a tilted sensor is only other camera rays against the same layers",
            scene: demo_scene(w, h, true)?,
            method: Method::Ibrt,
            preview: layers(4, 0.15),
            spp: 64,
        },
    ];
    for method in [Method::Spread, Method::Multiview] {
        cases.push(Failure {
            name: if method == Method::Spread { "near-object-spread" } else { "near-object-multiview" },
            what: "the near lattice far out of focus in front of bright lamps",
            scene: occluder_scene()?,
            method,
            preview: layers(4, 0.15),
            spp: 64,
        });
        cases.push(Failure {
            name: if method == Method::Spread { "tilt-spread" } else { "tilt-multiview" },
            what: "a tilted sensor (Scheimpflug)",
            scene: demo_scene(w, h, true)?,
            method,
            preview: layers(4, 0.15),
            spp: 64,
        });
    }
    println!("| case | method | what | rel. RMSE | mean FLIP | image |");
    println!("|---|---|---|---|---|---|");
    let base = RenderSettings { width: w, height: h, ..RenderSettings::default() };
    for case in &cases {
        let reference = render_one(
            &case.scene,
            Method::Mc,
            &RenderSettings { spp: reference_spp, seed: 99, ..base.clone() },
            None,
        )?;
        let settings = RenderSettings { spp: case.spp, ..base.clone() };
        let (image, _) = match render_one(&case.scene, case.method, &settings, Some(&case.preview)) {
            Ok(r) => r,
            Err(e) => {
                println!("| {} | {} | {} | not run: {e} | | |", case.name, case.method, case.what);
                continue;
            }
        };
        let rel_rmse = relative_rmse(&reference.0, &image)?;
        let flip = flip_mean(&reference.0, &image, 0.0)?;
        let file = format!("failure-{}.png", case.name);
        write_png(&dir.join(&file), &side_by_side(&image, &reference.0), 0.0, ToneMap::Srgb)?;
        println!("| {} | {} | {} | {rel_rmse:.4} | {flip:.4} | {file} |", case.name, case.method, case.what);
    }
    Ok(())
}

/// Two images of one size side by side (a left, b right).
fn side_by_side(a: &Image, b: &Image) -> Image {
    strip(&[a, b])
}

/// Images of one size placed left to right in one image.
fn strip(images: &[&Image]) -> Image {
    let (w, h) = (images[0].width as usize, images[0].height as usize);
    let n = images.len();
    let mut out = Image {
        width: n as u32 * images[0].width,
        height: images[0].height,
        rgba: Vec::with_capacity(n * w * h),
        depth: Vec::with_capacity(n * w * h),
        normal: Vec::with_capacity(n * w * h),
        albedo: Vec::with_capacity(n * w * h),
    };
    for y in 0..h {
        for img in images {
            let row = y * w..(y + 1) * w;
            out.rgba.extend_from_slice(&img.rgba[row.clone()]);
            out.depth.extend_from_slice(&img.depth[row.clone()]);
            out.normal.extend_from_slice(&img.normal[row.clone()]);
            out.albedo.extend_from_slice(&img.albedo[row]);
        }
    }
    out
}
