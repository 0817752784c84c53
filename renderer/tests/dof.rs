//! Depth-of-field preview methods against Monte Carlo.

use glam::{DAffine3, DVec2, DVec3};
use petzval_renderer::dof::{self, LayerFrame, LayerSettings, Layers};
use petzval_renderer::integrator::RenderScene;
use petzval_renderer::render::{render, CameraRig, RenderSettings};
use petzval_renderer::scene::demo;
use petzval_renderer::{Camera, PinholeCamera, Sensor};

fn demo_pinhole() -> (RenderScene, CameraRig) {
    let (scene, _shot) = demo::demo_scene();
    let sc = scene.cameras[0].clone();
    let to_world = DAffine3::from_cols_array(&sc.to_world.to_cols_array().map(|v| v as f64));
    let camera = Camera::Pinhole(PinholeCamera::new(Sensor::default(), 50.0).unwrap());
    (RenderScene::new(scene).unwrap(), CameraRig { camera, to_world })
}

#[test]
fn debug_layers_pinhole() {
    let (rs, rig) = demo_pinhole();
    let st = RenderSettings { width: 60, height: 40, spp: 64, ..RenderSettings::default() };
    let mc = render(&rs, &rig, &st, &|_| true).unwrap().image;
    let frame = LayerFrame::covering(&rig.camera, 60, 40, 0.0).unwrap();
    eprintln!("{frame:?}");
    let layers =
        Layers::trace(&rs, rig.to_world, frame, &LayerSettings { spp: 64, ..LayerSettings::default() }).unwrap();
    for (x, y) in [(5usize, 30usize), (10, 35), (30, 20), (55, 30), (50, 15)] {
        let i = y * 60 + x;
        let ray = rig
            .camera
            .generate_ray(DVec2::new((x as f64 + 0.5) / 60.0, (y as f64 + 0.5) / 40.0), DVec2::splat(0.5), 550.0)
            .unwrap();
        let (xy, _) = frame.project(ray.direction * 10.0).unwrap();
        let li = layers.index(0, x, y);
        eprintln!(
            "px ({x},{y}) mc {:?} depth {} | layer texel {xy:?} depth {:?} rad {:?} | l1 {:?}",
            mc.rgba[i],
            mc.depth[i],
            layers.depth_m[li],
            layers.radiance[li],
            layers.depth_m[layers.index(1, x, y)]
        );
    }
    let _ = (dof::Method::Mc, DVec3::ZERO);
    let tracer = petzval_renderer::PathTracer::default();
    let (x, y) = (10usize, 35usize);
    let dir = frame.direction(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
    let d = rig.to_world.transform_vector3(dir).normalize().as_vec3();
    let o = rig.to_world.transform_point3(DVec3::ZERO).as_vec3();
    let t = rs.intersect(o, d, f32::INFINITY).unwrap().t;
    for clip in [(0.0f32, f32::INFINITY), (t * (1.0 - 1e-4), f32::INFINITY), (t * 0.99, f32::INFINITY)] {
        let mut sum = glam::Vec3::ZERO;
        for s in 0..256 {
            let mut sm = petzval_renderer::sampler::PixelSampler::new(x as u32, y as u32, s, 7);
            sum += tracer.trace_clipped(&rs, o, d, clip, &mut sm).radiance;
        }
        eprintln!("clip {clip:?} t {t}: {:?}", sum / 256.0);
    }
}

// ==========================================================================================
// PSF spreading (`--method spread`): analytic cases and agreement with Monte Carlo. This
// section is self-contained (its own helpers in `spread_method`).

mod spread_method {
    use glam::{DAffine3, DVec2, DVec3, Vec2, Vec3, Vec4};
    use petzval_renderer::dof::spread::{self, Composite, SpreadSettings};
    use petzval_renderer::dof::{self, LayerFrame, LayerSettings, Layers, PreviewSettings};
    use petzval_renderer::film::{Image, PixelFilter};
    use petzval_renderer::integrator::RenderScene;
    use petzval_renderer::render::{render, CameraRig, RenderSettings};
    use petzval_renderer::scene::{Environment, Material, Mesh, Scene};
    use petzval_renderer::{Aperture, ApertureShape, Camera, PinholeCamera, Sensor, ThinCamera};
    use std::f64::consts::PI;

    fn emitter(le: f32) -> Material {
        Material {
            name: "emitter".into(),
            base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
            metallic: 0.0,
            roughness: 1.0,
            specular: 0.0,
            emissive: Vec3::splat(le),
            double_sided: true,
            ..Material::default()
        }
    }

    fn finish(mut m: Mesh) -> Mesh {
        let nv = m.positions.len();
        m.normals = vec![Vec3::Z; nv];
        m.tangents = vec![Vec4::ZERO; nv];
        m.uv0 = vec![Vec2::ZERO; nv];
        m
    }

    /// A flat regular 64-gon of circumradius `radius` at `c`, facing +z.
    fn disc(c: Vec3, radius: f32, material: u32) -> Mesh {
        let n = 64u32;
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
        finish(m)
    }

    /// An axis-aligned rectangle [x0, x1] × [y0, y1] at depth z, facing +z.
    fn rect(x0: f32, x1: f32, y0: f32, y1: f32, z: f32, material: u32) -> Mesh {
        let m = Mesh {
            positions: vec![Vec3::new(x0, y0, z), Vec3::new(x1, y0, z), Vec3::new(x1, y1, z), Vec3::new(x0, y1, z)],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            material_ids: vec![material; 2],
            ..Mesh::default()
        };
        finish(m)
    }

    fn scene_of(meshes: &[Mesh], materials: Vec<Material>) -> RenderScene {
        let mut mesh = Mesh::default();
        for m in meshes {
            mesh.append(m, 0);
        }
        RenderScene::new(Scene { materials, environment: Environment::Black, ..Scene::world(mesh) }).unwrap()
    }

    fn settings(w: u32, h: u32, spp: u32) -> RenderSettings {
        RenderSettings { width: w, height: h, spp, seed: 1, max_depth: 2, ..RenderSettings::default() }
    }

    fn thin(sensor: Sensor, n: f64, focus_m: f64, aperture: Aperture, vignetting: bool) -> Camera {
        Camera::Thin(
            ThinCamera::new(sensor, 50.0, n, Some(focus_m), aperture).unwrap().with_natural_vignetting(vignetting),
        )
    }

    /// Spreads `scene`'s layers (K layers at `layer_spp`) through `camera`.
    fn spread_img(
        scene: &RenderScene,
        camera: Camera,
        st: &RenderSettings,
        layer_spp: u32,
        s: &SpreadSettings,
    ) -> Image {
        let rig = CameraRig { camera, to_world: DAffine3::IDENTITY };
        let preview = PreviewSettings { layers: LayerSettings { spp: layer_spp, ..LayerSettings::default() } };
        let layers = dof::make_layers(scene, &rig, st, &preview).unwrap();
        let r = spread::render_spread(&layers, Some(scene), &rig.camera, st, s, &|_| true).unwrap();
        assert!(r.complete);
        r.image
    }

    fn mc_img(scene: &RenderScene, camera: Camera, st: &RenderSettings) -> Image {
        render(scene, &CameraRig { camera, to_world: DAffine3::IDENTITY }, st, &|_| true).unwrap().image
    }

    /// Flux, centroid (pixels, y down) and mean squared radius about it of the red channel.
    fn moments(img: &Image) -> (f64, DVec2, f64) {
        let w = img.width as usize;
        let (mut s0, mut s1) = (0.0, DVec2::ZERO);
        for (i, p) in img.rgba.iter().enumerate() {
            let v = p[0] as f64;
            s0 += v;
            s1 += DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5) * v;
        }
        let c = s1 / s0;
        let mut r2 = 0.0;
        for (i, p) in img.rgba.iter().enumerate() {
            let d = DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5) - c;
            r2 += d.length_squared() * p[0] as f64;
        }
        (s0, c, r2 / s0)
    }

    /// Mean of the red channel and the RMS of `a − b` relative to `b`'s mean.
    fn compare(a: &Image, b: &Image) -> (f64, f64, f64) {
        let n = a.rgba.len() as f64;
        let ma = a.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / n;
        let mb = b.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / n;
        let rms =
            (a.rgba.iter().zip(&b.rgba).map(|(p, q)| (p[0] as f64 - q[0] as f64).powi(2)).sum::<f64>() / n).sqrt();
        (ma, mb, rms / mb)
    }

    /// (a) A small emitter out of focus spreads into a disc of the thin-lens circle of
    /// confusion c = A·F·|1/d − 1/s| (Blender's thin lens: film at F, aperture A = F/N) with
    /// the in-focus image's energy, which is the emitter's projected area (radiance 1, no
    /// vignetting).
    #[test]
    fn spread_thin_lens_circle_of_confusion_and_energy() {
        let (f, n, d_mm) = (50.0f64, 2.0f64, 2000.0f64);
        let px = 64u32;
        for s_mm in [1000.0f64, 5000.0] {
            let c_mm = (f / n) * f * (1.0 / d_mm - 1.0 / s_mm).abs();
            let pitch = c_mm / 30.0; // a 30-pixel disc
            let sensor = Sensor { width_mm: px as f64 * pitch, height_mm: px as f64 * pitch, ..Sensor::default() };
            let r_src_px = 1.5;
            let rho_m = r_src_px * pitch * s_mm / f * 1e-3;
            let scene =
                scene_of(&[disc(Vec3::new(0.0, 0.0, -(s_mm * 1e-3) as f32), rho_m as f32, 0)], vec![emitter(1.0)]);
            let st = settings(px, px, 1);
            let sp = SpreadSettings::default();
            let focused = spread_img(&scene, thin(sensor, n, s_mm * 1e-3, Aperture::default(), false), &st, 64, &sp);
            let blurred = spread_img(&scene, thin(sensor, n, d_mm * 1e-3, Aperture::default(), false), &st, 64, &sp);
            let (e0, c0, r2_0) = moments(&focused);
            let (e1, c1, r2_1) = moments(&blurred);
            // Second moments add: blurred = focused ⊛ PSF ⊛ the pixel box of area sampling
            // (1/12 px² per axis; the focused image's texels sit on pixel centres). A uniform
            // 64-gon of circumradius R has E[r²] = R²(2 + cos(2π/64))/6.
            let r2_psf = r2_1 - r2_0 - 2.0 / 12.0;
            let radius = (r2_psf / ((2.0 + (2.0 * PI / 64.0).cos()) / 6.0)).sqrt();
            let radius_theory = 0.5 * c_mm / pitch;
            // Energy: the emitter's image (64-gon of circumradius r_src_px through the lens
            // centre, magnification F/s) in pixels at radiance 1.
            let area = 0.5 * 64.0 * r_src_px * r_src_px * (2.0 * PI / 64.0).sin();
            eprintln!(
                "spread CoC s = {s_mm} mm: radius {radius:.3} px vs theory {radius_theory:.3} px ({:+.2}%); energy focused {e0:.4}, blurred {e1:.4}, theory {area:.4}; centroids {c0:?} {c1:?}",
                (radius / radius_theory - 1.0) * 100.0
            );
            assert!((radius / radius_theory - 1.0).abs() < 0.01, "radius {radius} vs {radius_theory}");
            assert!((e1 / e0 - 1.0).abs() < 1e-3, "energy not conserved by the blur: {e1} vs {e0}");
            assert!((e0 / area - 1.0).abs() < 0.02, "in-focus energy {e0} vs the emitter's area {area}");
            assert!((c1 - c0).length() < 0.05 && (c0 - DVec2::splat(32.0)).length() < 0.05);
        }
    }

    /// (a′) One bright texel (radiance 1, depth 1 m; focus at 2 m, no vignetting): its PSF is
    /// the aperture's 64-gon of the circle-of-confusion radius, 15 px here, rasterised with
    /// exact pixel coverage: total energy 1 (the texel's footprint is one pixel), E[r²] =
    /// R²(2 + cos(2π/64))/6 + 2/12 (the pixel box of area sampling); in focus, the whole energy
    /// in the one pixel under the texel.
    #[test]
    fn spread_single_texel_is_the_aperture_disc() {
        let px = 64u32;
        let pitch = 0.625 / 30.0; // c = A·F·|1/d − 1/s| = 25 · 50 · 0.0005 mm = 0.625 mm = 30 px
        let sensor = Sensor { width_mm: px as f64 * pitch, height_mm: px as f64 * pitch, ..Sensor::default() };
        let cam = thin(sensor, 2.0, 2.0, Aperture::default(), false);
        let frame = LayerFrame::covering(&cam, px, px, 0.15).unwrap();
        let n = frame.texels();
        let centre = (frame.height / 2) * frame.width + frame.width / 2;
        let st = settings(px, px, 1);
        for (z, r_px) in [(1.0f32, 15.0f64), (2.0, 0.0)] {
            let mut depth_m = vec![f32::INFINITY; n];
            let mut radiance = vec![Vec3::ZERO; n];
            depth_m[centre] = z;
            radiance[centre] = Vec3::ONE;
            let layers = Layers { frame, count: 1, depth_m, radiance, to_world: DAffine3::IDENTITY };
            let img =
                spread::render_spread(&layers, None, &cam, &st, &SpreadSettings::default(), &|_| true).unwrap().image;
            let (flux, c, r2) = moments(&img);
            let expected =
                r_px * r_px * (2.0 + (2.0 * PI / 64.0).cos()) / 6.0 + if r_px > 0.0 { 2.0 / 12.0 } else { 0.0 };
            eprintln!("spread single texel at {z} m: energy {flux:.6}, centre {c:?}, E[r²] {r2:.4} vs {expected:.4}");
            assert!((flux - 1.0).abs() < 1e-6, "energy {flux}");
            assert!((r2 - expected).abs() < 1e-3 * expected.max(1.0), "E[r²] {r2} vs {expected}");
            assert!((c - DVec2::splat(32.5)).length() < 1e-6, "centre {c:?}");
        }
    }

    /// Vertical stripes of emission 0.2 and 1 filling a wall at 2 m.
    fn striped_wall(z: f32, stripes: usize, half: f32) -> RenderScene {
        let mut meshes = Vec::new();
        for k in 0..stripes {
            let x0 = -half + 2.0 * half * k as f32 / stripes as f32;
            let x1 = -half + 2.0 * half * (k + 1) as f32 / stripes as f32;
            meshes.push(rect(x0, x1, -half, half, z, (k % 2) as u32));
        }
        scene_of(&meshes, vec![emitter(0.2), emitter(1.0)])
    }

    /// (b) A flat wall in focus equals Monte Carlo within the noise of the two estimates:
    /// spreading through a pinhole against the pinhole MC render, and through a thin lens
    /// focused on the wall against its MC render (natural vignetting on: the weight table).
    #[test]
    fn spread_in_focus_wall_equals_mc() {
        let scene = striped_wall(-2.0, 12, 3.0);
        let st = settings(72, 48, 64);
        let pinhole = Camera::Pinhole(PinholeCamera::new(Sensor::default(), 50.0).unwrap());
        let lens = thin(Sensor::default(), 2.8, 2.0, Aperture::default(), true);
        for (name, cam) in [("pinhole", pinhole), ("thin f/2.8 focused on the wall", lens)] {
            let mc = mc_img(&scene, cam.clone(), &st);
            let mc2 = mc_img(&scene, cam.clone(), &RenderSettings { seed: 9, ..st.clone() });
            let (_, _, noise) = compare(&mc2, &mc);
            let sp = spread_img(&scene, cam, &st, 64, &SpreadSettings::default());
            let (m_sp, m_mc, rel_rms) = compare(&sp, &mc);
            eprintln!(
                "spread in-focus wall, {name}: mean {m_sp:.5} vs MC {m_mc:.5} ({:+.3}%), relative RMSE {rel_rms:.4} (MC vs MC {noise:.4})",
                (m_sp / m_mc - 1.0) * 100.0
            );
            // The image mean of 3456 pixels averages the noise away: 0.5% is a bias bound. Per
            // pixel: the two estimates' noise adds (MC 64 spp, layers 64 spp), ≈ √2 × one MC's.
            assert!((m_sp / m_mc - 1.0).abs() < 0.005, "{name}: mean {m_sp} vs {m_mc}");
            assert!(rel_rms < 2.0 * noise + 0.005, "{name}: relative RMSE {rel_rms} (noise {noise})");
        }
    }

    /// A defocused scene with partial occlusion: a striped wall at 3 m (stripes of emission
    /// 0.2 and 1, 0.06 m wide) and a square of emission 0.6 at 1.2 m in front of it.
    fn occlusion_scene() -> RenderScene {
        let mut meshes = Vec::new();
        let stripes = 10;
        for k in 0..stripes {
            let x0 = -0.3 + 0.6 * k as f32 / stripes as f32;
            let x1 = -0.3 + 0.6 * (k + 1) as f32 / stripes as f32;
            meshes.push(rect(x0, x1, -0.3, 0.3, -3.0, (k % 2) as u32));
        }
        meshes.push(rect(-0.04, 0.03, -0.03, 0.02, -1.2, 2));
        scene_of(&meshes, vec![emitter(0.2), emitter(1.0), emitter(0.6)])
    }

    /// The 6 × 4 mm sensor of the defocus scenes (72 × 48 px: 0.083 mm pixels), tilted by
    /// `tilt_x` degrees.
    fn small_sensor(tilt_x: f64) -> Sensor {
        Sensor { width_mm: 6.0, height_mm: 4.0, tilt_x_deg: tilt_x, ..Sensor::default() }
    }

    /// (c) A tilted sensor (Scheimpflug, 6° about the horizontal axis; 50 mm f/1.4 focused at
    /// 2 m: circles of confusion of about 7 px at the square and 3.5 px on the wall, changed
    /// by the tilt across the frame as much as by the depth) on a scene with partial occlusion:
    /// spreading with the projectively distorted PSFs agrees with Monte Carlo (mean within 1%,
    /// relative RMSE within 3× the MC noise + 2%: the layers' own errors at silhouettes), and
    /// much better than spreading with the untilted sensor's PSFs, which shows the conic PSFs
    /// carry the tilt.
    #[test]
    fn spread_tilted_sensor_matches_mc() {
        let scene = occlusion_scene();
        let st = settings(72, 48, 128);
        let cam = |tilt: f64| thin(small_sensor(tilt), 1.4, 2.0, Aperture::default(), true);
        let mc = mc_img(&scene, cam(6.0), &st);
        let mc2 = mc_img(&scene, cam(6.0), &RenderSettings { seed: 9, ..st.clone() });
        let (_, _, noise) = compare(&mc2, &mc);
        let mut results = Vec::new();
        for composite in [Composite::Over, Composite::Saturate] {
            let s = SpreadSettings { composite, ..SpreadSettings::default() };
            let sp = spread_img(&scene, cam(6.0), &st, 32, &s);
            let (m_sp, m_mc, rel) = compare(&sp, &mc);
            eprintln!(
                "spread tilt 6° ({composite:?}): mean {m_sp:.5} vs MC {m_mc:.5} ({:+.2}%), relative RMSE {rel:.4} (MC noise {noise:.4})",
                (m_sp / m_mc - 1.0) * 100.0
            );
            results.push((m_sp / m_mc - 1.0, rel));
        }
        // Untilted: spread and MC against each other (the method without tilt), and the
        // untilted spread against the tilted MC (tilt ignored).
        let flat = spread_img(&scene, cam(0.0), &st, 32, &SpreadSettings::default());
        let flat_mc = mc_img(&scene, cam(0.0), &st);
        let (_, _, rel_untilted) = compare(&flat, &flat_mc);
        let (_, _, rel_ignored) = compare(&flat, &mc);
        eprintln!("spread untilted vs untilted MC: relative RMSE {rel_untilted:.4}; untilted spread vs tilted MC: {rel_ignored:.4}");
        let (mean_err, rel) = results[0];
        assert!(mean_err.abs() < 0.01, "mean off by {mean_err}");
        assert!(rel < 3.0 * noise + 0.02, "relative RMSE {rel} (noise {noise})");
        assert!(rel < 0.5 * rel_ignored, "tilted PSFs ({rel}) should beat ignoring the tilt ({rel_ignored})");
    }

    /// (d) Straight blades: the PSF of a defocused point through an N-bladed stop is the
    /// N-gon, with N-fold symmetry — vertices at equal distances from the centre, 360°/N apart —
    /// and the spread image is invariant under a rotation by 360°/N about its centroid but not
    /// under half that.
    #[test]
    fn spread_blade_polygon_has_the_blade_symmetry() {
        let blades = 5u32;
        let aperture = Aperture {
            shape: ApertureShape::Blades { count: blades, curvature: 0.0 },
            rotation_rad: 0.2,
            anamorphic_ratio: 1.0,
        };
        let px = 64u32;
        let sensor = Sensor { width_mm: 2.0, height_mm: 2.0, ..Sensor::default() };
        let cam = thin(sensor, 2.0, 2.0, aperture, false);
        // 1. The polygon.
        let poly = spread::thin_psf(&cam, DVec3::new(0.0, 0.0, -1.0), 1.0).unwrap();
        assert_eq!(poly.len(), blades as usize);
        let c = poly.iter().copied().sum::<DVec2>() / poly.len() as f64;
        let r: Vec<f64> = poly.iter().map(|p| (*p - c).length()).collect();
        let angles: Vec<f64> = poly.iter().map(|p| (p.y - c.y).atan2(p.x - c.x)).collect();
        for k in 0..poly.len() {
            assert!((r[k] / r[0] - 1.0).abs() < 1e-9, "radii {r:?}");
            let step = (angles[(k + 1) % poly.len()] - angles[k]).rem_euclid(2.0 * PI);
            let expected = 2.0 * PI / blades as f64;
            assert!((step - expected).abs() < 1e-9 || (2.0 * PI - step - expected).abs() < 1e-9, "angles {angles:?}");
        }
        // 2. The image of a point-like emitter at 1 m.
        let pitch = 2.0 / px as f64;
        let rho_m = 0.7 * pitch * 1000.0 / 50.0 * 1e-3;
        let scene = scene_of(&[disc(Vec3::new(0.0, 0.0, -1.0), rho_m as f32, 0)], vec![emitter(1.0)]);
        let img = spread_img(&scene, cam, &settings(px, px, 1), 16, &SpreadSettings::default());
        let (_, centroid, r2) = moments(&img);
        assert!(r2 > 25.0, "the PSF should be tens of pixels across: E[r²] = {r2}");
        let value = |p: DVec2| -> f64 {
            let (x, y) = ((p.x - 0.5).floor(), (p.y - 0.5).floor());
            let (fx, fy) = (p.x - 0.5 - x, p.y - 0.5 - y);
            let at = |i: f64, j: f64| {
                if i < 0.0 || j < 0.0 || i >= px as f64 || j >= px as f64 {
                    0.0
                } else {
                    img.rgba[j as usize * px as usize + i as usize][0] as f64
                }
            };
            (at(x, y) * (1.0 - fx) + at(x + 1.0, y) * fx) * (1.0 - fy)
                + (at(x, y + 1.0) * (1.0 - fx) + at(x + 1.0, y + 1.0) * fx) * fy
        };
        let mismatch = |angle: f64| -> f64 {
            let (s, co) = angle.sin_cos();
            let mut sum = 0.0;
            for (i, p) in img.rgba.iter().enumerate() {
                let q = DVec2::new((i % px as usize) as f64 + 0.5, (i / px as usize) as f64 + 0.5) - centroid;
                let rot = centroid + DVec2::new(co * q.x - s * q.y, s * q.x + co * q.y);
                sum += (p[0] as f64 - value(rot)).abs();
            }
            sum
        };
        let (sym, half) = (mismatch(2.0 * PI / blades as f64), mismatch(PI / blades as f64));
        eprintln!("spread {blades} blades: rotation mismatch at 72° {sym:.4}, at 36° {half:.4}");
        assert!(sym < 0.3 * half, "{sym} vs {half}");
    }

    /// Variances (px²) of the red channel along the radial and tangential directions about
    /// the optical axis at `axis_px` (pixels, y down), and the flux.
    fn radial_tangential(img: &Image, axis_px: DVec2) -> (f64, f64, f64) {
        let (flux, c, _) = moments(img);
        let mut radial = c - axis_px;
        if radial.length() < 1e-9 {
            radial = DVec2::X;
        }
        let e = radial.normalize();
        let t = DVec2::new(-e.y, e.x);
        let w = img.width as usize;
        let (mut vr, mut vt) = (0.0, 0.0);
        for (i, p) in img.rgba.iter().enumerate() {
            let d = DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5) - c;
            vr += d.dot(e).powi(2) * p[0] as f64;
            vt += d.dot(t).powi(2) * p[0] as f64;
        }
        (vr / flux, vt / flux, flux)
    }

    /// A real lens (double Gauss 50 mm f/2, exact trace) through the traced PSF table: a
    /// defocused point on the axis spreads into a round blur, one near the corner of a full
    /// frame into a cat's eye (vignetted pupil samples drop out), as in Monte Carlo: the
    /// radial/tangential width ratio within 10% of MC's, the widths within 10%, the energy
    /// within 8%.
    #[test]
    fn spread_real_lens_cats_eye_matches_mc() {
        use petzval_renderer::{library_lens, ExactCamera};
        let lens = library_lens("double-gauss-50mm").unwrap();
        let (w, pitch) = (64u32, 0.0625);
        let mut ratios = Vec::new();
        for shift in [DVec2::ZERO, DVec2::new(15.0, 10.0)] {
            let sensor = Sensor {
                width_mm: w as f64 * pitch,
                height_mm: w as f64 * pitch,
                shift_mm: shift,
                ..Sensor::default()
            };
            let cam = Camera::Exact(ExactCamera::new(sensor, lens.clone(), Some(2.0)).unwrap());
            let ray = cam.generate_ray(DVec2::splat(0.5), DVec2::splat(0.5), 587.56).unwrap();
            let dist = 0.7 / -ray.direction.z;
            let p = ray.origin + ray.direction * dist;
            let rho = 3.0 * pitch / 50.0 * dist;
            let scene = scene_of(&[crate::common::icosphere(p.as_vec3(), rho as f32, 3, 0)], vec![emitter(1.0)]);
            let st = settings(w, w, 256);
            let mc = mc_img(&scene, cam.clone(), &st);
            let sp = spread_img(&scene, cam, &st, 32, &SpreadSettings::default());
            let a = sensor.axis_film_coord();
            let axis_px = DVec2::new(a.x, a.y) * w as f64;
            let (r_mc, t_mc, f_mc) = radial_tangential(&mc, axis_px);
            let (r_sp, t_sp, f_sp) = radial_tangential(&sp, axis_px);
            let (ratio_mc, ratio_sp) = ((r_mc / t_mc).sqrt(), (r_sp / t_sp).sqrt());
            eprintln!(
                "spread real lens, shift {shift}: σ radial/tangential spread {:.2}/{:.2} px (ratio {ratio_sp:.3}), MC {:.2}/{:.2} px (ratio {ratio_mc:.3}); energy spread {f_sp:.3} vs MC {f_mc:.3} ({:+.2}%)",
                r_sp.sqrt(), t_sp.sqrt(), r_mc.sqrt(), t_mc.sqrt(), (f_sp / f_mc - 1.0) * 100.0
            );
            assert!((ratio_sp / ratio_mc - 1.0).abs() < 0.1, "shape ratio {ratio_sp} vs MC {ratio_mc}");
            assert!(((t_sp / t_mc).sqrt() - 1.0).abs() < 0.1, "tangential width {} vs {}", t_sp.sqrt(), t_mc.sqrt());
            assert!(((r_sp / r_mc).sqrt() - 1.0).abs() < 0.1, "radial width {} vs {}", r_sp.sqrt(), r_mc.sqrt());
            // Energy, mechanical vignetting included (MC's flux of this small emitter has a few
            // % of noise; the layers' 3-px filter and the pixels sample it differently).
            assert!((f_sp / f_mc - 1.0).abs() < 0.08, "energy {f_sp} vs {f_mc}");
            ratios.push(ratio_sp);
        }
        assert!(ratios[1] < 0.9 * ratios[0], "no cat's eye in the corner: {ratios:?}");
    }

    /// A real lens's relative illumination (natural and mechanical vignetting, from the table
    /// of mean ray weights): a uniform emitting wall in focus through the double Gauss at f/2,
    /// on the axis and near the corner of a full frame, reads as Monte Carlo within 4% (both
    /// are estimates from a few thousand camera rays of a heavy-tailed weight: the table's
    /// 32 × 32 lens samples per node, MC's 256 per pixel; the exposure makes the axis read 1).
    #[test]
    fn spread_real_lens_flat_field_matches_mc() {
        use petzval_renderer::{library_lens, ExactCamera};
        let lens = library_lens("double-gauss-50mm").unwrap();
        let (w, pitch) = (48u32, 0.0625);
        let scene = scene_of(&[rect(-5.0, 5.0, -5.0, 5.0, -2.0, 0)], vec![emitter(1.0)]);
        let mean = |img: &Image| img.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / img.rgba.len() as f64;
        for shift in [DVec2::ZERO, DVec2::new(15.0, 10.0)] {
            let sensor = Sensor {
                width_mm: w as f64 * pitch,
                height_mm: w as f64 * pitch,
                shift_mm: shift,
                ..Sensor::default()
            };
            let cam = Camera::Exact(ExactCamera::new(sensor, lens.clone(), Some(2.0)).unwrap());
            let st = settings(w, w, 256);
            let mc = mean(&mc_img(&scene, cam.clone(), &st));
            let sp = mean(&spread_img(&scene, cam, &st, 4, &SpreadSettings::default()));
            eprintln!(
                "spread real-lens flat field, shift {shift}: spread {sp:.4} vs MC {mc:.4} ({:+.2}%)",
                (sp / mc - 1.0) * 100.0
            );
            assert!((sp / mc - 1.0).abs() < 0.04, "shift {shift}: {sp} vs {mc}");
        }
    }

    /// The same image for any number of threads (fixed chunks summed in a fixed order).
    #[test]
    fn spread_is_deterministic_across_thread_counts() {
        let scene = occlusion_scene();
        let st = settings(48, 32, 1);
        let cam = thin(Sensor { tilt_y_deg: 4.0, ..Sensor::default() }, 2.0, 2.0, Aperture::default(), true);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| spread_img(&scene, cam.clone(), &st, 8, &SpreadSettings::default()))
        };
        let (a, b) = (run(1), run(3));
        let bits = |img: &Image| img.rgba.iter().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
        assert!(a.rgba.iter().any(|p| p[0] > 0.0));
        assert_eq!(bits(&a), bits(&b));
    }

    /// `render_method(Method::Spread)` (the CLI's `--method spread`) is this spread of the
    /// layers made with the preview settings, and reports itself complete.
    #[test]
    fn spread_method_renders_through_render_method() {
        let scene = occlusion_scene();
        let st = settings(36, 24, 1);
        let cam = thin(small_sensor(3.0), 1.4, 2.0, Aperture::default(), true);
        let rig = CameraRig { camera: cam.clone(), to_world: DAffine3::IDENTITY };
        let preview = PreviewSettings { layers: LayerSettings { spp: 4, ..LayerSettings::default() } };
        let passes = std::sync::atomic::AtomicU32::new(0);
        let r = dof::render_method(dof::Method::Spread, &scene, &rig, &st, &preview, &|_| true, &|_, _| {
            passes.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        })
        .unwrap();
        assert!(r.complete && r.spp_done == st.spp);
        assert_eq!(passes.load(std::sync::atomic::Ordering::Relaxed), 1);
        let direct = spread_img(&scene, cam, &st, 4, &SpreadSettings::default());
        assert_eq!(r.image.rgba, direct.rgba);
        assert!(
            r.image.rgba.iter().any(|p| p[0] > 0.1) && r.image.rgba.iter().all(|p| p.iter().all(|v| v.is_finite()))
        );
        // Cancelled through the progress callback: incomplete, not an error.
        let c = dof::render_method(dof::Method::Spread, &scene, &rig, &st, &preview, &|_| false, &|_, _| {}).unwrap();
        assert!(!c.complete);
    }

    /// Bad settings are errors, not panics.
    #[test]
    fn spread_rejects_bad_settings() {
        let scene = occlusion_scene();
        let st = settings(16, 16, 1);
        let rig = CameraRig {
            camera: thin(Sensor::default(), 2.0, 2.0, Aperture::default(), true),
            to_world: DAffine3::IDENTITY,
        };
        let layers = dof::make_layers(&scene, &rig, &st, &PreviewSettings::default()).unwrap();
        for bad in [
            SpreadSettings { slice_blur_px: 0.0, ..SpreadSettings::default() },
            SpreadSettings { max_slices: 0, ..SpreadSettings::default() },
            SpreadSettings { pupil_grid: 1, ..SpreadSettings::default() },
        ] {
            assert!(spread::render_spread(&layers, Some(&scene), &rig.camera, &st, &bad, &|_| true).is_err());
        }
        // Layers whose planes do not match their frame.
        let mut broken = layers.clone();
        broken.depth_m.pop();
        assert!(spread::render_spread(&broken, Some(&scene), &rig.camera, &st, &SpreadSettings::default(), &|_| true)
            .is_err());
        // A real lens with a tilted sensor is refused before any layer is traced.
        let lens = petzval_renderer::library_lens("double-gauss-50mm").unwrap();
        let tilted = Sensor { tilt_x_deg: 3.0, ..Sensor::default() };
        let exact = Camera::Exact(petzval_renderer::ExactCamera::new(tilted, lens, Some(2.0)).unwrap());
        assert!(spread::check_camera(&exact).is_err());
        assert!(spread::check_camera(&thin(tilted, 2.0, 2.0, Aperture::default(), true)).is_ok());
        let rig = CameraRig { camera: exact, to_world: DAffine3::IDENTITY };
        let r = dof::render_method(
            dof::Method::Spread,
            &scene,
            &rig,
            &st,
            &PreviewSettings::default(),
            &|_| true,
            &|_, _| {},
        );
        assert!(r.is_err());
        let _ = PixelFilter::default();
    }
}
