//! Image-based ray tracing on depth-peeled layers (`dof::ibrt`) against Monte Carlo through the
//! same thin lens, on emission-only scenes (max depth 0 after the camera ray: the layers' radiance
//! is exact, so every difference is the method's).

use glam::{DAffine3, DVec2, DVec3, Vec2, Vec3, Vec4};
use petzval_renderer::dof::{self, LayerSettings, LayerTracer, Method, PreviewSettings};
use petzval_renderer::film::metrics::relative_rmse;
use petzval_renderer::film::{Image, PixelFilter};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render, CameraRig, RenderSettings};
use petzval_renderer::scene::{Environment, Material, Mesh, Scene};
use petzval_renderer::{Aperture, Camera, Sensor, ThinCamera};

/// A black, double-sided emitter of radiance `le`.
fn emitter(le: f32) -> Material {
    Material {
        emissive: Vec3::splat(le),
        double_sided: true,
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        roughness: 1.0,
        specular: 0.0,
        ..Material::default()
    }
}

/// An axis-aligned rectangle [x0, x1] × [y0, y1] at depth z (facing +z).
fn rect(x0: f32, x1: f32, y0: f32, y1: f32, z: f32, material: u32) -> Mesh {
    Mesh {
        positions: vec![Vec3::new(x0, y0, z), Vec3::new(x1, y0, z), Vec3::new(x1, y1, z), Vec3::new(x0, y1, z)],
        normals: vec![Vec3::Z; 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::ZERO; 4],
        uv1: vec![],
        colors: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
    }
}

/// A wall of vertical stripes (radiance 1 and 0.2, 0.1 m wide) at `z`.
fn stripes(z: f32) -> Vec<Mesh> {
    (0..40).map(|i| rect(-2.0 + 0.1 * i as f32, -1.9 + 0.1 * i as f32, -2.0, 2.0, z, (i % 2) as u32)).collect()
}

fn scene_of(meshes: &[Mesh], materials: Vec<Material>) -> RenderScene {
    let mut mesh = Mesh::default();
    for m in meshes {
        mesh.append(m, 0);
    }
    RenderScene::new(Scene { materials, environment: Environment::Constant(Vec3::splat(0.05)), ..Scene::world(mesh) })
        .unwrap()
}

/// 50 mm f/2 thin lens focused at `focus_m`, no natural vignetting, 36 × 27 mm sensor.
fn thin_rig(focus_m: f64, tilt_x_deg: f64) -> CameraRig {
    let sensor = Sensor { width_mm: 36.0, height_mm: 27.0, tilt_x_deg, ..Sensor::default() };
    let camera = ThinCamera::new(sensor, 50.0, 2.0, Some(focus_m), Aperture::default()).unwrap();
    CameraRig { camera: Camera::Thin(camera.with_natural_vignetting(false)), to_world: DAffine3::IDENTITY }
}

fn settings(spp: u32, seed: u32) -> RenderSettings {
    RenderSettings {
        width: 64,
        height: 48,
        spp,
        seed,
        max_depth: 1,
        filter: PixelFilter::default(),
        ..Default::default()
    }
}

fn ibrt(rs: &RenderScene, rig: &CameraRig, st: &RenderSettings, layers: usize) -> Image {
    let preview = PreviewSettings { layers: LayerSettings { count: layers, spp: 4, ..LayerSettings::default() } };
    dof::render_method(Method::Ibrt, rs, rig, st, &preview, &|_| true, None).unwrap().image
}

/// A striped wall slightly out of focus (0.8 px blur; one surface, nothing hidden): IBRT's error
/// against a converged MC render is at most 1.5 × MC's noise at the same lens samples (the rest is
/// the resampling of in-focus stripes through the layer texels, half a pixel across).
#[test]
fn ibrt_matches_monte_carlo_on_a_wall() {
    let rs = scene_of(&stripes(-3.0), vec![emitter(1.0), emitter(0.2)]);
    let rig = thin_rig(1.5, 0.0);
    let reference = render(&rs, &rig, &settings(1024, 7), &|_| true).unwrap().image;
    let mc = render(&rs, &rig, &settings(64, 1), &|_| true).unwrap().image;
    let image = ibrt(&rs, &rig, &settings(64, 1), 2);
    let (e_mc, e_ibrt) = (relative_rmse(&reference, &mc).unwrap(), relative_rmse(&reference, &image).unwrap());
    eprintln!("defocused wall, relative RMSE against MC 1024 spp: MC 64 spp {e_mc:.4}, IBRT 64 spp {e_ibrt:.4}");
    assert!(e_ibrt < 1.5 * e_mc + 0.005, "IBRT {e_ibrt} vs MC noise {e_mc}");
}

/// Partial occlusion: a near black bar (0.04 m wide at 0.3 m), far out of focus (a ~7 px blur),
/// in front of the striped wall in focus at 3 m. Through the bar's blurred edges the lens sees
/// the wall behind it, which only the hidden layers hold. Over the columns of the blurred bar,
/// three layers are within twice MC's noise of the reference; one layer is not.
#[test]
fn ibrt_hidden_layers_fill_partial_occlusion() {
    let mut meshes = stripes(-3.0);
    meshes.push(rect(-0.02, 0.02, -1.0, 1.0, -0.3, 2));
    let rs = scene_of(&meshes, vec![emitter(1.0), emitter(0.2), emitter(0.0)]);
    let rig = thin_rig(3.0, 0.0);
    let reference = render(&rs, &rig, &settings(1024, 7), &|_| true).unwrap().image;
    let mc = render(&rs, &rig, &settings(64, 1), &|_| true).unwrap().image;
    let one = ibrt(&rs, &rig, &settings(64, 1), 1);
    let three = ibrt(&rs, &rig, &settings(64, 1), 3);
    // Relative RMSE over columns 18..46 (the bar, 12 px wide at the centre, and its blur).
    let band = |img: &Image| {
        let (mut se, mut sum) = (0.0f64, 0.0f64);
        for y in 0..48 {
            for x in 18..46 {
                let (a, b) = (img.rgba[y * 64 + x][0] as f64, reference.rgba[y * 64 + x][0] as f64);
                se += (a - b) * (a - b);
                sum += b;
            }
        }
        let n = (48 * 28) as f64;
        (se / n).sqrt() / (sum / n)
    };
    let (e_mc, e1, e3) = (band(&mc), band(&one), band(&three));
    eprintln!(
        "occluder's blurred band, relative RMSE against MC 1024 spp: MC 64 {e_mc:.4}, IBRT K=1 {e1:.4}, K=3 {e3:.4}"
    );
    assert!(e3 < 2.0 * e_mc, "K=3 {e3} vs MC noise {e_mc}");
    assert!(e1 > 3.0 * e_mc, "one layer cannot see behind the bar, yet K=1 {e1} is within MC noise {e_mc}");
}

/// Geometric invariant: rays from points on the lens towards a single tilted plane meet the
/// layer of that plane at the plane's depth (within the elements' thickness), and rays that pass
/// beside it miss.
#[test]
fn ibrt_rays_meet_a_plane_layer_at_its_depth() {
    // A plane through (0, 0, −2) tilted 30° about x (facing the camera), 1.2 m square.
    let (c, s) = (30f32.to_radians().cos(), 30f32.to_radians().sin());
    let p = |x: f32, y: f32| Vec3::new(x, y * c, -2.0 - y * s);
    let plane = Mesh {
        positions: vec![p(-0.6, -0.6), p(0.6, -0.6), p(0.6, 0.6), p(-0.6, 0.6)],
        normals: vec![Vec3::new(0.0, s, c); 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::ZERO; 4],
        uv1: vec![],
        colors: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![0; 2],
    };
    let rs = scene_of(&[plane], vec![emitter(1.0)]);
    let rig = thin_rig(2.0, 0.0);
    let st = settings(1, 0);
    let preview = PreviewSettings { layers: LayerSettings { count: 1, spp: 1, ..LayerSettings::default() } };
    let tracer = LayerTracer::new(dof::make_layers(&rs, &rig, &st, &preview, &|_| true).unwrap().unwrap());
    let normal = DVec3::new(0.0, s as f64, c as f64);
    let mut state = 12345u64;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut hits, mut worst) = (0, 0.0f64);
    for _ in 0..2000 {
        // A lens point within 12.5 mm and a target on (or beside) the plane.
        let origin = DVec3::new((rnd() - 0.5) * 0.025, (rnd() - 0.5) * 0.025, 0.0);
        let (u, v) = ((rnd() - 0.5) * 1.6, (rnd() - 0.5) * 1.6);
        let target = DVec3::new(u, v * c as f64, -2.0 - v * s as f64);
        let dir = (target - origin).normalize();
        let inside = u.abs() < 0.55 && v.abs() < 0.55;
        let outside = u.abs() > 0.65 || v.abs() > 0.65;
        let found = tracer.intersect(origin, dir);
        if inside {
            let (_, z) = found.expect("a ray towards the plane's interior hits its layer");
            // The ray's depth where it crosses the plane.
            let t = (DVec3::new(0.0, 0.0, -2.0) - origin).dot(normal) / dir.dot(normal);
            let z_true = -(origin.z + t * dir.z);
            worst = worst.max((z - z_true).abs() / z_true);
            hits += 1;
        } else if outside {
            assert!(found.is_none(), "a ray beside the plane hit its layer at {found:?}");
        }
    }
    eprintln!("plane layer: {hits} rays hit, worst relative depth error {worst:.2e}");
    assert!(hits > 500);
    // The texel's own depth is returned: within half a texel of slope plus the thickness.
    assert!(worst < 5e-3, "worst relative depth error {worst}");
    let _ = DVec2::ZERO;
}

/// Hidden texels that no camera ray can reach are not shaded, and none is ever hit: across the
/// frame and the whole aperture, every IBRT hit of the occluder scene lands on a shaded texel,
/// while most of the hidden layers' texels were skipped.
#[test]
fn ibrt_only_unreachable_hidden_texels_go_unshaded() {
    let mut meshes = stripes(-3.0);
    meshes.push(rect(-0.02, 0.02, -1.0, 1.0, -0.3, 2));
    meshes.push(rect(-2.0, 2.0, -2.0, 2.0, -3.5, 0));
    let rs = scene_of(&meshes, vec![emitter(1.0), emitter(0.2), emitter(0.0)]);
    let rig = thin_rig(3.0, 0.0);
    let st = settings(1, 0);
    let preview = PreviewSettings { layers: LayerSettings { count: 3, spp: 1, ..LayerSettings::default() } };
    let layers = dof::make_layers(&rs, &rig, &st, &preview, &|_| true).unwrap().unwrap();
    let fraction = layers.hidden_shaded_fraction();
    let tracer = LayerTracer::new(layers);
    let (mut hits, mut hidden_hits) = (0usize, 0usize);
    for j in 0..48 {
        for i in 0..64 {
            for l in 0..16 {
                let film = DVec2::new((i as f64 + 0.5) / 64.0, (j as f64 + 0.5) / 48.0);
                let lens = DVec2::new((l % 4) as f64 / 4.0 + 0.125, (l / 4) as f64 / 4.0 + 0.125);
                let Some(ray) = rig.camera.generate_ray(film, lens, 550.0) else { continue };
                if let Some((index, _)) = tracer.intersect(ray.origin, ray.direction) {
                    hits += 1;
                    hidden_hits += (index >= tracer.layers().frame.texels()) as usize;
                    assert!(tracer.layers().shaded[index], "ray {ray:?} hit unshaded texel {index}");
                }
            }
        }
    }
    eprintln!("hidden texels shaded: {:.1} %; {hits} hits, {hidden_hits} on hidden layers", 100.0 * fraction);
    assert!(hidden_hits > 100, "the bar's blur should reach the hidden layers: {hidden_hits}");
    assert!(fraction < 0.5, "most hidden texels (the wall behind the back wall) are unreachable: {fraction}");
}

/// Clipping planes: with the near clip beyond the bar (1 m), the bar vanishes from IBRT as it
/// does from Monte Carlo (the layers still hold it; the rays skip elements before the clip).
#[test]
fn ibrt_honours_the_clipping_planes() {
    let mut meshes = stripes(-3.0);
    meshes.push(rect(-0.02, 0.02, -1.0, 1.0, -0.3, 2));
    let rs = scene_of(&meshes, vec![emitter(1.0), emitter(0.2), emitter(0.0)]);
    let rig = thin_rig(3.0, 0.0);
    let clipped = |spp: u32, seed: u32| RenderSettings { clip_start_m: 1.0, ..settings(spp, seed) };
    let reference = render(&rs, &rig, &clipped(256, 7), &|_| true).unwrap().image;
    let with_clip = ibrt(&rs, &rig, &clipped(64, 1), 3);
    let without = ibrt(&rs, &rig, &settings(64, 1), 3);
    let (e_clip, e_none) =
        (relative_rmse(&reference, &with_clip).unwrap(), relative_rmse(&reference, &without).unwrap());
    eprintln!("near clip 1 m: IBRT with the clip {e_clip:.4}, without {e_none:.4} against clipped MC");
    assert!(e_clip < 0.05, "IBRT with the clip {e_clip}");
    assert!(e_none > 3.0 * e_clip, "the bar should show without the clip: {e_none} vs {e_clip}");
}
