//! The full render path (camera → integrator → film) against analytic expectations: furnace,
//! thin-lens circle of confusion, flux conservation under defocus, bokeh shapes (blades, cat's
//! eye), the tilted-sensor plane of focus, determinism across thread counts, cancellation.
//!
//! Scenes are built in code. Camera space: metres, looking down −z, thin lens / entrance pupil
//! at the origin. Image coordinates below are in pixels with x to the right and y *up* (row
//! index flipped) unless stated otherwise.

use crate::common::icosphere;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{DAffine3, DVec2, DVec3, Vec2, Vec3, Vec4};
use petzval_renderer::camera::host::{FilmBack, HostCamera};
use petzval_renderer::film::{Image, PixelFilter};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render, CameraRig, RenderResult, RenderSettings};
use petzval_renderer::scene::texture::Wrap;
use petzval_renderer::scene::{demo, Environment, Material, Mesh, Scene, Texture, TextureRef};
use petzval_renderer::{
    library_lens, Aperture, ApertureShape, Camera, ExactCamera, PinholeCamera, Sensor, ShotContext, ThickCamera,
    ThinCamera,
};

// ------------------------------------------------------------------------------------------
// Scene helpers.

fn diffuse(base: Vec3) -> Material {
    Material {
        name: "diffuse".into(),
        base_color: base.extend(1.0),
        metallic: 0.0,
        roughness: 1.0,
        specular: 0.0,
        ..Material::default()
    }
}

/// A black, double-sided emitter of radiance `le` (nothing but its emission reaches the camera).
fn emitter(le: f32) -> Material {
    Material { emissive: Vec3::splat(le), double_sided: true, ..diffuse(Vec3::ZERO) }
}

/// Number of sides of the flat emitter discs (a regular polygon).
const DISC_SIDES: u32 = 64;

/// A flat regular `DISC_SIDES`-gon of circumradius `radius` centred at `c`, facing +z.
fn disc(c: Vec3, radius: f32, material: u32) -> Mesh {
    let n = DISC_SIDES;
    let mut m = Mesh::default();
    m.positions.push(c);
    for k in 0..n {
        let a = std::f32::consts::TAU * k as f32 / n as f32;
        m.positions.push(c + Vec3::new(a.cos(), a.sin(), 0.0) * radius);
    }
    for k in 0..n {
        m.indices.push([0, 1 + k, 1 + (k + 1) % n]);
        m.material_ids.push(material);
    }
    let nv = m.positions.len();
    m.normals = vec![Vec3::Z; nv];
    m.tangents = vec![Vec4::ZERO; nv];
    m.uv0 = vec![Vec2::ZERO; nv];
    m
}

/// E[r²] of a uniform regular n-gon of circumradius `r` about its centre (→ r²/2 for a disc).
fn polygon_mean_r2(r: f64, n: u32) -> f64 {
    r * r * (2.0 + (2.0 * PI / n as f64).cos()) / 6.0
}

/// Area of a regular n-gon of circumradius `r`.
fn polygon_area(r: f64, n: u32) -> f64 {
    0.5 * n as f64 * r * r * (2.0 * PI / n as f64).sin()
}

fn scene_of(meshes: &[Mesh], materials: Vec<Material>, env: Environment) -> RenderScene {
    let mut mesh = Mesh::default();
    for m in meshes {
        mesh.append(m, 0);
    }
    RenderScene::new(Scene { materials, environment: env, ..Scene::world(mesh) }).unwrap()
}

fn settings(w: u32, h: u32, spp: u32, seed: u32, filter: PixelFilter) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        spp,
        seed,
        max_depth: 8,
        spectral: false,
        time_limit: None,
        filter,
        ..RenderSettings::default()
    }
}

const BOX1: PixelFilter = PixelFilter::Box { width_px: 1.0 };

fn shoot(scene: &RenderScene, camera: Camera, to_world: DAffine3, s: &RenderSettings) -> RenderResult {
    let rig = CameraRig { camera, to_world };
    let r = render(scene, &rig, s, &|_| true).unwrap();
    assert!(r.complete);
    assert_eq!(r.spp_done, s.spp);
    assert_eq!(r.dropped_samples, 0, "non-finite samples were dropped");
    r
}

fn shoot_img(scene: &RenderScene, camera: Camera, s: &RenderSettings) -> Image {
    shoot(scene, camera, DAffine3::IDENTITY, s).image
}

fn thin(sensor: Sensor, f_mm: f64, n: f64, focus_m: f64, aperture: Aperture, vignetting: bool) -> Camera {
    Camera::Thin(ThinCamera::new(sensor, f_mm, n, Some(focus_m), aperture).unwrap().with_natural_vignetting(vignetting))
}

fn square_sensor(side_mm: f64) -> Sensor {
    Sensor { width_mm: side_mm, height_mm: side_mm, ..Sensor::default() }
}

/// Red channel (every scene here is grey) as a row-major f64 grid, row 0 at the top.
fn red(img: &Image) -> Vec<f64> {
    img.rgba.iter().map(|p| p[0] as f64).collect()
}

/// Intensity moments of an image in pixel units, y up, about the centroid.
#[derive(Debug, Clone, Copy)]
struct Moments {
    flux: f64,
    cx: f64,
    cy: f64,
    sxx: f64,
    syy: f64,
    sxy: f64,
}

impl Moments {
    fn of(img: &Image) -> Moments {
        let (w, h) = (img.width as usize, img.height as usize);
        let v = red(img);
        let (mut s0, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let i = v[y * w + x];
                s0 += i;
                sx += i * (x as f64 + 0.5);
                sy += i * ((h - y) as f64 - 0.5);
            }
        }
        let (cx, cy) = (sx / s0, sy / s0);
        let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let i = v[y * w + x];
                let dx = x as f64 + 0.5 - cx;
                let dy = (h - y) as f64 - 0.5 - cy;
                xx += i * dx * dx;
                yy += i * dy * dy;
                xy += i * dx * dy;
            }
        }
        Moments { flux: s0, cx, cy, sxx: xx / s0, syy: yy / s0, sxy: xy / s0 }
    }

    fn mean_r2(&self) -> f64 {
        self.sxx + self.syy
    }

    /// Variance along the unit direction `d` (y up).
    fn var_along(&self, d: DVec2) -> f64 {
        d.x * d.x * self.sxx + 2.0 * d.x * d.y * self.sxy + d.y * d.y * self.syy
    }
}

/// Image distance of a point at `s_mm` through Blender's thin lens of focal length `f` (the film
/// distance) focused at `d_mm`: the lens's power is 1/F + 1/d.
fn thin_image_distance_mm(f: f64, d_mm: f64, s_mm: f64) -> f64 {
    1.0 / (1.0 / f + 1.0 / d_mm - 1.0 / s_mm)
}

/// Circle of confusion (diameter on the sensor, mm) of Blender's thin lens: film at F, aperture
/// diameter A = F/N, lens focal length F·d/(F + d) (focused at d), so a point at s images at
/// 1/v = 1/F + 1/d − 1/s and c = A·|F − v|/v = A·F·|1/d − 1/s|.
fn thin_lens_coc_mm(f: f64, n: f64, s_mm: f64, d_mm: f64) -> f64 {
    (f / n) * f * (1.0 / d_mm - 1.0 / s_mm).abs()
}

// ------------------------------------------------------------------------------------------
// 1. Furnace.

/// `mesh` with flat facets: three vertices of its own per triangle, with the face's normal.
fn flat_shaded(mesh: Mesh) -> Mesh {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    for t in &mesh.indices {
        let p = t.map(|i| mesh.positions[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
        positions.extend(p);
        normals.extend([n; 3]);
    }
    let k = positions.len();
    let indices = (0..k as u32 / 3).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    Mesh { positions, normals, indices, tangents: vec![Vec4::ZERO; k], uv0: vec![Vec2::ZERO; k], ..mesh }
}

/// A closed white Lambertian sphere (albedo 1, specular 0, flat facets) in a uniform radiance-1
/// environment, seen through a pinhole without cos⁴: every pixel — sphere, background and the
/// silhouette — must read 1. (With smooth normals, a cosine sample about the shading normal that
/// points below its facet is discarded, as Cycles discards it: about 10⁻⁴ of the samples, whole
/// samples lost in single pixels; `render_furnace_smooth_sphere_loses_almost_nothing` bounds
/// that.)
#[test]
fn render_furnace_white_sphere_pinhole() {
    let rs = scene_of(
        &[flat_shaded(icosphere(Vec3::new(0.0, 0.0, -4.0), 1.0, 4, 0))],
        vec![diffuse(Vec3::ONE)],
        Environment::Constant(Vec3::ONE),
    );
    let cam = PinholeCamera::new(Sensor::default(), 50.0).unwrap().with_natural_vignetting(false);
    let (w, h) = (72, 48);
    let spp = 64;
    // Two independent seeds: their difference measures the per-pixel Monte Carlo noise, so the
    // per-pixel bound is set by the noise actually present (a bias of one pixel or a band would
    // show up as a deviation far outside it).
    let a = shoot_img(&rs, Camera::Pinhole(cam.clone()), &settings(w, h, spp, 1, PixelFilter::default()));
    let b = shoot_img(&rs, Camera::Pinhole(cam), &settings(w, h, spp, 2, PixelFilter::default()));
    let n = (w * h) as usize;
    let covered = a.rgba.iter().filter(|p| p[3] > 0.999).count();
    assert!(covered > n / 5 && covered < n, "the sphere should cover part of the frame: {covered} of {n}");
    let mut sum = [0.0f64; 3];
    let mut diff2 = 0.0f64;
    for i in 0..n {
        for (k, s) in sum.iter_mut().enumerate() {
            *s += 0.5 * (a.rgba[i][k] + b.rgba[i][k]) as f64;
            let d = (a.rgba[i][k] - b.rgba[i][k]) as f64;
            diff2 += d * d;
        }
    }
    // σ of one image's pixel = rms(a − b)/√2
    let sigma = (diff2 / (3 * n) as f64 / 2.0).sqrt();
    let mut worst = 0.0f64;
    for i in 0..n {
        for k in 0..3 {
            worst = worst.max((a.rgba[i][k] as f64 - 1.0).abs());
        }
    }
    let means: Vec<f64> = sum.iter().map(|s| s / n as f64).collect();
    eprintln!(
        "furnace (pinhole): image means {means:?}, per-pixel noise σ = {sigma:.2e}, worst pixel |L−1| = {worst:.2e}"
    );
    // The image average of 2·3456 pixels has noise σ/√6912 ≪ 1%: 1% is a pure bias bound.
    for m in &means {
        assert!((m - 1.0).abs() < 0.01, "image mean {m}");
    }
    // Per pixel: 6σ (one pixel in ~10⁴ beyond 4σ for Gaussian noise; 6σ leaves room for the
    // heavier tail of a few-sample estimate) plus 1e-3 for f32 accumulation.
    assert!(sigma < 0.02, "per-pixel noise σ = {sigma}");
    assert!(worst < 6.0 * sigma + 1e-3, "worst pixel deviates by {worst}, noise σ = {sigma}");
}

/// A white Lambertian icosphere with smooth normals in a uniform radiance-1 environment.
fn smooth_furnace() -> RenderScene {
    scene_of(
        &[icosphere(Vec3::new(0.0, 0.0, -4.0), 1.0, 4, 0)],
        vec![diffuse(Vec3::ONE)],
        Environment::Constant(Vec3::ONE),
    )
}

/// The furnace's sphere with smooth normals: samples below a facet are discarded (see above), a
/// loss bounded here by 0.05 % of the image mean (measured 2026-12-06: 0.005 %).
#[test]
fn render_furnace_smooth_sphere_loses_almost_nothing() {
    let rs = smooth_furnace();
    let cam = PinholeCamera::new(Sensor::default(), 50.0).unwrap().with_natural_vignetting(false);
    let img = shoot_img(&rs, Camera::Pinhole(cam), &settings(72, 48, 64, 1, PixelFilter::default()));
    let mean = img.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / img.rgba.len() as f64;
    eprintln!("smooth furnace: image mean {mean:.6}");
    assert!(mean <= 1.0 + 1e-5 && mean > 1.0 - 5e-4, "image mean {mean}");
}

/// The environment is a light only where it varies with direction, as Cycles samples its world
/// (a uniform world, also when Blender's USD export writes it as an image of one colour, is found
/// by BSDF samples alone).
#[test]
fn only_a_varying_environment_is_a_light() {
    use petzval_renderer::scene::environment::EnvironmentMap;
    let sphere = icosphere(Vec3::new(0.0, 0.0, -4.0), 1.0, 2, 0);
    let map = |texels: Vec<Vec3>| Environment::Map(EnvironmentMap::new("sky", 2, 2, texels, 1.0, 0.0).unwrap());
    let cases = [
        (Environment::Black, 0),
        (Environment::Constant(Vec3::splat(0.3)), 0),
        (map(vec![Vec3::new(0.3, 0.4, 0.5); 4]), 0),
        (map(vec![Vec3::splat(0.3), Vec3::splat(0.3), Vec3::splat(0.3), Vec3::splat(0.31)]), 1),
    ];
    for (env, lights) in cases {
        assert!(env.is_uniform() == (lights == 0), "{env:?}");
        let rs = scene_of(std::slice::from_ref(&sphere), vec![diffuse(Vec3::ONE)], env);
        assert_eq!(rs.light_count(), lights);
    }
}

/// The same furnace through a thin lens at f/2 with natural vignetting off: no falloff at all,
/// so every pixel reads 1 (the exposure normalisation must match the weights actually used).
#[test]
fn render_furnace_thin_lens_without_natural_vignetting() {
    let rs = smooth_furnace();
    let cam = thin(Sensor::default(), 50.0, 2.0, 4.0, Aperture::default(), false);
    let img = shoot_img(&rs, cam, &settings(48, 32, 64, 1, PixelFilter::default()));
    let n = img.rgba.len();
    let mean = img.rgba.iter().map(|p| p[1] as f64).sum::<f64>() / n as f64;
    // Pixels that see only the environment: every camera ray carries the same weight and
    // radiance 1, so they are exactly 1 (up to f32 sums).
    let sky: Vec<f64> = img.rgba.iter().filter(|p| p[3] == 0.0).map(|p| p[1] as f64).collect();
    let (lo, hi) = sky.iter().fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
    eprintln!("furnace (thin f/2, vignetting off): image mean {mean:.4}, {} sky pixels in {lo:.6}..{hi:.6}", sky.len());
    assert!(sky.len() > n / 4);
    assert!(
        lo > 1.0 - 1e-4 && hi < 1.0 + 1e-4,
        "sky pixels {lo}..{hi}: thin lens with natural_vignetting = false is not exposure-normalised"
    );
    // the whole image (sphere noise at 64 spp ≈ 1.2% per pixel): mean within 1%
    assert!((mean - 1.0).abs() < 0.01, "mean {mean}");
}

// ------------------------------------------------------------------------------------------
// 2. Thin-lens circle of confusion.

/// A small flat emitter on the axis, defocused: the blur is the aperture disc scaled by the
/// circle of confusion. Its diameter from the image's second moment must match
/// c = A·F·|1/d − 1/s| (Blender's thin lens) within 2%.
#[test]
fn render_thin_lens_circle_of_confusion() {
    let (f, n_stop, d_mm) = (50.0, 2.0, 2000.0);
    let v_d = thin_image_distance_mm(f, d_mm, d_mm); // = F: the film stays at the focal length
    let (w, h) = (96u32, 96u32);
    // s before and behind the focus distance, and at f/4
    for &(s_mm, n) in &[(1000.0, n_stop), (5000.0, n_stop), (700.0, 4.0)] {
        let c_mm = thin_lens_coc_mm(f, n, s_mm, d_mm);
        // pixel pitch such that the blur disc is 56 px across
        let pitch = c_mm / 56.0;
        let r_src_px = 4.0;
        let rho_m = r_src_px * pitch * s_mm / v_d * 1e-3;
        let rs = scene_of(
            &[disc(Vec3::new(0.0, 0.0, -(s_mm * 1e-3) as f32), rho_m as f32, 0)],
            vec![emitter(1.0)],
            Environment::Black,
        );
        let cam = thin(square_sensor(w as f64 * pitch), f, n, d_mm * 1e-3, Aperture::default(), false);
        let mut st = settings(w, h, 256, 3, BOX1);
        st.max_depth = 1;
        let m = Moments::of(&shoot_img(&rs, cam, &st));
        // The image is (source image) ⊛ (blur disc) ⊛ (1-px box of the filter and pixel area):
        // second moments add. Source: a 64-gon of circumradius r_src_px (magnification v_d/s
        // through the lens centre); box: 1/12 px² per axis.
        let blur_r2 = m.mean_r2() - polygon_mean_r2(r_src_px, DISC_SIDES) - 2.0 / 12.0;
        let measured_c = 2.0 * (2.0 * blur_r2).sqrt() * pitch;
        let err = measured_c / c_mm - 1.0;
        eprintln!("CoC s = {s_mm} mm, f/{n}: measured {measured_c:.5} mm, formula {c_mm:.5} mm ({:+.2}%), centroid ({:.2}, {:.2}) px", err * 100.0, m.cx, m.cy);
        // 2%: the brief's bound. Noise: ~13k source hits, relative σ of E[r²] ≈ 0.6% before
        // stratification, so σ(diameter) ≈ 0.3%.
        assert!(err.abs() < 0.02, "s = {s_mm}: CoC {measured_c} vs {c_mm}");
        // on the axis: centred on the image centre within a pixel
        assert!((m.cx - 48.0).abs() < 1.0 && (m.cy - 48.0).abs() < 1.0);
    }
}

// ------------------------------------------------------------------------------------------
// 3. Flux conservation under defocus.

/// Renders a flat on-axis emitter of fixed angular radius `alpha` (radius ∝ distance) at
/// distance `s_m` and returns the image moments.
fn emitter_moments(cam: &Camera, s_m: f64, alpha: f64, w: u32, spp: u32, seed: u32) -> Moments {
    let rs = scene_of(
        &[disc(Vec3::new(0.0, 0.0, -s_m as f32), (alpha * s_m) as f32, 0)],
        vec![emitter(1.0)],
        Environment::Black,
    );
    let mut st = settings(w, w, spp, seed, BOX1);
    st.max_depth = 1;
    Moments::of(&shoot_img(&rs, cam.clone(), &st))
}

/// Power that an on-axis flat Lambertian emitter of radiance 1 and unit area at distance
/// `s_mm` in front of the entrance pupil sends through `lens` (exact trace, scene to film), per
/// unit area: ∫ cosθ_source dω over the directions that pass, on a 400² grid in tan θ.
fn power_through_lens(lens: &petzval_renderer::Lens, s_mm: f64) -> f64 {
    use petzval_renderer::{Ray, TraceDirection};
    let src = DVec3::new(0.0, 0.0, lens.paraxial().entrance_pupil_z_mm - s_mm);
    // a cone 1.5× the paraxial entrance pupil: everything that passes lies inside it
    let t = 1.5 * 0.5 * lens.paraxial().entrance_pupil_diameter_mm / s_mm;
    let n = 400;
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let d = DVec3::new(
                (2.0 * (i as f64 + 0.5) / n as f64 - 1.0) * t,
                (2.0 * (j as f64 + 0.5) / n as f64 - 1.0) * t,
                1.0,
            );
            // dω = cos³θ dA on the plane z = 1, times the source's cos θ
            let c = 1.0 / d.length();
            if let Some(tr) = lens.trace(&Ray::new(src, d), lens.primary_wavelength_nm(), TraceDirection::SceneToFilm) {
                sum += c.powi(4) * tr.transmission;
            }
        }
    }
    sum * (2.0 * t / n as f64).powi(2)
}

/// The total image flux of a small emitter of fixed angular size does not depend on whether it
/// is in focus: thin lens with and without natural vignetting, and a real lens traced exactly.
#[test]
fn render_defocus_conserves_flux() {
    // Thin lens, f = 50 mm f/2, focused at 2 m; the emitter at 2 m (in focus) and at 0.6 m
    // (blur ≈ 1.5 mm ≈ 60 px across). Box filter: pixel values tile the image plane exactly,
    // so Σ pixels = ∫ image. The source's image is 8 px in radius: its flux is then estimated
    // from ≈ 50k source hits (measured σ over seeds: 0.03% in focus, 0.12% defocused).
    let (f, n, d) = (50.0, 2.0, 2.0);
    let v_d = thin_image_distance_mm(f, d * 1e3, d * 1e3);
    let pitch = 0.025;
    let w = 96u32;
    let r_src_px = 8.0;
    let alpha = r_src_px * pitch / v_d;
    for vignetting in [false, true] {
        let cam = thin(square_sensor(w as f64 * pitch), f, n, d, Aperture::default(), vignetting);
        let focused = emitter_moments(&cam, d, alpha, w, 256, 5);
        let blurred = emitter_moments(&cam, 0.6, alpha, w, 256, 5);
        // Expected ratio under the camera's measurement model: the source's image on the film
        // has the same area for any s (fixed angular size); a film point sees it from lens
        // point l with weight cosθ_film·cosθ_lens/d² = 1/(v_d²(1 + l²/v_s²)²) where v_s is the
        // source's image distance, so the total ∝ ∫_disc (1 + l²/v_s²)⁻² dA = πr²/(1 + r²/v_s²)
        // (+0.66% here). Without vignetting the weight is constant: ratio 1.
        let r = 0.5 * f / n;
        let v_s = thin_image_distance_mm(f, d * 1e3, 600.0);
        let expected = if vignetting { (1.0 + r * r / (v_d * v_d)) / (1.0 + r * r / (v_s * v_s)) } else { 1.0 };
        let ratio = blurred.flux / focused.flux;
        let area = polygon_area(r_src_px, DISC_SIDES);
        eprintln!(
            "flux thin f/2 vignetting {vignetting}: focused {:.3} (flux/area {:.4}), defocused {:.3} (blur r_rms {:.1} px), ratio {ratio:.4}, expected {expected:.4}",
            focused.flux,
            focused.flux / area,
            blurred.flux,
            blurred.mean_r2().sqrt()
        );
        // 1% (the brief), ≈ 8σ of the noise.
        assert!((ratio / expected - 1.0).abs() < 0.01, "vignetting {vignetting}: ratio {ratio}, expected {expected}");
        if vignetting {
            // absolute: the in-focus image of a radiance-1 source reads 1 (exposure normalised
            // at the image centre) over its image, a 64-gon of circumradius 8 px
            assert!((focused.flux / area - 1.0).abs() < 0.01, "in-focus flux {} vs image area {area}", focused.flux);
        }
    }

    // A real lens traced exactly: double-gauss-50mm wide open, focused at 2 m, on the axis.
    // Tracing conserves étendue, so the film receives what passes the stop: for a source of
    // fixed angular size (seen from the paraxial entrance pupil) that is Ω_eff(s)·s², computed
    // independently by tracing from the source through the lens (it differs from 1 by ≈ 0.5%:
    // pupil aberration moves the real entrance pupil for a near source).
    let lens = library_lens("double-gauss-50mm").unwrap();
    let expected =
        power_through_lens(&lens, 600.0) * 0.6f64.powi(2) / (power_through_lens(&lens, 2000.0) * 2.0f64.powi(2));
    let pitch = 0.03125;
    let w = 128u32;
    let cam = Camera::Exact(ExactCamera::new(square_sensor(w as f64 * pitch), lens, Some(d)).unwrap());
    let alpha = r_src_px * pitch / 50.0;
    let focused = emitter_moments(&cam, d, alpha, w, 256, 7);
    let blurred = emitter_moments(&cam, 0.6, alpha, w, 256, 7);
    let ratio = blurred.flux / focused.flux;
    eprintln!(
        "flux double-gauss-50mm f/2: focused {:.2} (r_rms {:.2} px), defocused {:.2} (r_rms {:.1} px), ratio {ratio:.4}, traced power ratio {expected:.4}",
        focused.flux,
        focused.mean_r2().sqrt(),
        blurred.flux,
        blurred.mean_r2().sqrt()
    );
    // 1% (the brief) both against 1 and against the traced power ratio. Measured over seeds
    // 1–9: ratio 1.0043 ± 0.0025 (σ), so 1% is 4σ from the traced value 1.0047.
    assert!((ratio - 1.0).abs() < 0.01, "realistic lens: defocused/focused flux {ratio}");
    assert!(
        (ratio / expected - 1.0).abs() < 0.01,
        "realistic lens: flux ratio {ratio} vs traced power ratio {expected}"
    );
}

// ------------------------------------------------------------------------------------------
// 4. Bokeh shape.

/// Mean of the pixels within `radius` px of (cx, cy) (y up).
fn plateau(img: &Image, cx: f64, cy: f64, radius: f64) -> f64 {
    let (w, h) = (img.width as usize, img.height as usize);
    let v = red(img);
    let (mut s, mut k) = (0.0, 0);
    for y in 0..h {
        for x in 0..w {
            let dx = x as f64 + 0.5 - cx;
            let dy = (h - y) as f64 - 0.5 - cy;
            if dx * dx + dy * dy < radius * radius {
                s += v[y * w + x];
                k += 1;
            }
        }
    }
    s / k as f64
}

/// Orientation of the 6-fold structure: the phase of Σ I·r²·e^{6iφ} / 6 (degrees, y up): the
/// direction of a vertex of a hexagon, in (−30°, 30°].
fn hexagonal_phase_deg(img: &Image, m: &Moments) -> (f64, f64) {
    let (w, h) = (img.width as usize, img.height as usize);
    let v = red(img);
    let (mut re, mut im, mut norm) = (0.0, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let dx = x as f64 + 0.5 - m.cx;
            let dy = (h - y) as f64 - 0.5 - m.cy;
            let r2 = dx * dx + dy * dy;
            let phi = dy.atan2(dx);
            let i = v[y * w + x] * r2;
            re += i * (6.0 * phi).cos();
            im += i * (6.0 * phi).sin();
            norm += i;
        }
    }
    (im.atan2(re).to_degrees() / 6.0, (re * re + im * im).sqrt() / norm)
}

/// Radius (px) at which the profile along direction `phi_deg` (y up) from (cx, cy) falls to
/// `level`, sampling the image bilinearly; averaged over ±2° to reduce noise.
fn boundary_radius(img: &Image, cx: f64, cy: f64, phi_deg: f64, level: f64) -> f64 {
    let (w, h) = (img.width as usize, img.height as usize);
    let v = red(img);
    let sample = |px: f64, py: f64| -> f64 {
        // px, py in pixel units, y up; pixel centres at +0.5
        let x = px - 0.5;
        let y = (h as f64 - py) - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |xi: f64, yi: f64| -> f64 {
            if xi < 0.0 || yi < 0.0 || xi >= w as f64 || yi >= h as f64 {
                0.0
            } else {
                v[yi as usize * w + xi as usize]
            }
        };
        let a = at(x0, y0) * (1.0 - fx) + at(x0 + 1.0, y0) * fx;
        let b = at(x0, y0 + 1.0) * (1.0 - fx) + at(x0 + 1.0, y0 + 1.0) * fx;
        a * (1.0 - fy) + b * fy
    };
    let mut radii = Vec::new();
    for k in -4..=4 {
        let a = (phi_deg + 0.5 * k as f64).to_radians();
        let (dx, dy) = (a.cos(), a.sin());
        // walk outwards, averaging a 3-px wide strip across the direction
        let prof = |r: f64| -> f64 {
            (-1..=1).map(|j| sample(cx + dx * r - dy * j as f64, cy + dy * r + dx * j as f64)).sum::<f64>() / 3.0
        };
        let mut r = 0.0;
        let step = 0.05;
        while prof(r + step) > level && r < w as f64 {
            r += step;
        }
        radii.push(r + 0.5 * step);
    }
    radii.iter().sum::<f64>() / radii.len() as f64
}

/// Six straight blades: the defocused image of a small emitter is a hexagon whose area is
/// 3√3/(2π) of the circle the same f-number gives (the circumscribed circle), oriented with the
/// blade rotation.
#[test]
fn render_bokeh_hexagon_area_and_orientation() {
    let (f, n, d_mm, s_mm) = (50.0, 2.0, 2000.0, 1000.0);
    let v_d = thin_image_distance_mm(f, d_mm, d_mm);
    let c_mm = thin_lens_coc_mm(f, n, s_mm, d_mm);
    let w = 96u32;
    let pitch = c_mm / 60.0; // circumradius 30 px
    let r_src_px = 6.0;
    let rho = r_src_px * pitch * s_mm / v_d * 1e-3;
    let rs = scene_of(
        &[disc(Vec3::new(0.0, 0.0, -(s_mm * 1e-3) as f32), rho as f32, 0)],
        vec![emitter(1.0)],
        Environment::Black,
    );
    let mut st = settings(w, w, 512, 11, BOX1);
    st.max_depth = 1;
    let sensor = square_sensor(w as f64 * pitch);
    let circle = shoot_img(&rs, thin(sensor, f, n, d_mm * 1e-3, Aperture::default(), false), &st);
    let mc = Moments::of(&circle);
    // Both openings have the same circumradius; the flux is the same power per unit aperture
    // area (exposure normalised), so the plateau of a uniform blur = flux / blur area, and
    // area_hex / area_circle = plateau_circle / plateau_hex. Plateaus are averaged inside
    // 0.866·30 − 6 − 1 ≈ 19 px (the hexagon's apothem minus the source radius and a margin).
    let inner = 0.866 * 30.0 - r_src_px - 1.5;
    let p_circle = plateau(&circle, mc.cx, mc.cy, inner);
    for rot_deg in [0.0f64, 13.0, 40.0] {
        let ap = Aperture {
            shape: ApertureShape::Blades { count: 6, curvature: 0.0 },
            rotation_rad: rot_deg.to_radians(),
            anamorphic_ratio: 1.0,
        };
        let hex = shoot_img(&rs, thin(sensor, f, n, d_mm * 1e-3, ap, false), &st);
        let mh = Moments::of(&hex);
        let p_hex = plateau(&hex, mh.cx, mh.cy, inner);
        let ratio = p_circle / p_hex;
        let expected = 3.0 * 3f64.sqrt() / (2.0 * PI);
        // Orientation. Aperture rotation is counter-clockwise seen from the film, i.e. in the
        // camera's x-right/y-up frame; the emitter is nearer than the focus, so its blur is the
        // aperture shape upright on the film and rotated by 180° in the (inverted) image: for a
        // hexagon the same set of vertex directions, rot + k·60°.
        let (phase, strength) = hexagonal_phase_deg(&hex, &mh);
        // edge middles at the rotation (Blender's convention), vertices 30° further
        let want = (rot_deg + 30.0 + 30.0).rem_euclid(60.0) - 30.0;
        let dphase = ((phase - want + 30.0).rem_euclid(60.0) - 30.0).abs();
        // Boundary at 12 angles: vertices (rot + k·60°) lie at the circumradius, edge midpoints
        // (rot + 30° + k·60°) at the apothem R·cos 30°. Half-plateau crossings; the source
        // disc (6 px) rounds the vertices, so their radius is compared loosely.
        let (mut rv, mut re) = (Vec::new(), Vec::new());
        for k in 0..6 {
            let a = rot_deg + 30.0 + 60.0 * k as f64;
            rv.push(boundary_radius(&hex, mh.cx, mh.cy, a, 0.5 * p_hex));
            re.push(boundary_radius(&hex, mh.cx, mh.cy, a + 30.0, 0.5 * p_hex));
        }
        let min_v = rv.iter().cloned().fold(f64::MAX, f64::min);
        let max_e = re.iter().cloned().fold(f64::MIN, f64::max);
        let mean_e = re.iter().sum::<f64>() / 6.0;
        eprintln!(
            "hexagon rot {rot_deg}°: area ratio {ratio:.4} (expected {expected:.4}), vertex phase {phase:.2}° (want {want:.2}°, 6-fold strength {strength:.3}), vertex radii {rv:.2?}, edge radii {re:.2?}",
        );
        // 3% (the brief); the plateau means have ≈ 0.5% noise each.
        assert!((ratio / expected - 1.0).abs() < 0.03, "rot {rot_deg}: area ratio {ratio} vs {expected}");
        // 1.5°: a 1° rotation moves a vertex of a 30-px hexagon by 0.5 px; the phase estimate
        // over the whole blur is much finer than that.
        assert!(dphase < 1.5, "rot {rot_deg}: vertex direction {phase}° vs {want}°");
        // every vertex direction reaches further than every edge-midpoint direction (a 30°
        // error in orientation would swap them), by 1.155 for a sharp hexagon; the 6-px source
        // disc rounds the corners to ≈ 1.09 (half-level contour of the corner blurred by it)
        let mean_v = rv.iter().sum::<f64>() / 6.0;
        assert!(min_v > max_e, "rot {rot_deg}: vertices ({rv:?}) must lie outside the edge midpoints ({re:?})");
        assert!(mean_v / mean_e > 1.06, "rot {rot_deg}: vertex/edge radius {}", mean_v / mean_e);
        // apothem: the half-level crossing of a straight edge blurred by a symmetric kernel is
        // the edge itself: 30 px · cos 30° (2% allows for the pixel grid and noise)
        assert!((mean_e / (30.0 * 0.866) - 1.0).abs() < 0.02, "apothem {mean_e}");
    }
    // the circle has no 6-fold structure
    let (_, s_circle) = hexagonal_phase_deg(&circle, &mc);
    assert!(s_circle < 0.01, "circle 6-fold strength {s_circle}");
}

/// Spread of a blur along the radial (towards the image centre / optical axis) and tangential
/// directions, with the source's own extent (a uniform disc of radius `r_src` px, variance
/// r²/4 per axis) and the box filter (1/12 px²) removed.
fn radial_tangential_sigma(m: &Moments, axis_px: DVec2, r_src: f64) -> (f64, f64) {
    let mut radial = DVec2::new(m.cx, m.cy) - axis_px;
    if radial.length() < 1e-9 {
        radial = DVec2::X;
    }
    let radial = radial.normalize();
    let tangential = DVec2::new(-radial.y, radial.x);
    let extra = r_src * r_src / 4.0 + 1.0 / 12.0;
    ((m.var_along(radial) - extra).sqrt(), (m.var_along(tangential) - extra).sqrt())
}

/// A real lens wide open: an on-axis defocused emitter blurs into a round disc, one near the
/// corner of a full-frame image into a cat's eye (clipped by the element rims), narrower in the
/// radial than in the tangential direction.
#[test]
fn render_bokeh_cats_eye_double_gauss() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    let pitch = 0.03125;
    let w = 128u32;
    let r_src_px = 2.0;
    let mut results = Vec::new();
    // A 4 mm square window on a full-frame sensor, shifted to the axis and towards the corner
    // (15, 10) mm — 18 mm off axis, 83% of the full-frame half-diagonal.
    for shift in [DVec2::ZERO, DVec2::new(15.0, 10.0)] {
        let sensor =
            Sensor { width_mm: w as f64 * pitch, height_mm: w as f64 * pitch, shift_mm: shift, ..Sensor::default() };
        let cam = Camera::Exact(ExactCamera::new(sensor, lens.clone(), Some(2.0)).unwrap());
        // aim the emitter along the ray through the window centre and the pupil centre
        let ray =
            cam.generate_ray(DVec2::new(0.5, 0.5), DVec2::new(0.5, 0.5), 587.56).expect("window centre sees the scene");
        let s = 0.7;
        let dist = s / -ray.direction.z;
        let p = ray.origin + ray.direction * dist;
        let rho = r_src_px * pitch / 50.0 * dist;
        // an icosphere looks like the same disc from every lens point
        let rs = scene_of(&[icosphere(p.as_vec3(), rho as f32, 3, 0)], vec![emitter(1.0)], Environment::Black);
        let mut st = settings(w, w, 256, 13, BOX1);
        st.max_depth = 1;
        let m = Moments::of(&shoot_img(&rs, cam.clone(), &st));
        // optical axis in image pixels (y up)
        let a = sensor.axis_film_coord();
        let axis_px = DVec2::new(a.x * w as f64, (1.0 - a.y) * w as f64);
        let (sr, stg) = radial_tangential_sigma(&m, axis_px, r_src_px);
        eprintln!("cat's eye shift {shift}: centroid ({:.1}, {:.1}) px, σ radial {sr:.2} px, σ tangential {stg:.2} px, ratio {:.3}, flux {:.1}", m.cx, m.cy, sr / stg, m.flux);
        results.push((sr, stg, m));
    }
    let (sr0, st0, m0) = results[0];
    // on axis: round within 5% (rotational symmetry; the measured ratio of two σ estimates each
    // from ≈ 3k hits has ≈ 2% noise)
    assert!((sr0 / st0 - 1.0).abs() < 0.05, "on-axis blur not round: {sr0} vs {st0}");
    assert!((m0.cx - 64.0).abs() < 1.5 && (m0.cy - 64.0).abs() < 1.5, "on-axis blur not centred");
    let (sr1, st1, _) = results[1];
    // off axis: a cat's eye
    assert!(sr1 / st1 < 0.9, "corner blur should be narrower radially: σr {sr1}, σt {st1}");
    // and the cat's eye is cut from the full disc, not a scaled copy of it
    assert!(st1 < st0 * 1.05, "tangential width {st1} vs on-axis {st0}");
}

/// Bokeh light paths (issue 14): light traced from the emitter through the lens and combined
/// with camera paths by MIS gives the image of camera paths alone, within noise, with far less
/// noise at equal samples. A defocused emitter through the real lens wide open, on the axis and
/// in the corner (a cat's eye: element rims), half hidden behind an occluder (visibility), with
/// the default Blackman–Harris filter (splat weights), a crop window, and a camera moved and
/// turned in the world (the light tracer's frames). At least 55 % of the light paths reach the
/// window: in the corner 65 %, aiming at the part of the disc the emitter's light passes (37 %
/// when they aimed at the whole disc).
#[test]
fn bokeh_light_paths_match_camera_paths_with_less_noise() {
    let lens = library_lens("double-gauss-50mm").unwrap();
    let exact = |sensor: Sensor| Camera::Exact(ExactCamera::new(sensor, lens.clone(), Some(2.0)).unwrap());
    check_bokeh_light_paths(
        "exact",
        &exact,
        &[(DVec2::ZERO, false), (DVec2::new(15.0, 10.0), false), (DVec2::ZERO, true)],
        0.55,
    );
}

/// Bokeh light paths through Blender's thin lens and the thick-lens model: the same checks as
/// for the real lens, on the axis and off it (where the thin lens's slope mapping departs most
/// from étendue conservation, which the light tracer's Jacobian accounts for), with and without
/// natural vignetting, a 6-bladed stop, and a tilted sensor. At least 60 % of the light paths
/// reach the window (the disc is the opening's bounding circle: 94 % for a round opening, 78 %
/// for six blades, 69 % with the occluder).
#[test]
fn bokeh_light_paths_through_thin_and_thick_lenses() {
    let blades = Aperture { shape: ApertureShape::Blades { count: 6, curvature: 0.0 }, ..Aperture::default() };
    let thin_vignetting = |sensor: Sensor| thin(sensor, 50.0, 2.0, 10.0, Aperture::default(), true);
    let thin_flat_blades = |sensor: Sensor| thin(sensor, 50.0, 2.0, 10.0, blades.clone(), false);
    let thin_tilted =
        |sensor: Sensor| thin(Sensor { tilt_x_deg: 5.0, ..sensor }, 50.0, 2.0, 10.0, Aperture::default(), true);
    let lens = library_lens("double-gauss-50mm").unwrap();
    let thick = |sensor: Sensor| {
        Camera::Thick(ThickCamera::new(sensor, &lens, Some(2.0), Some(10.0), Aperture::default()).unwrap())
    };
    let cases = [(DVec2::ZERO, false), (DVec2::new(15.0, 10.0), false)];
    check_bokeh_light_paths("thin", &thin_vignetting, &cases, 0.6);
    check_bokeh_light_paths("thin, no vignetting, 6 blades", &thin_flat_blades, &cases, 0.6);
    check_bokeh_light_paths("thin, tilted 5°", &thin_tilted, &cases[..1], 0.6);
    check_bokeh_light_paths("thick", &thick, &[(DVec2::new(15.0, 10.0), false), (DVec2::ZERO, true)], 0.6);
}

/// The checks of the two tests above for the camera `make(sensor)` makes, one per (sensor
/// shift, occluder) case: an emitter 0.7 m deep on the window centre's ray, far out of focus.
fn check_bokeh_light_paths(name: &str, make: &dyn Fn(Sensor) -> Camera, cases: &[(DVec2, bool)], min_reached: f64) {
    let pitch = 0.0625;
    let w = 64u32;
    let to_world = DAffine3::from_rotation_translation(
        glam::DQuat::from_euler(glam::EulerRot::YXZ, 0.4, -0.2, 0.1),
        DVec3::new(1.0, 0.5, -2.0),
    );
    for &(shift, occluded) in cases {
        let sensor =
            Sensor { width_mm: w as f64 * pitch, height_mm: w as f64 * pitch, shift_mm: shift, ..Sensor::default() };
        let cam = make(sensor);
        let ray =
            cam.generate_ray(DVec2::new(0.5, 0.5), DVec2::new(0.5, 0.5), 587.56).expect("window centre sees the scene");
        let dist = 0.7 / -ray.direction.z;
        let p = ray.origin + ray.direction * dist;
        let mut meshes =
            vec![icosphere(to_world.transform_point3(p).as_vec3(), (1.0 * pitch / 50.0 * dist) as f32, 3, 0)];
        if occluded {
            // a black ball halfway, off the chief ray: it hides part of the lens from the emitter
            let q = ray.origin + ray.direction * (0.5 * dist) + DVec3::new(0.012, 0.0, 0.0);
            meshes.push(icosphere(to_world.transform_point3(q).as_vec3(), 0.01, 3, 1));
        }
        let rs = scene_of(&meshes, vec![emitter(1.0), diffuse(Vec3::ZERO)], Environment::Black);
        let st = |spp: u32, seed: u32, paths: f32| RenderSettings {
            width: w,
            height: w,
            spp,
            seed,
            max_depth: 1,
            crop: Some([3, 0, w, w - 5]),
            bokeh_paths: paths,
            ..RenderSettings::default()
        };
        let img = |s: &RenderSettings| red(&shoot(&rs, cam.clone(), to_world, s).image);
        let reference = img(&st(1024, 1, 0.0));
        let camera = [img(&st(16, 2, 0.0)), img(&st(16, 3, 0.0))];
        let light = [img(&st(16, 2, 1.0)), img(&st(16, 3, 1.0))];
        let lit = shoot(&rs, cam.clone(), to_world, &st(4, 4, 1.0));
        let reached = lit.light_paths_landed as f64 / lit.light_paths as f64;
        eprintln!(
            "{name}, shift {shift}, occluded {occluded}: {:.1} % of light paths reached the window",
            100.0 * reached
        );
        assert!(
            reached >= min_reached,
            "{name}, shift {shift}: {:.1} % of light paths reached the window",
            100.0 * reached
        );
        let sum = |v: &[f64]| v.iter().sum::<f64>();
        let rms =
            |a: &[f64], b: &[f64]| (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        let flux_ref = sum(&reference);
        let flux_light = 0.5 * (sum(&light[0]) + sum(&light[1]));
        let noise_camera = rms(&camera[0], &camera[1]);
        let noise_light = rms(&light[0], &light[1]);
        let mean_light: Vec<f64> = light[0].iter().zip(&light[1]).map(|(a, b)| 0.5 * (a + b)).collect();
        // the reference's own noise, as at 1024 spp, and the pair mean's
        let err = rms(&mean_light, &reference);
        let expected = ((noise_light * noise_light / 4.0) + noise_camera * noise_camera / 128.0).sqrt();
        eprintln!(
            "bokeh paths, {name}, shift {shift}, occluded {occluded}: flux {flux_light:.2} vs {flux_ref:.2}, noise {noise_light:.4} vs camera {noise_camera:.4}, rms vs reference {err:.4} (noise alone {expected:.4})"
        );
        assert!(flux_ref > 1.0, "{name}: the emitter is not in the window");
        // flux: within 2.5 % (the 1024-spp camera reference's flux is itself noisy to about 1 %:
        // on the axis it reads 1.9 % below the light paths' at 1024 spp and 0.9 % at 8192)
        assert!((flux_light / flux_ref - 1.0).abs() < 0.025, "{name}: flux {flux_light} vs {flux_ref}");
        // per pixel: the difference is the noise, not a bias pattern (within 1.5× the noise)
        assert!(err < 1.5 * expected, "{name}: rms {err} against noise {expected}");
        // and the light paths make it at least 3× less noisy at equal samples
        assert!(noise_light * 3.0 < noise_camera, "{name}: noise {noise_light} vs {noise_camera}");
    }
}

/// An emitter in focus, large on the film (Blender's thin lens): inside its sharp image every
/// camera sample hits it, so camera paths alone are nearly noiseless there; light paths would
/// land a random number of times per pixel. Its points are blurred by less than the defocus
/// threshold, so no light path is traced and the image is the camera paths' alone, bit for bit.
#[test]
fn bokeh_light_paths_leave_sharp_emitters_to_camera_paths() {
    let cam = thin(square_sensor(4.0), 50.0, 2.8, 1.0, Aperture::default(), true);
    // 1.05 m deep: a blur of 17.9 mm × 50 mm × |1/1050 − 1/1000| ≈ 0.04 mm ≈ 0.6 px at 64 px
    let rs = scene_of(&[icosphere(Vec3::new(0.0, 0.0, -1.05), 0.02, 3, 0)], vec![emitter(1.0)], Environment::Black);
    let st = |paths: f32| RenderSettings {
        width: 64,
        height: 64,
        spp: 8,
        seed: 4,
        max_depth: 1,
        bokeh_paths: paths,
        ..RenderSettings::default()
    };
    let with = shoot(&rs, cam.clone(), DAffine3::IDENTITY, &st(1.0)).image;
    let without = shoot(&rs, cam, DAffine3::IDENTITY, &st(0.0)).image;
    assert!(red(&without).iter().sum::<f64>() > 10.0, "the emitter is not in view");
    assert_eq!(with.rgba, without.rgba);
}

/// Light paths go to the emitters the lens sees. A bright emitter in the frame but hidden from
/// the whole lens behind a wall keeps only one probe's share (1/16) of the light paths its flux
/// would give it, so the visible emitter's bokeh stays nearly as clean as without it (measured
/// 1.3× the noise). Chosen by flux alone, the hidden one (9× the visible one's flux) takes 90 %
/// of the light paths, all blocked, and the noise is 2.7× (the test fails).
#[test]
fn bokeh_light_paths_skip_emitters_the_lens_cannot_see() {
    let cam = thin(square_sensor(4.0), 50.0, 2.8, 1.0, Aperture::default(), true);
    // A black wall over the left of the view at 1.5 m, from x = −2 mm outwards.
    let wall = Mesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, -1.5),
            Vec3::new(-0.002, -1.0, -1.5),
            Vec3::new(-0.002, 1.0, -1.5),
            Vec3::new(-1.0, 1.0, -1.5),
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![1, 1],
        normals: vec![Vec3::Z; 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::ZERO; 4],
        ..Mesh::default()
    };
    // Both emitters blurred about as much as their size (ρ ≈ 1): light paths serve them.
    let visible = icosphere(Vec3::new(0.04, 0.0, -2.0), 0.01, 2, 0);
    let hidden = icosphere(Vec3::new(-0.06, 0.0, -3.0), 0.02, 2, 2);
    let materials = vec![emitter(1.0), diffuse(Vec3::ZERO), emitter(5.0)];
    let image = |meshes: &[Mesh], seed: u32| {
        let rs = scene_of(meshes, materials.clone(), Environment::Black);
        let st = RenderSettings {
            width: 64,
            height: 64,
            spp: 16,
            seed,
            max_depth: 1,
            bokeh_paths: 1.0,
            ..RenderSettings::default()
        };
        red(&shoot(&rs, cam.clone(), DAffine3::IDENTITY, &st).image)
    };
    let without = [image(&[visible.clone(), wall.clone()], 1), image(&[visible.clone(), wall.clone()], 2)];
    let with = [
        image(&[visible.clone(), wall.clone(), hidden.clone()], 1),
        image(&[visible.clone(), wall.clone(), hidden.clone()], 2),
    ];
    let unwalled = image(&[visible.clone(), hidden], 1);
    let sum = |img: &[f64]| img.iter().sum::<f64>();
    assert!(sum(&without[0]) > 1.0, "the visible emitter is not in view");
    assert!(sum(&unwalled) > 3.0 * sum(&without[0]), "the hidden emitter is not in the frame behind the wall");
    // Noise of the visible emitter's bokeh: the two seeds' RMS difference over its pixels.
    let bokeh: Vec<usize> =
        (0..without[0].len()).filter(|&i| without[0][i] + without[1][i] > 0.2 * sum(&without[0]) / 64.0).collect();
    assert!(bokeh.len() > 40, "{} bokeh pixels", bokeh.len());
    let noise =
        |a: &[f64], b: &[f64]| (bokeh.iter().map(|&i| (a[i] - b[i]).powi(2)).sum::<f64>() / bokeh.len() as f64).sqrt();
    let (n_without, n_with) = (noise(&without[0], &without[1]), noise(&with[0], &with[1]));
    assert!(n_without > 0.0);
    assert!(n_with < 2.0 * n_without, "noise with the hidden emitter {n_with:.4}, without {n_without:.4}");
}

/// Adaptive sampling with bokeh light paths: once the pixels a sample's light paths land in
/// have stopped, fewer light paths are traced (the share of the splats in pixels still
/// sampled), and the splats are scaled by the light paths actually traced, so the bokeh keeps
/// its flux. A defocused emitter on black: the black pixels stop at the first test, the
/// bokeh's rim before its middle.
#[test]
fn bokeh_light_paths_follow_adaptive_sampling() {
    let cam = thin(square_sensor(4.0), 50.0, 2.8, 1.0, Aperture::default(), true);
    let rs = scene_of(&[icosphere(Vec3::new(0.0, 0.0, -2.0), 0.01, 2, 0)], vec![emitter(1.0)], Environment::Black);
    let base =
        RenderSettings { width: 64, height: 64, max_depth: 1, bokeh_paths: 1.0, spp: 512, ..RenderSettings::default() };
    let rig = CameraRig { camera: cam, to_world: DAffine3::IDENTITY };
    let run = |s: &RenderSettings| render(&rs, &rig, s, &|_| true).unwrap();
    let flux = |r: &RenderResult| red(&r.image).iter().sum::<f64>();
    let reference = flux(&run(&RenderSettings { spp: 1024, seed: 99, ..base.clone() }));
    let k = 64 * 64;
    for seed in [1, 2] {
        let adaptive = run(&RenderSettings { adaptive_threshold: 0.002, seed, ..base.clone() });
        let (paths, max_spp) = (adaptive.light_paths, adaptive.spp_done as u64);
        let ratio = flux(&adaptive) / reference;
        eprintln!(
            "seed {seed}: {max_spp} spp at most, {:.1} on average; light paths {paths} = {:.3} of K × {max_spp}; flux / reference {ratio:.4}",
            adaptive.camera_rays as f64 / k as f64,
            paths as f64 / (k * max_spp) as f64
        );
        assert!(max_spp > 64 && paths < k * max_spp * 85 / 100, "light paths {paths}, at most {max_spp} spp");
        assert!((ratio - 1.0).abs() < 0.01, "flux {ratio:.4} of the reference's");
        if seed == 1 {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            let one = pool.install(|| run(&RenderSettings { adaptive_threshold: 0.002, seed, ..base.clone() }));
            assert!(bits(&one.image) == bits(&adaptive.image), "1 thread and the pool's differ");
        }
    }
}

/// Light paths need a camera that can trace light onto its film: asked of a pinhole, the
/// render says so.
#[test]
fn bokeh_light_paths_need_a_lens() {
    let rs = scene_of(&[icosphere(Vec3::new(0.0, 0.0, -2.0), 0.05, 1, 0)], vec![emitter(1.0)], Environment::Black);
    let cam = Camera::Pinhole(PinholeCamera::new(square_sensor(36.0), 50.0).unwrap());
    let s = RenderSettings { width: 8, height: 8, spp: 1, bokeh_paths: 1.0, ..RenderSettings::default() };
    let rig = CameraRig { camera: cam, to_world: DAffine3::IDENTITY };
    let err = render(&rs, &rig, &s, &|_| true).unwrap_err().to_string();
    assert!(err.contains("bokeh_paths") && err.contains("pinhole"), "{err}");
}

// ------------------------------------------------------------------------------------------
// 5. Tilted sensor: the plane of sharp focus on the ground.

/// Ground scene: an emissive plane y = −h (world) carrying vertical stripes of a fixed image
/// period: u = K·x_c/(−z_c) in the camera frame, so lines of constant u are planes through the
/// camera's vertical axis. The ground is a grid of thin cells (2% in depth, 0.025 in x/|z|
/// across), with u set per vertex: u is exact along the cell edges of constant depth and its
/// bilinear error inside a cell is below 0.01 stripe periods.
fn striped_ground(h: f64, cam_to_world: &DAffine3, stripes_per_radian: f64) -> RenderScene {
    let texture = Texture {
        name: "stripes".into(),
        width: 2,
        height: 1,
        texels: vec![Vec4::new(0.2, 0.2, 0.2, 1.0), Vec4::ONE],
        wrap_s: Wrap::Repeat,
        wrap_t: Wrap::Repeat,
        bilinear: false,
        srgb_encoded: false,
    };
    let to_cam = cam_to_world.inverse();
    let mut mesh = Mesh::default();
    let columns = 48;
    let q = |k: i32| -> f64 { 0.6 * (2.0 * k as f64 / columns as f64 - 1.0) };
    let mut z0 = -0.02f64;
    while z0 > -400.0 {
        let z1 = z0 * 1.02;
        for k in 0..columns {
            let corners = [
                DVec3::new(q(k) * -z0, -h, z0),
                DVec3::new(q(k + 1) * -z0, -h, z0),
                DVec3::new(q(k + 1) * -z1, -h, z1),
                DVec3::new(q(k) * -z1, -h, z1),
            ];
            let base = mesh.positions.len() as u32;
            for c in corners {
                let pc = to_cam.transform_point3(c);
                let u = stripes_per_radian * pc.x / -pc.z;
                mesh.positions.push(c.as_vec3());
                mesh.normals.push(Vec3::Y);
                mesh.tangents.push(Vec4::ZERO);
                mesh.uv0.push(Vec2::new(u as f32, 0.5));
            }
            mesh.indices.push([base, base + 1, base + 2]);
            mesh.indices.push([base, base + 2, base + 3]);
            mesh.material_ids.extend([0, 0]);
        }
        z0 = z1;
    }
    let mat = Material {
        emissive: Vec3::ONE,
        emissive_texture: Some(TextureRef { index: 0, uv_set: 0, transform: None }),
        ..emitter(1.0)
    };
    RenderScene::new(Scene { materials: vec![mat], textures: vec![Arc::new(texture)], ..Scene::world(mesh) }).unwrap()
}

/// Per-row sharpness: mean |∂x I| / mean I over the central columns; `None` where the row is
/// not entirely ground.
fn row_sharpness(img: &Image) -> Vec<Option<f64>> {
    let (w, h) = (img.width as usize, img.height as usize);
    (0..h)
        .map(|y| {
            let row = &img.rgba[y * w..(y + 1) * w];
            if row.iter().any(|p| p[3] < 0.999) {
                return None;
            }
            let (x0, x1) = (w / 8, w - w / 8);
            let grad: f64 = (x0..x1).map(|x| (row[x + 1][0] - row[x][0]).abs() as f64).sum();
            let mean: f64 = (x0..=x1).map(|x| row[x][0] as f64).sum::<f64>() / (x1 - x0 + 1) as f64;
            Some(grad / (x1 - x0) as f64 / mean)
        })
        .collect()
}

/// Predicted sharpest row (fractional, row index from the top, pixel centres at +0.5): where the
/// chief ray of the centre column meets the ground and the plane of focus at the same distance.
fn predicted_sharp_row(cam: &Camera, ground_n: DVec3, h: f64, rows: u32) -> Option<f64> {
    let plane = cam.focus_plane()?;
    let gap = |y: f64| -> Option<f64> {
        let ray = cam.generate_ray(DVec2::new(0.5, y / rows as f64), DVec2::new(0.5, 0.5), 587.56)?;
        let den = ground_n.dot(ray.direction);
        if den >= 0.0 {
            return None;
        }
        let t_ground = (-h - ground_n.dot(ray.origin)) / den;
        let t_focus = plane.intersect(ray.origin, ray.direction).unwrap_or(f64::INFINITY);
        Some(t_ground - t_focus)
    };
    let mut prev: Option<(f64, f64)> = None;
    for k in 0..=(rows * 8) {
        let y = k as f64 / 8.0;
        let Some(g) = gap(y) else {
            prev = None;
            continue;
        };
        if let Some((py, pg)) = prev {
            if pg.signum() != g.signum() {
                return Some(py + (y - py) * pg / (pg - g));
            }
        }
        prev = Some((y, g));
    }
    None
}

/// Measured sharpest row (fractional, pixel centres at +0.5): the best row of the 3-row
/// smoothed sharpness ratio, refined by the vertex of a least-squares parabola through the raw
/// ratio of the 7 rows around it. Returns (row, peak of the smoothed ratio).
fn measured_sharp_row(ratio: &[Option<f64>]) -> (f64, f64) {
    let n = ratio.len();
    let smooth: Vec<Option<f64>> = (0..n)
        .map(|y| {
            if y == 0 || y + 1 >= n {
                return None;
            }
            Some((ratio[y - 1]? + ratio[y]? + ratio[y + 1]?) / 3.0)
        })
        .collect();
    let (best, peak) = smooth.iter().enumerate().filter_map(|(y, v)| v.map(|v| (y, v))).fold((0, f64::MIN), |a, b| {
        if b.1 > a.1 {
            b
        } else {
            a
        }
    });
    // normal equations for r = c0 + c1·t + c2·t², t = y − best
    let mut m = [[0.0f64; 3]; 3];
    let mut rhs = [0.0f64; 3];
    for (y, r) in ratio.iter().enumerate().take((best + 4).min(n)).skip(best.saturating_sub(3)) {
        let Some(r) = *r else { continue };
        let t = y as f64 - best as f64;
        let basis = [1.0, t, t * t];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += basis[i] * basis[j];
            }
            rhs[i] += basis[i] * r;
        }
    }
    let det3 = |m: &[[f64; 3]; 3]| -> f64 {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let solve = |k: usize| -> f64 {
        let mut mk = m;
        for i in 0..3 {
            mk[i][k] = rhs[i];
        }
        det3(&mk) / det3(&m)
    };
    let (c1, c2) = (solve(1), solve(2));
    let off = if c2 < 0.0 { (-c1 / (2.0 * c2)).clamp(-3.0, 3.0) } else { 0.0 };
    (best as f64 + 0.5 + off, peak)
}

/// Thin lens f = 50 mm f/2 over a striped ground: the band of sharp rows lies where the
/// `FocusPlane` meets the ground, for an untilted and a tilted sensor; with the tilt from the
/// hinge rule the whole ground is sharp.
#[test]
fn render_tilted_sensor_focus_on_the_ground() {
    let (f, n) = (50.0, 2.0);
    let pitch_down = 8f64.to_radians();
    let to_world = DAffine3::from_rotation_x(-pitch_down);
    // ground normal (world +y) in camera space; the ground is {p : n·p = −h}
    let ground_n = to_world.matrix3.transpose() * DVec3::Y;
    let (w, rows) = (192u32, 128u32);
    let sensor = Sensor { width_mm: 36.0, height_mm: 24.0, ..Sensor::default() };
    // stripes: one period per 4 px
    let px_mm = 36.0 / w as f64;
    let stripes_per_radian = 50.0 / (4.0 * px_mm);
    let st = settings(w, rows, 64, 17, PixelFilter::default());
    let st_ref = settings(w, rows, 16, 17, PixelFilter::default());

    // The ratio to an f/500 reference with the same focus and tilt (the same image mapping, and
    // a blur below 0.02 px) removes the dependence of the metric on the stripe contrast and the
    // pixel filter, leaving the defocus alone.
    let ratio_for = |rs: &RenderScene, tilt_x: f64, focus_m: f64| -> (Vec<Option<f64>>, Camera) {
        let sensor = Sensor { tilt_x_deg: tilt_x, ..sensor };
        let cam = thin(sensor, f, n, focus_m, Aperture::default(), true);
        let reference = thin(sensor, f, 500.0, focus_m, Aperture::default(), true);
        let img = shoot(rs, cam.clone(), to_world, &st).image;
        let img_ref = shoot(rs, reference, to_world, &st_ref).image;
        let (a, b) = (row_sharpness(&img), row_sharpness(&img_ref));
        let ratio = a.iter().zip(&b).map(|(a, b)| Some(a.as_ref()? / b.as_ref()?)).collect();
        (ratio, cam)
    };

    // (a) untilted, focused at 0.25 m; (b) tilted by +3° and focused at 0.6 m: the plane of
    // focus leans towards the ground and meets it at another row. The lens is 6 cm above the
    // ground (a table-top scene), so the blur grows by A·cos 8°/h ≈ 0.41 px per row away from
    // the sharp row (the inverse depth of a plane is affine in the image) and the sharp band
    // is a few rows wide.
    let h = 0.06;
    let rs = striped_ground(h, &to_world, stripes_per_radian);
    let mut rows_found = Vec::new();
    for (tilt, focus) in [(0.0, 0.25), (3.0, 0.6)] {
        let (ratio, cam) = ratio_for(&rs, tilt, focus);
        let predicted =
            predicted_sharp_row(&cam, ground_n, h, rows).expect("the plane of focus meets the ground in the image");
        let (measured, peak) = measured_sharp_row(&ratio);
        let ground_rows = ratio.iter().flatten().count();
        let sharp_rows = ratio.iter().flatten().filter(|r| **r > 0.8 * peak).count();
        eprintln!("tilt {tilt}°, focus {focus} m: sharpest row measured {measured:.2}, predicted {predicted:.2}; {sharp_rows} of {ground_rows} ground rows within 80% of the peak {peak:.3}");
        let mut line = String::new();
        for (y, r) in ratio.iter().enumerate() {
            if let Some(r) = r {
                if (y as f64 - predicted).abs() < 10.0 {
                    line += &format!("{y}:{r:.2} ");
                }
            }
        }
        eprintln!("  ratio by row: {line}");
        // 1 row: the ratio falls by ≈ 10% within 2–3 rows of the sharp row (blur ≈ 1 px for a
        // 4-px stripe period), and the parabola vertex of 7 rows, each the mean of 144 pixels,
        // locates the peak to a fraction of a row.
        assert!((measured - predicted).abs() < 1.0, "tilt {tilt}: sharpest row {measured} vs predicted {predicted}");
        assert!(peak > 0.9, "the sharp band should be as sharp as the reference: {peak}");
        assert!(sharp_rows < ground_rows / 4, "only a band should be sharp: {sharp_rows} of {ground_rows}");
        rows_found.push(predicted);
    }
    assert!((rows_found[0] - rows_found[1]).abs() > 10.0, "the two cases should put the band on different rows");

    // (c) The hinge rule, lens 0.3 m above the ground: choose tilt and focus so that the plane
    // of focus is the ground. Two ground points on the vertical midline and their thin-lens
    // conjugates fix the sensor plane (a thin lens maps planes to planes).
    let h = 0.3;
    let rs = striped_ground(h, &to_world, stripes_per_radian);
    let ground_point = |dist_m: f64| -> DVec3 {
        // the ground point straight ahead at horizontal distance dist_m, in camera space (mm)
        to_world.inverse().transform_point3(DVec3::new(0.0, -h, -dist_m)) * 1e3
    };
    // Blender's thin lens keeps its film pivot at F = f and focuses by the lens's power
    // f' = F·s/(F + s): find f' whose sensor line through the two conjugates crosses the axis
    // at F (bisection), then s = F·f'/(F − f').
    let sensor_line = |fl: f64| -> (f64, f64) {
        let conj = |p: DVec3| -> DVec3 { -p * (fl / (-p.z - fl)) }; // object (z < 0, mm) → image (z > 0)
        let (i1, i2) = (conj(ground_point(1.0)), conj(ground_point(20.0)));
        // sensor line through i1, i2 in the (y, z) plane: local +y maps to (cos t, sin t)
        let dir = (i2 - i1).normalize();
        let dir = if dir.y < 0.0 { -dir } else { dir };
        (dir.z.atan2(dir.y).to_degrees(), i1.z - i1.y * dir.z / dir.y)
    };
    let (mut lo, mut hi) = (0.5 * f, f);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if sensor_line(mid).1 < f {
            lo = mid
        } else {
            hi = mid
        }
    }
    let f_lens = 0.5 * (lo + hi);
    let (tilt, _) = sensor_line(f_lens);
    let focus_m = f * f_lens / (f - f_lens) * 1e-3;
    let (ratio, cam) = ratio_for(&rs, tilt, focus_m);
    let plane = cam.focus_plane().unwrap();
    let misalign = plane.normal.dot(ground_n).abs().min(1.0).acos().to_degrees();
    let offset = (plane.normal.dot(plane.point_m) + h * plane.normal.dot(ground_n).signum()).abs();
    eprintln!(
        "hinge rule: tilt {tilt:.3}°, focus {focus_m:.3} m, hinge {:.3} m, plane-of-focus/ground angle {misalign:.4}°, offset {offset:.2e} m",
        plane.hinge_distance_m.unwrap_or(f64::NAN)
    );
    assert!(misalign < 0.01 && offset < 1e-4, "the FocusPlane for the hinge-rule tilt should be the ground");
    let vals: Vec<f64> = ratio.iter().flatten().cloned().collect();
    let worst = vals.iter().cloned().fold(f64::MAX, f64::min);
    let mean = vals.iter().sum::<f64>() / vals.len() as f64;
    let (untilted, _) = ratio_for(&rs, 0.0, 1.2);
    let u: Vec<f64> = untilted.iter().flatten().cloned().collect();
    let u_sharp = u.iter().filter(|r| **r > 0.9).count();
    eprintln!(
        "hinge rule: sharpness ratio over {} ground rows: mean {mean:.3}, worst {worst:.3}; untilted at 1.2 m: {u_sharp} of {} rows above 0.9, worst {:.3}",
        vals.len(),
        u.len(),
        u.iter().cloned().fold(f64::MAX, f64::min)
    );
    // every ground row as sharp as the f/500 reference: 0.9 (the per-row ratio's noise is
    // ≈ 2%; a blur of 1 px at this stripe period would already bring it to ≈ 0.9)
    assert!(worst > 0.9, "with the plane of focus on the ground every row should be sharp: worst {worst}");
    assert!(u_sharp < u.len() / 2, "untilted, only a band should be sharp");
}

// ------------------------------------------------------------------------------------------
// Alpha.

/// Alpha is coverage: a wall filling the left half of the view through a real lens wide open
/// (about half the film samples are blocked inside the lens, more towards the corners) reads
/// alpha 1 on the wall and 0 on the sky, not the fraction of samples the lens let through.
#[test]
fn render_alpha_is_coverage_through_a_real_lens() {
    // wall x < 0 at 3 m, facing the camera; grey sky
    let wall = Mesh {
        positions: vec![
            Vec3::new(-50.0, -50.0, -3.0),
            Vec3::new(0.0, -50.0, -3.0),
            Vec3::new(0.0, 50.0, -3.0),
            Vec3::new(-50.0, 50.0, -3.0),
        ],
        normals: vec![Vec3::Z; 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::ZERO; 4],
        uv1: vec![],
        colors: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![0, 0],
    };
    let rs = scene_of(&[wall], vec![diffuse(Vec3::splat(0.5))], Environment::Constant(Vec3::splat(0.3)));
    let lens = library_lens("double-gauss-50mm").unwrap();
    let cam = Camera::Exact(ExactCamera::new(Sensor::default(), lens, Some(3.0)).unwrap());
    let (w, h) = (48u32, 32u32);
    let img = shoot_img(&rs, cam, &settings(w, h, 8, 1, BOX1));
    // columns well clear of the edge (the defocus there is < 1 px: the wall is in focus)
    let (mut lo_wall, mut hi_sky) = (1.0f32, 0.0f32);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let a = img.rgba[y * w as usize + x][3];
            if x < 22 {
                lo_wall = lo_wall.min(a);
            } else if x > 25 {
                hi_sky = hi_sky.max(a);
            }
        }
    }
    eprintln!("alpha through double-gauss-50mm: wall min {lo_wall}, sky max {hi_sky}");
    // exact: every sample that passes the lens hits the wall (or misses it)
    assert!(lo_wall > 1.0 - 1e-5, "alpha on the wall {lo_wall}");
    assert!(hi_sky < 1e-6, "alpha on the sky {hi_sky}");
}

// ------------------------------------------------------------------------------------------
// 6. Determinism.

fn demo_rig() -> (RenderScene, CameraRig) {
    let (scene, shot) = demo::demo_scene();
    let sc = scene.cameras[0].clone();
    let to_world = DAffine3::from_cols_array(&sc.to_world.to_cols_array().map(|v| v as f64));
    let lens = library_lens(shot.lens).unwrap().stopped_down(shot.f_number).unwrap().with_aperture(Aperture {
        shape: ApertureShape::Blades { count: shot.blades, curvature: 0.0 },
        rotation_rad: shot.blade_rotation_deg.to_radians(),
        anamorphic_ratio: 1.0,
    });
    let sensor = Sensor { tilt_x_deg: shot.tilt_x_deg, ..Sensor::default() };
    let camera = Camera::Exact(ExactCamera::new(sensor, lens, Some(shot.focus_distance_m)).unwrap());
    (RenderScene::new(scene).unwrap(), CameraRig { camera, to_world })
}

fn bits(img: &Image) -> Vec<u32> {
    let mut v: Vec<u32> = img.rgba.iter().flat_map(|p| p.iter().map(|c| c.to_bits())).collect();
    v.extend(img.depth.iter().map(|d| d.to_bits()));
    v.extend(img.normal.iter().flat_map(|p| p.iter().map(|c| c.to_bits())));
    v.extend(img.albedo.iter().flat_map(|p| p.iter().map(|c| c.to_bits())));
    v
}

/// The demo (textures, emitters, a tilted real lens with blades) renders bit-identically on 1
/// and 2 threads with the same seed, and differently with another seed.
#[test]
fn render_is_deterministic_across_thread_counts() {
    let (rs, rig) = demo_rig();
    let st = settings(60, 40, 6, 42, PixelFilter::default());
    let run = |threads: usize, s: &RenderSettings| -> Image {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render(&rs, &rig, s, &|_| true).unwrap().image)
    };
    let one = run(1, &st);
    let two = run(2, &st);
    let two_again = run(2, &st);
    assert!(one.rgba.iter().any(|p| p[0] > 0.0), "the demo should not be black");
    assert!(bits(&one) == bits(&two), "1 vs 2 threads differ");
    assert!(bits(&two) == bits(&two_again), "two runs on 2 threads differ");
    let other = run(2, &RenderSettings { seed: 43, ..st.clone() });
    let differing = one.rgba.iter().zip(&other.rgba).filter(|(a, b)| a != b).count();
    eprintln!("determinism: seed 42 vs 43 differ in {differing} of {} pixels", one.rgba.len());
    assert!(differing > one.rgba.len() / 2, "another seed should give another image: {differing} pixels differ");
}

/// An orthographic camera (Orthographic Scale 2 m, square frame) sees a flat emitter disc at its
/// true size wherever it stands along the view axis: the image's sum is the disc's area over
/// the window's, its centroid the disc centre's window position, at 2 m and at 20 m alike.
#[test]
fn render_orthographic_camera_keeps_sizes_at_any_distance() {
    let (w, le, r) = (64u32, 2.0f32, 0.5f32);
    let host = HostCamera {
        film_back: FilmBack { width_mm: 36.0, height_mm: 36.0, ..FilmBack::default() },
        ortho_scale_m: Some(2.0),
        ..HostCamera::default()
    };
    let spec = host.camera_spec(w, w).unwrap();
    let camera = spec.build(&ShotContext { width: w, height: w, ..ShotContext::default() }).unwrap().camera;
    let centre = Vec3::new(0.4, 0.2, 0.0);
    let expected_sum = polygon_area(r as f64, DISC_SIDES) / 4.0 * le as f64 * (w * w) as f64;
    let expected_centroid = (32.0 + 0.4 / 2.0 * 64.0, 32.0 - 0.2 / 2.0 * 64.0);
    for z in [-2.0f32, -20.0] {
        let rs = scene_of(&[disc(centre + Vec3::Z * z, r, 0)], vec![emitter(le)], Environment::Constant(Vec3::ZERO));
        let img = shoot_img(&rs, camera.clone(), &settings(w, w, 64, 1, BOX1));
        let red = red(&img);
        let sum: f64 = red.iter().sum();
        let (mut cx, mut cy) = (0.0, 0.0);
        for (i, v) in red.iter().enumerate() {
            cx += v * ((i % w as usize) as f64 + 0.5);
            cy += v * ((i / w as usize) as f64 + 0.5);
        }
        let (cx, cy) = (cx / sum, cy / sum);
        eprintln!(
            "orthographic, disc at {z} m: sum {sum:.3} (expected {expected_sum:.3}), centroid ({cx:.4}, {cy:.4})"
        );
        assert!((sum / expected_sum - 1.0).abs() < 2e-3, "{sum} vs {expected_sum}");
        assert!((cx - expected_centroid.0).abs() < 0.02 && (cy - expected_centroid.1).abs() < 0.02, "({cx}, {cy})");
    }
}

// ------------------------------------------------------------------------------------------
// 7. Cancellation and time limits.

fn furnace_for_interrupts() -> (RenderScene, CameraRig) {
    let rs = scene_of(
        &[icosphere(Vec3::new(0.0, 0.0, -4.0), 1.0, 3, 0)],
        vec![diffuse(Vec3::ONE)],
        Environment::Constant(Vec3::ONE),
    );
    let cam = PinholeCamera::new(Sensor::default(), 50.0).unwrap().with_natural_vignetting(false);
    (rs, CameraRig { camera: Camera::Pinhole(cam), to_world: DAffine3::IDENTITY })
}

fn assert_finite(img: &Image) {
    assert!(img.rgba.iter().all(|p| p.iter().all(|c| c.is_finite())), "non-finite pixels");
    assert!(img.normal.iter().all(|p| p.iter().all(|c| c.is_finite())));
    assert!(img.albedo.iter().all(|p| p.iter().all(|c| c.is_finite())));
    assert!(img.depth.iter().all(|d| !d.is_nan()));
}

/// A pool of its own, so that timing is not disturbed by renders of tests running alongside
/// (they share rayon's global pool).
fn own_pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap()
}

fn check_furnace_image(img: &Image) {
    // An unsampled pixel has no radiance and no coverage; a sampled one reads ≈ 1 (sky) or is
    // covered by the sphere (alpha 1). A single sample of the sphere may legitimately be 0.
    let unsampled = img.rgba.iter().filter(|p| p[1] == 0.0 && p[3] == 0.0).count();
    assert_eq!(unsampled, 0, "unsampled pixels");
    // the furnace's mean is 1: 1% ≫ the noise of the mean over 16k pixels even at 1 spp
    let mean = img.rgba.iter().map(|p| p[1] as f64).sum::<f64>() / img.rgba.len() as f64;
    assert!((mean - 1.0).abs() < 0.01, "furnace mean {mean}");
}

/// Returning false from the progress callback stops the render within a row, with
/// `complete = false` and a finite image.
#[test]
fn render_cancel_via_progress_returns_promptly() {
    let (rs, rig) = furnace_for_interrupts();
    let st = settings(160, 100, 1 << 20, 0, PixelFilter::default());
    let start = Instant::now();
    let calls = AtomicU32::new(0);
    let cancelled_at = std::sync::Mutex::new(None::<Instant>);
    // cancel once 0.3 s have passed and the first pass is complete (progress = rows done /
    // (spp · height), so past 1/spp every pixel has a sample)
    let progress = |f: f32| {
        calls.fetch_add(1, Ordering::Relaxed);
        let go_on = start.elapsed() < Duration::from_millis(300) || (f as f64) * (st.spp as f64) < 1.5;
        if !go_on {
            cancelled_at.lock().unwrap().get_or_insert_with(Instant::now);
        }
        go_on
    };
    let r = own_pool().install(|| render(&rs, &rig, &st, &progress)).unwrap();
    let t = start.elapsed().as_secs_f64();
    let after = cancelled_at.lock().unwrap().expect("cancelled").elapsed().as_secs_f64();
    eprintln!(
        "cancel: returned {after:.4} s after the cancel ({t:.3} s in all), spp_done {}, {} progress calls",
        r.spp_done,
        calls.load(Ordering::Relaxed)
    );
    assert!(!r.complete);
    assert!(r.spp_done >= 1 && r.spp_done < st.spp, "spp_done {}", r.spp_done);
    // "promptly": the cancel flag is checked per row; rows in flight (one per thread, ≤ 16 spp
    // of 160 px, ≈ 2 ms each) finish. 0.5 s leaves room for a loaded machine.
    assert!(after < 0.5, "cancel took {after} s");
    assert_finite(&r.image);
    check_furnace_image(&r.image);

    // cancelled at the very first progress call (inside the first pass): still finite, incomplete
    let start = Instant::now();
    let r = own_pool().install(|| render(&rs, &rig, &st, &|_| false)).unwrap();
    assert!(!r.complete && r.spp_done == 0);
    assert!(start.elapsed() < Duration::from_millis(500));
    assert_finite(&r.image);
}

/// A time limit stops after the pass that crosses it.
#[test]
fn render_time_limit_stops_early() {
    let (rs, rig) = furnace_for_interrupts();
    let st = RenderSettings {
        time_limit: Some(Duration::from_millis(250)),
        ..settings(160, 100, 1 << 20, 0, PixelFilter::default())
    };
    let pool = own_pool();
    let start = Instant::now();
    let r = pool.install(|| render(&rs, &rig, &st, &|_| true)).unwrap();
    let t = start.elapsed().as_secs_f64();
    eprintln!("time limit 0.25 s: returned after {t:.3} s, spp_done {}", r.spp_done);
    assert!(!r.complete && r.spp_done >= 1 && r.spp_done < st.spp);
    // It stops after the pass that crosses the limit: a pass is at most 16 spp of 16k pixels
    // (≈ 0.05 s on one idle core); 3 s allows for a loaded machine. The full 2²⁰ spp would
    // take hours.
    assert!(t < 3.0, "time limit overrun: {t} s");
    assert_finite(&r.image);
    check_furnace_image(&r.image);
}

/// Samples are keyed by absolute pixel, so a crop window renders exactly the full frame's
/// pixels there (the Blender border test relies on it): a thin lens with depth of field, a
/// Blackman–Harris filter and a lit sphere over a sky.
#[test]
fn crop_window_equals_the_full_frame() {
    let rs = scene_of(
        &[icosphere(Vec3::new(0.3, -0.2, -4.0), 1.0, 3, 0)],
        vec![diffuse(Vec3::splat(0.6))],
        Environment::Constant(Vec3::ONE),
    );
    let cam = thin(Sensor::default(), 50.0, 2.0, 3.0, Aperture::default(), true);
    let filter = PixelFilter::BlackmanHarris { width_px: 3.0 };
    let (w, h) = (48, 32);
    let full = shoot(&rs, cam.clone(), DAffine3::IDENTITY, &settings(w, h, 8, 5, filter)).image;
    let [x0, y0, x1, y1] = [10u32, 4, 37, 21];
    let crop_settings = RenderSettings { crop: Some([x0, y0, x1, y1]), ..settings(w, h, 8, 5, filter) };
    let crop = shoot(&rs, cam, DAffine3::IDENTITY, &crop_settings).image;
    assert_eq!((crop.width, crop.height), (x1 - x0, y1 - y0));
    for y in y0..y1 {
        for x in x0..x1 {
            let c = ((y - y0) * (x1 - x0) + (x - x0)) as usize;
            let f = (y * w + x) as usize;
            for k in 0..4 {
                let (a, b) = (crop.rgba[c][k], full.rgba[f][k]);
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "pixel ({x}, {y}) channel {k}: crop {a} vs full {b}");
            }
            let (a, b) = (crop.depth[c], full.depth[f]);
            assert!(a == b || (a - b).abs() <= 1e-6 * b.abs(), "depth at ({x}, {y}): crop {a} vs full {b}");
        }
    }
}

// ------------------------------------------------------------------------------------------
// 8. Adaptive sampling.

/// Cycles' convergence test on hand-made sums: equal halves pass, a difference above the
/// threshold (relative to √intensity) fails, and fewer than two samples never pass.
#[test]
fn adaptive_test_is_cycles_error_estimate() {
    use petzval_renderer::render::{adaptive_class_a, adaptive_class_a_count, adaptive_converged};
    // 8 samples of mean (1, 1, 1); class A (4 of them) also has mean 1 → error 0
    assert!(adaptive_converged(Vec3::splat(8.0), Vec3::splat(4.0), 8, 0.01));
    // class A mean 1.1 in red, intensity 3 ≥ 1: error = 0.1 / (1e-4 + 3) ≈ 0.0333
    let odd = Vec3::new(4.4, 4.0, 4.0);
    assert!(!adaptive_converged(Vec3::splat(8.0), odd, 8, 0.03));
    assert!(adaptive_converged(Vec3::splat(8.0), odd, 8, 0.04));
    // a dim pixel (mean 0.1, intensity 0.3 < 1) is normalised by √0.3: odd half 0.11 in red
    // gives error 0.01 / (1e-4 + 0.5477) ≈ 0.01826
    let odd = Vec3::new(0.44, 0.4, 0.4);
    assert!(!adaptive_converged(Vec3::splat(0.8), odd, 8, 0.018));
    assert!(adaptive_converged(Vec3::splat(0.8), odd, 8, 0.0185));
    assert!(!adaptive_converged(Vec3::ONE, Vec3::ZERO, 1, 1.0), "one sample says nothing about noise");
    // 15 noiseless samples of 0.7 hold 8 of class A, so the error is 0 (the estimate
    // 2·Σ_A / n would say 1/15 and keep the pixel sampling)
    assert_eq!(adaptive_class_a_count(15), 8);
    assert!(adaptive_converged(Vec3::splat(15.0 * 0.7), Vec3::splat(8.0 * 0.7), 15, 0.01));
    // Cycles' class split (popcount(i & 0xaaaaaaaa) & 1), and the count against brute force
    let a: Vec<u32> = (0..16).filter(|&i| adaptive_class_a(i)).collect();
    assert_eq!(a, [2, 3, 6, 7, 8, 9, 12, 13]);
    for n in 0..5000u32 {
        assert_eq!(adaptive_class_a_count(n), (0..n).filter(|&i| adaptive_class_a(i)).count() as u32, "n = {n}");
    }
    // automatic minimum, Cycles' table: 0.1 → 32, 0.01 → 64, 0.001 → 128
    for (t, min) in [(0.1, 32), (0.01, 64), (0.001, 128)] {
        let s = RenderSettings { adaptive_threshold: t, ..RenderSettings::default() };
        assert_eq!(s.adaptive_min_spp(), Some(min), "threshold {t}");
    }
    assert_eq!(RenderSettings::default().adaptive_min_spp(), None, "off by default");
}

/// A frame of constant sky has no noise: with adaptive sampling every pixel stops at its first
/// test (16 samples for a minimum of 8, as Cycles schedules it), the render reports itself
/// complete, and the image is the sky's value.
#[test]
fn adaptive_sampling_stops_noiseless_pixels_at_the_first_test() {
    let rs = scene_of(&[], vec![diffuse(Vec3::ONE)], Environment::Constant(Vec3::splat(0.7)));
    let cam = PinholeCamera::new(Sensor::default(), 50.0).unwrap().with_natural_vignetting(false);
    let rig = CameraRig { camera: Camera::Pinhole(cam), to_world: DAffine3::IDENTITY };
    let st = RenderSettings { adaptive_threshold: 0.01, adaptive_min_samples: 8, ..settings(24, 16, 1024, 3, BOX1) };
    let r = render(&rs, &rig, &st, &|_| true).unwrap();
    assert!(r.complete, "converged everywhere counts as complete");
    assert_eq!(r.camera_rays, 24 * 16 * 16, "every pixel should stop at the first test, 16 samples");
    use petzval_renderer::render::adaptive_next_check;
    // Cycles' schedule: (min + 1) | 15 as a 0-based index, then every 16 samples
    for (done, min, next) in
        [(0, 8, 16), (15, 8, 16), (16, 8, 32), (0, 14, 16), (0, 15, 32), (0, 64, 80), (80, 64, 96), (100, 64, 112)]
    {
        assert_eq!(adaptive_next_check(done, min), next, "done {done}, min {min}");
    }
    assert!(r.image.rgba.iter().all(|p| (p[0] - 0.7).abs() < 1e-6), "sky value");
}

/// A ground lit by a small lamp (noisy) under a sky map (noiseless; a map that varies, so
/// next-event estimation shares its samples between the sky and the lamp): adaptive sampling
/// spends its samples on the ground, stays deterministic across thread counts, and reaches a
/// lower error against a converged reference than fixed sampling with the same number of camera
/// rays. The error is the relative RMSE over the frame, pooled over 6 seeds: one seed's is
/// carried by a few rare bright samples near the lamp and varies by ±40 % from seed to seed.
/// The threshold is Cycles' default, 0.01 (automatic minimum 64, first test at 80). Measured
/// 2026-12-04 over thresholds 0.01 to 0.002: adaptive sampling's error was 0.61–0.79× fixed
/// sampling's. Before the tests were aligned to multiples of 16 samples, as Cycles aligns them,
/// thresholds whose automatic minimum was odd (0.005–0.007) lost to fixed sampling (up to 1.3×
/// its error) in every seed.
#[test]
fn adaptive_sampling_beats_fixed_sampling_at_equal_camera_rays() {
    let ground = {
        Mesh {
            positions: vec![
                Vec3::new(-20.0, -1.0, 1.0),
                Vec3::new(20.0, -1.0, 1.0),
                Vec3::new(20.0, -1.0, -40.0),
                Vec3::new(-20.0, -1.0, -40.0),
            ],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            material_ids: vec![0, 0],
            normals: vec![Vec3::Y; 4],
            tangents: vec![Vec4::ZERO; 4],
            uv0: vec![Vec2::ZERO; 4],
            ..Mesh::default()
        }
    };
    // a lamp above the frame (26° up; the frame reaches 13.5°), facing down
    let mut lamp = disc(Vec3::ZERO, 0.15, 1);
    for p in &mut lamp.positions {
        *p = Vec3::new(p.x, 2.0, -4.0 + p.y);
    }
    let rs = scene_of(
        &[ground, lamp],
        vec![diffuse(Vec3::splat(0.5)), emitter(400.0)],
        // a sky map (0.2 above the horizon, 0.1 below), so that it is a light (a uniform
        // environment is found by BSDF samples only, and the ground would be nearly noiseless too)
        Environment::Map(
            petzval_renderer::scene::environment::EnvironmentMap::new(
                "sky",
                4,
                2,
                [[Vec3::splat(0.2); 4], [Vec3::splat(0.1); 4]].concat(),
                1.0,
                0.0,
            )
            .unwrap(),
        ),
    );
    let cam = PinholeCamera::new(Sensor::default(), 50.0).unwrap().with_natural_vignetting(false);
    let rig = CameraRig { camera: Camera::Pinhole(cam), to_world: DAffine3::IDENTITY };
    let (w, h) = (32u32, 24u32);
    let base = RenderSettings { max_depth: 3, ..settings(w, h, 512, 1, BOX1) };
    let reference = render(&rs, &rig, &RenderSettings { spp: 4096, seed: 99, ..base.clone() }, &|_| true).unwrap();
    let adaptive_settings = RenderSettings { adaptive_threshold: 0.01, ..base.clone() };
    let run = |threads: usize, s: &RenderSettings| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render(&rs, &rig, s, &|_| true).unwrap())
    };
    let first = run(2, &adaptive_settings);
    assert!(bits(&first.image) == bits(&run(1, &adaptive_settings).image), "1 vs 2 threads differ");
    let squared_error = |img: &Image| -> (f64, f64) {
        let (mut se, mut s2) = (0.0, 0.0);
        for (a, b) in img.rgba.iter().zip(&reference.image.rgba) {
            for k in 0..3 {
                se += ((a[k] - b[k]) as f64).powi(2);
                s2 += (b[k] as f64).powi(2);
            }
        }
        (se, s2)
    };
    let pixels = (w * h) as f64;
    let (mut se_adaptive, mut se_fixed, mut s2, mut rays) = (0.0, 0.0, 0.0, 0u64);
    for seed in 1..=6 {
        let adaptive = run(2, &RenderSettings { seed, ..adaptive_settings.clone() });
        let spp = (adaptive.camera_rays as f64 / pixels).round() as u32;
        let fixed = render(&rs, &rig, &RenderSettings { spp, seed, ..base.clone() }, &|_| true).unwrap();
        let (a, r2) = squared_error(&adaptive.image);
        se_adaptive += a;
        se_fixed += squared_error(&fixed.image).0;
        s2 += r2;
        rays += adaptive.camera_rays;
    }
    let mean_spp = rays as f64 / (6.0 * pixels);
    eprintln!("adaptive: {mean_spp:.1} spp on average (first test at 80, max 512)");
    // the sky (upper half) stops at the first test, the ground needs more
    assert!(mean_spp > 80.0 && mean_spp < 0.75 * 512.0, "mean spp {mean_spp}");
    let (e_adaptive, e_fixed) = ((se_adaptive / s2).sqrt(), (se_fixed / s2).sqrt());
    eprintln!("rel. RMSE over 6 seeds at {mean_spp:.1} spp: adaptive {e_adaptive:.4}, fixed {e_fixed:.4}");
    assert!(e_adaptive < 0.9 * e_fixed, "adaptive {e_adaptive:.4} should beat fixed {e_fixed:.4}");
}

/// A pass observer (progressive display) sees every pass, with the samples done so far, and the
/// last image it sees is the render's; without one (None: no image is made between passes) the
/// render is the same, bit for bit.
#[test]
fn pass_observer_sees_every_pass_and_changes_nothing() {
    let (rs, rig) = furnace_for_interrupts();
    let s = settings(16, 12, 20, 3, BOX1);
    let seen = std::sync::Mutex::new(Vec::new());
    let watched = petzval_renderer::render::render_observed(
        &rs,
        &rig,
        &s,
        &|_| true,
        Some(&|img: &Image, done: u32| seen.lock().unwrap().push((done, img.rgba.clone()))),
    )
    .unwrap();
    let unwatched = petzval_renderer::render::render_observed(&rs, &rig, &s, &|_| true, None).unwrap();
    let seen = seen.into_inner().unwrap();
    // passes of 1, 2, 4, 8 and the remaining 5 samples
    assert_eq!(seen.iter().map(|p| p.0).collect::<Vec<_>>(), [1, 3, 7, 15, 20]);
    assert_eq!(seen.last().unwrap().1, watched.image.rgba);
    assert_eq!(watched.image.rgba, unwatched.image.rgba);
    assert_eq!(watched.image.depth, unwatched.image.depth);
}

/// Bad adaptive settings are refused naming the field, and the preview methods refuse
/// adaptive sampling instead of ignoring it.
#[test]
fn adaptive_settings_are_checked() {
    for t in [f32::NAN, -0.1, 2.0] {
        let s = RenderSettings { adaptive_threshold: t, ..settings(8, 8, 4, 0, BOX1) };
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("adaptive_threshold"), "{e}");
    }
    let (rs, rig) = furnace_for_interrupts();
    let s = RenderSettings { adaptive_threshold: 0.01, ..settings(8, 8, 4, 0, BOX1) };
    let e = petzval_renderer::dof::render_method(
        petzval_renderer::dof::Method::Multiview,
        &rs,
        &rig,
        &s,
        &petzval_renderer::dof::PreviewSettings::default(),
        &|_| true,
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("adaptive_threshold"), "{e}");
}

/// Autofocus sees what the render sees: with clipping planes it focuses past a surface nearer
/// than the clip start and ignores one beyond the clip end.
#[test]
fn autofocus_honours_the_clipping_planes() {
    // discs facing the camera at 1 m and 3 m down −z from the origin
    let scene = scene_of(
        &[disc(Vec3::new(0.0, 0.0, -1.0), 0.2, 0), disc(Vec3::new(0.0, 0.0, -3.0), 1.0, 0)],
        vec![diffuse(Vec3::splat(0.5))],
        Environment::Black,
    );
    let at = DAffine3::IDENTITY;
    let f = |clip| petzval_renderer::shot::autofocus_clipped_m(&scene, &at, clip);
    assert!((petzval_renderer::shot::autofocus_m(&scene, &at).unwrap() - 1.0).abs() < 1e-5);
    assert!((f((0.0, f64::INFINITY)).unwrap() - 1.0).abs() < 1e-5);
    assert!((f((1.5, 100.0)).unwrap() - 3.0).abs() < 1e-5, "{:?}", f((1.5, 100.0)));
    assert_eq!(f((1.5, 2.5)), None);
    assert_eq!(f((4.0, 100.0)), None);
}
