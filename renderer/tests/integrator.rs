//! Integrator: BVH queries (watertightness, self-intersection, alpha cut-outs), the glTF BSDF
//! (energy, sampling consistency, reciprocity) and the path tracer against analytic scenes.

use crate::common::icosphere;
use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Affine3A, Quat, Vec2, Vec3, Vec4};
use petzval_renderer::integrator::bsdf::{luminance, sample_cosine_hemisphere};
use petzval_renderer::integrator::{
    primary_ray_throughput, primary_ray_throughput_packets, Bsdf, BvhQuality, Coat, LightStrategy, PathSample,
    PathTracer, RenderScene,
};
use petzval_renderer::sampler::PixelSampler;
use petzval_renderer::scene::texture::Wrap;
use petzval_renderer::scene::{
    AlphaMode, AngleWeight, Environment, Light, Material, Mesh, Scene, SpotFalloff, Texture, TextureRef,
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

fn emitter(le: Vec3, double_sided: bool) -> Material {
    Material { emissive: le, double_sided, ..diffuse(Vec3::ZERO) }
}

/// A quad with corners `o`, `o + a`, `o + a + b`, `o + b`; front side along a × b; uv (0,0)
/// at `o`, u along a, v along b.
fn quad(o: Vec3, a: Vec3, b: Vec3, material: u32) -> Mesh {
    let n = a.cross(b).normalize();
    Mesh {
        positions: vec![o, o + a, o + a + b, o + b],
        normals: vec![n; 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)],
        uv1: vec![],
        colors: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
    }
}

fn scene_of(meshes: &[Mesh], materials: Vec<Material>) -> Scene {
    let mut mesh = Mesh::default();
    for m in meshes {
        mesh.append(m, 0);
    }
    Scene { materials, ..Scene::world(mesh) }
}

/// A sampler positioned as the render loop leaves it (camera dimensions consumed).
fn sampler(px: u32, s: u32) -> PixelSampler {
    let mut sp = PixelSampler::new(px, 7, s, 1);
    sp.next_2d();
    sp.next_2d();
    sp.next_1d();
    sp
}

fn mean_radiance(tracer: &PathTracer, scene: &RenderScene, o: Vec3, d: Vec3, px: u32, n: u32) -> (Vec3, PathSample) {
    let mut sum = Vec3::ZERO;
    let mut first = None;
    for s in 0..n {
        let r = tracer.trace(scene, o, d, &mut sampler(px, s));
        assert!(!r.dropped, "dropped sample");
        assert!(r.radiance.is_finite());
        sum += r.radiance;
        first.get_or_insert(r);
    }
    (sum / n as f32, first.unwrap())
}

fn rel(a: f32, b: f32) -> f32 {
    (a - b).abs() / b.abs().max(1e-12)
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
    fn v2(&mut self) -> Vec2 {
        Vec2::new(self.next(), self.next())
    }
    fn dir(&mut self) -> Vec3 {
        let z = 1.0 - 2.0 * self.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * PI * self.next();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

// ------------------------------------------------------------------------------------------
// Ray casting.

#[test]
fn closed_sphere_is_watertight() {
    let c = Vec3::new(0.3, -0.2, 0.1);
    let rs = RenderScene::new(scene_of(&[icosphere(c, 1.0, 4, 0)], vec![diffuse(Vec3::ONE)])).unwrap();
    assert_eq!(rs.triangle_count(), 5120);
    let mut rng = Rng(3);
    let mut misses = 0;
    let n = 100_000;
    for i in 0..n {
        // Rays from outside aimed at points inside, and rays from inside (two hits / one hit).
        let (o, target) = if i % 2 == 0 {
            (c + rng.dir() * 3.0, c + rng.dir() * 0.5 * rng.next())
        } else {
            (c + rng.dir() * 0.9 * rng.next(), c + rng.dir() * 5.0)
        };
        if rs.intersect(o, target - o, f32::INFINITY).is_none() {
            misses += 1;
        }
        assert!(rs.occluded(o, target - o, f32::INFINITY) || misses > 0);
    }
    assert_eq!(misses, 0, "{misses} of {n} rays leaked through the closed mesh");
}

#[test]
fn hit_record_attributes() {
    // Quad in the z = 0 plane facing +z, uv0 along x/y.
    let q = quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), 0);
    let rs = RenderScene::new(scene_of(&[q], vec![diffuse(Vec3::ONE)])).unwrap();
    let h = rs.intersect(Vec3::new(0.5, 0.25, 2.0), Vec3::new(0.0, 0.0, -1.0), f32::INFINITY).unwrap();
    assert!((h.t - 2.0).abs() < 1e-6);
    assert!(h.position.distance(Vec3::new(0.5, 0.25, 0.0)) < 1e-6);
    assert!(h.geometric_normal.distance(Vec3::Z) < 1e-6);
    assert!(h.shading_normal.distance(Vec3::Z) < 1e-6);
    assert!(h.uv0.distance(Vec2::new(0.75, 0.625)) < 1e-6);
    assert!(h.front_face);
    let back = rs.intersect(Vec3::new(0.5, 0.25, -2.0), Vec3::Z, f32::INFINITY).unwrap();
    assert!(!back.front_face, "back faces are hit and reported");
    assert!(rs.intersect(Vec3::new(0.5, 0.25, 2.0), Vec3::NEG_Z, 1.99).is_none(), "t_max respected");
    assert!(!rs.occluded(Vec3::new(0.5, 0.25, 2.0), Vec3::NEG_Z, 1.99));
    assert!(rs.occluded(Vec3::new(0.5, 0.25, 2.0), Vec3::NEG_Z, 2.01));
    // Non-unit direction for occluded: t in units of its length.
    assert!(rs.occluded(Vec3::new(0.5, 0.25, 2.0), Vec3::new(0.0, 0.0, -4.0), 0.51));
    assert!(!rs.occluded(Vec3::new(0.5, 0.25, 2.0), Vec3::new(0.0, 0.0, -4.0), 0.49));
}

#[test]
fn normal_map_tilts_shading_normal() {
    // A normal map texel pointing along +u (tangent-space (1, 0, 1)/√2) on a quad without
    // vertex tangents: the frame comes from the UV derivatives (u along +x).
    let q = quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), 0);
    let tn = Vec3::new(1.0, 0.0, 1.0).normalize();
    let tex = Texture::constant("n", (tn * 0.5 + Vec3::splat(0.5)).extend(1.0));
    let mat =
        Material { normal_texture: Some(TextureRef { index: 0, uv_set: 0, transform: None }), ..diffuse(Vec3::ONE) };
    let mut scene = scene_of(&[q], vec![mat]);
    scene.textures.push(Arc::new(tex));
    let rs = RenderScene::new(scene).unwrap();
    let h = rs.intersect(Vec3::new(0.1, 0.2, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert!(h.shading_normal.distance(tn) < 1e-3, "{:?}", h.shading_normal);
    assert!(h.geometric_normal.distance(Vec3::Z) < 1e-6);
}

/// A normal-mapped quad keeps the geometric normal's test for light samples (Cycles' bump
/// shadowing term is zero below the geometric surface): a point light just behind it, above its
/// tilted shading normal, lights nothing in front (it leaked through when light samples skipped
/// the test); the same light just in front does.
#[test]
fn no_light_leaks_through_a_normal_mapped_quad() {
    let q = quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), 0);
    let tn = Vec3::new(1.0, 0.0, 1.0).normalize();
    let tex = Texture::constant("n", (tn * 0.5 + Vec3::splat(0.5)).extend(1.0));
    let mat =
        Material { normal_texture: Some(TextureRef { index: 0, uv_set: 0, transform: None }), ..diffuse(Vec3::ONE) };
    let lit = |z: f32| {
        let mut scene = scene_of(std::slice::from_ref(&q), vec![mat.clone()]);
        scene.textures.push(Arc::new(tex.clone()));
        scene.lights.push(Light::Point {
            position: Vec3::new(10.0, 0.0, z),
            intensity: Vec3::splat(100.0),
            range: None,
            radius_m: 0.0,
            sphere: false,
        });
        let rs = RenderScene::new(scene).unwrap();
        let tracer = PathTracer { max_depth: 1, ..PathTracer::default() };
        mean_radiance(&tracer, &rs, Vec3::new(0.0, 0.0, 2.0), -Vec3::Z, 3, 16).0
    };
    // behind: n·L = 0.63 > 0 but ng·L = −0.1 < 0
    assert_eq!(lit(-1.0), Vec3::ZERO, "light behind the quad leaked through");
    assert!(lit(1.0).y > 0.1, "light in front: {}", lit(1.0));
}

#[test]
fn spawned_rays_do_not_self_intersect_far_from_origin() {
    // A sphere 10⁴ m from the origin: positions have ULPs of ~1 mm.
    let c = Vec3::new(7000.0, -3000.0, 5000.0);
    let r = 2.0;
    let rs = RenderScene::new(scene_of(&[icosphere(c, r, 4, 0)], vec![diffuse(Vec3::ONE)])).unwrap();
    let mut rng = Rng(11);
    let mut tested = 0;
    for _ in 0..20_000 {
        let o = c + rng.dir() * 10.0;
        let target = c + rng.dir() * (0.5 * r);
        let Some(h) = rs.intersect(o, target - o, f32::INFINITY) else { continue };
        tested += 1;
        let ng = h.geometric_normal_toward(o - h.position);
        // Outward: a convex object cannot be hit again.
        let mut out = rng.dir();
        if out.dot(ng) < 0.0 {
            out = -out;
        }
        let so = h.spawn_origin(out);
        assert!(rs.intersect(so, out, f32::INFINITY).is_none(), "self-hit leaving the surface at {:?}", h.position);
        assert!(!rs.occluded(so, out, f32::INFINITY));
        // Inward: must reach the far side, not the starting triangle.
        let inw = -ng;
        let so_in = h.spawn_origin(inw);
        let h2 = rs.intersect(so_in, inw, f32::INFINITY).unwrap_or_else(|| {
            panic!(
                "inward ray must hit the far side: hit {:?} origin {so_in:?} (dist from centre {}) dir {inw:?}",
                h,
                (so_in - c).length()
            )
        });
        assert!(h2.t > 0.5 * r, "inward ray hit at t = {}", h2.t);
    }
    assert!(tested > 10_000);
}

fn alpha_quads(mode: AlphaMode, factor: f32, texture: bool) -> RenderScene {
    // Front quad at z = 0 (x in [-1, 1]) with a 2×1 texture: alpha 0 on the left half, 1 on the
    // right; an opaque back quad at z = −1.
    let front = quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), 0);
    let back = quad(Vec3::new(-2.0, -2.0, -1.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 4.0, 0.0), 1);
    let mut m = diffuse(Vec3::ONE);
    m.base_color.w = factor;
    m.alpha_mode = mode;
    if texture {
        m.base_color_texture = Some(TextureRef { index: 0, uv_set: 0, transform: None });
    }
    let mut scene = scene_of(&[front, back], vec![m, diffuse(Vec3::splat(0.5))]);
    scene.textures.push(Arc::new(Texture {
        name: "alpha".into(),
        width: 2,
        height: 1,
        texels: vec![Vec4::new(1.0, 1.0, 1.0, 0.0), Vec4::ONE],
        wrap_s: Wrap::ClampToEdge,
        wrap_t: Wrap::ClampToEdge,
        bilinear: false,
        srgb_encoded: false,
    }));
    RenderScene::new(scene).unwrap()
}

#[test]
fn alpha_mask_cuts_out() {
    let rs = alpha_quads(AlphaMode::Mask(0.5), 1.0, true);
    let left = rs.intersect(Vec3::new(-0.5, 0.0, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert_eq!(left.material_id, 1, "cut-out: the ray reaches the back quad");
    assert!((left.t - 2.0).abs() < 1e-5);
    let right = rs.intersect(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert_eq!(right.material_id, 0);
    assert!((right.t - 1.0).abs() < 1e-5);
    assert!(!rs.occluded(Vec3::new(-0.5, 0.0, 1.0), Vec3::NEG_Z, 1.5));
    assert!(rs.occluded(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z, 1.5));
    // Factor alone below the cutoff removes the whole quad; Opaque ignores alpha.
    let cut = alpha_quads(AlphaMode::Mask(0.5), 0.4, false);
    assert_eq!(cut.intersect(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap().material_id, 1);
    let opaque = alpha_quads(AlphaMode::Opaque, 0.0, true);
    assert_eq!(opaque.intersect(Vec3::new(-0.5, 0.0, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap().material_id, 0);
    // The camera sees through the cut-out to the (lit) back quad.
    let mut scene = alpha_quads(AlphaMode::Mask(0.5), 1.0, true).into_scene();
    scene.meshes[0] = {
        // Only the front quad: the cut-out shows the environment with alpha 0.
        let mut m = quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0), 0);
        m.material_ids = vec![0, 0];
        m
    };
    scene.environment = Environment::Constant(Vec3::splat(0.25));
    let rs = RenderScene::new(scene).unwrap();
    let s = PathTracer::default().trace(&rs, Vec3::new(-0.5, 0.0, 1.0), Vec3::NEG_Z, &mut sampler(0, 0));
    assert_eq!(s.alpha, 0.0);
    assert!(s.depth_m.is_infinite());
    assert!(s.radiance.distance(Vec3::splat(0.25)) < 1e-6);
}

/// Vertex colours (glTF `COLOR_0`) multiply the base colour and alpha: a diffuse plane of base
/// 0.5 with red, green, blue and white corners under a constant sky of radiance 1 reflects
/// base × colour (an open Lambertian plane under a uniform sky: L = albedo), the colour
/// interpolated across each triangle; corners of alpha 0 cut a masked, untextured material out
/// where the interpolated alpha is below the cutoff.
#[test]
fn vertex_colours_multiply_the_base_colour_and_alpha() {
    let mut plane = quad(Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), 0);
    plane.colors =
        vec![Vec4::new(1.0, 0.0, 0.0, 1.0), Vec4::new(0.0, 1.0, 0.0, 1.0), Vec4::new(0.0, 0.0, 1.0, 1.0), Vec4::ONE];
    let mut scene = scene_of(&[plane], vec![diffuse(Vec3::splat(0.5))]);
    scene.environment = Environment::Constant(Vec3::ONE);
    let rs = RenderScene::new(scene).unwrap();
    let eye = Vec3::new(0.0, 3.0, 0.0);
    // (point on the plane, its colour) for corners red (−1, 1), green (1, 1), blue (1, −1) and
    // white (−1, −1) in (x, z): the centre is halfway along the diagonal red–blue; (−0.5, −0.5)
    // is red, blue, white at barycentrics (0.25, 0.25, 0.5); (0.5, 0.5) red, green, blue at
    // (0.25, 0.5, 0.25)
    for (p, colour) in [
        (Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.5, 0.0, 0.5)),
        (Vec3::new(-0.5, 0.0, -0.5), Vec3::new(0.75, 0.5, 0.75)),
        (Vec3::new(0.5, 0.0, 0.5), Vec3::new(0.25, 0.5, 0.25)),
    ] {
        let hit = rs.intersect(eye, (p - eye).normalize(), f32::INFINITY).unwrap();
        let c = rs.vertex_color(hit.instance, hit.triangle, hit.barycentrics.x, hit.barycentrics.y);
        assert!(c.truncate().distance(colour) < 1e-5, "{p}: vertex colour {c}, expected {colour}");
        let (l, _) = mean_radiance(&PathTracer::default(), &rs, eye, p - eye, 5, 512);
        let want = 0.5 * colour;
        for k in 0..3 {
            assert!((l[k] - want[k]).abs() <= 0.03 * want.max_element(), "{p}: radiance {l}, expected {want}");
        }
    }
    // alpha: 0 on the left corners, 1 on the right; Mask(0.5) without a texture
    let rs = {
        let mut scene = alpha_quads(AlphaMode::Mask(0.5), 1.0, false).into_scene();
        let front = &mut scene.meshes[0];
        front.colors = front
            .positions
            .iter()
            .map(|p| if p.z == 0.0 { Vec4::new(1.0, 1.0, 1.0, (p.x > 0.0) as u8 as f32) } else { Vec4::ONE })
            .collect();
        RenderScene::new(scene).unwrap()
    };
    let left = rs.intersect(Vec3::new(-0.6, 0.0, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert_eq!(left.material_id, 1, "interpolated alpha 0.2: cut out");
    let right = rs.intersect(Vec3::new(0.6, 0.0, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert_eq!(right.material_id, 0, "interpolated alpha 0.8: kept");
}

/// Blender's Translucent BSDF: a Lambertian plane that scatters through itself, over a large
/// emitter facing up (radiance 1, the sky black), shows base × 1 from above (within the 0.1 %
/// of the lower hemisphere the emitter misses, and 2 % noise); the same plane reflecting
/// (not translucent) shows nothing there.
#[test]
fn translucent_surfaces_scatter_through() {
    let plane = quad(Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), 0);
    let lamp = quad(Vec3::new(-20.0, -0.5, 20.0), Vec3::new(40.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -40.0), 1);
    let leaf = Material { translucent: true, ..diffuse(Vec3::splat(0.7)) };
    for (material, want) in [(leaf, 0.7f32), (diffuse(Vec3::splat(0.7)), 0.0)] {
        let rs = RenderScene::new(scene_of(&[plane.clone(), lamp.clone()], vec![material, emitter(Vec3::ONE, false)]))
            .unwrap();
        let (l, _) = mean_radiance(&PathTracer::default(), &rs, Vec3::new(0.1, 2.0, 0.2), Vec3::NEG_Y, 7, 4096);
        for k in 0..3 {
            assert!((l[k] - want).abs() <= 0.02 * 0.7, "translucent {}: radiance {l}, expected {want}", want > 0.0);
        }
    }
}

/// Cycles' Fresnel and Layer Weight factors: the dielectric reflectance head-on ((n − 1)/(n + 1))²
/// (Fresnel IOR 1.5: 0.04; Layer Weight Fresnel, blend 0.5: index 2, 1/9), total internal
/// reflection seen from behind at grazing angles, and Facing 1 − μ^k with k = 2·blend below one
/// half, 0.5/(1 − blend) above (1 at one half).
#[test]
fn mix_angle_factors_follow_cycles() {
    use petzval_renderer::integrator::angle_factor;
    let close = |a: f32, b: f32| (a - b).abs() < 1e-6;
    assert!(close(angle_factor(&AngleWeight::Fresnel { ior: 1.5 }, 1.0, false), 0.04));
    assert!(close(angle_factor(&AngleWeight::LayerFresnel { blend: 0.5 }, 1.0, false), 1.0 / 9.0));
    assert!(close(angle_factor(&AngleWeight::LayerFresnel { blend: 0.5 }, 1.0, true), 1.0 / 9.0));
    assert_eq!(angle_factor(&AngleWeight::Fresnel { ior: 1.5 }, 0.1, true), 1.0);
    assert!(angle_factor(&AngleWeight::Fresnel { ior: 1.5 }, 0.1, false) < 1.0);
    for (blend, k) in [(0.25f32, 0.5f32), (0.5, 1.0), (0.75, 2.0)] {
        for mu in [0.1f32, 0.5, 0.9] {
            let got = angle_factor(&AngleWeight::LayerFacing { blend }, mu, false);
            assert!(close(got, 1.0 - mu.powf(k)), "blend {blend}, μ {mu}: {got}");
        }
    }
}

/// Blender's Mix Shader and the Glass/Glossy colour: a Lambert plane under a white sky whose
/// material scatters as another one with probability 0.25 (tinted) and 0.15 further down the
/// chain returns the weighted sum of their albedos; the components' emission does not count
/// (the hit material's does); a mix masked by a texture follows the mask, one by a Fresnel node
/// the reflectance at the view's angle; malformed chains are errors naming the material.
#[test]
fn mixed_materials_scatter_as_their_weighted_sum() {
    use petzval_renderer::scene::MaterialMix;
    let plane = quad(Vec3::new(-1.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -2.0), 2);
    let tint = Vec3::new(1.0, 0.5, 0.25);
    let materials = vec![
        // 0: a dark red component, its emission ignored
        Material { emissive: Vec3::splat(5.0), ..diffuse(Vec3::new(0.4, 0.0, 0.0)) },
        // 1: white, tinted, mixing 0 in with weight 0.2 (0.25 · 0.2 = 5 % overall)
        Material {
            scatter_tint: tint,
            mix: Some(MaterialMix { material: 0, weight: 0.2, weight_texture: None, weight_angle: None }),
            ..diffuse(Vec3::splat(1.0))
        },
        // 2: the plane's, grey 0.8, emitting 0.1, mixing 1 in with weight 0.25
        Material {
            emissive: Vec3::splat(0.1),
            mix: Some(MaterialMix { material: 1, weight: 0.25, weight_texture: None, weight_angle: None }),
            ..diffuse(Vec3::splat(0.8))
        },
    ];
    let mut scene = scene_of(&[plane], materials);
    scene.environment = Environment::Constant(Vec3::ONE);
    let want = Vec3::splat(0.1) + 0.75 * Vec3::splat(0.8) + 0.25 * 0.8 * tint + 0.25 * 0.2 * Vec3::new(0.4, 0.0, 0.0);
    let rs = RenderScene::new(scene.clone()).unwrap();
    let eye = Vec3::new(0.1, 2.0, 0.2);
    let (l, first) = mean_radiance(&PathTracer::default(), &rs, eye, Vec3::NEG_Y, 3, 4096);
    for k in 0..3 {
        assert!(rel(l[k], want[k]) < 0.02, "radiance {l}, expected {want}");
    }
    let albedo = 0.75 * Vec3::splat(0.8) + 0.2 * tint + 0.05 * Vec3::new(0.4, 0.0, 0.0);
    assert!(first.albedo.distance(albedo) < 1e-5, "albedo {}, expected {albedo}", first.albedo);
    // the lobe sample picks the component: shares 0.75, 0.2, 0.05, and the remapped sample
    // stays uniform in [0, 1)
    let n = 100_000;
    let (mut counts, mut mean_u) = ([0u32; 3], 0.0f64);
    let hit = rs.intersect(eye, Vec3::NEG_Y, f32::INFINITY).unwrap();
    for i in 0..n {
        let (id, u) =
            petzval_renderer::integrator::scattering_material(&rs, &hit, Vec3::Y, 2, (i as f32 + 0.5) / n as f32);
        assert!((0.0..1.0).contains(&u));
        counts[id as usize] += 1;
        mean_u += u as f64 / n as f64;
    }
    assert_eq!(counts, [5_000, 20_000, 75_000]);
    assert!((mean_u - 0.5).abs() < 1e-3, "mean remapped sample {mean_u}");
    // a mix masked by a texture (a Mix Shader factor from an image): its red channel, 0 on the
    // plane's left half (u < 0.5: all grey), 0.5 on the right (half grey, half tinted white)
    let mut masked = scene.clone();
    masked.materials[1].mix = None;
    masked.textures.push(Arc::new(Texture {
        name: "mask".into(),
        width: 2,
        height: 1,
        texels: vec![Vec4::new(0.0, 1.0, 1.0, 1.0), Vec4::new(0.5, 0.0, 0.0, 1.0)],
        wrap_s: Wrap::ClampToEdge,
        wrap_t: Wrap::ClampToEdge,
        bilinear: false,
        srgb_encoded: false,
    }));
    masked.materials[2].mix = Some(MaterialMix {
        material: 1,
        weight: 1.0,
        weight_texture: Some(TextureRef { index: 0, uv_set: 0, transform: None }),
        weight_angle: None,
    });
    let rs = RenderScene::new(masked).unwrap();
    for (x, share) in [(-0.5f32, 0.0f32), (0.5, 0.5)] {
        let eye = Vec3::new(x, 2.0, 0.2);
        let want = Vec3::splat(0.1) + (1.0 - share) * Vec3::splat(0.8) + share * tint;
        let (l, first) = mean_radiance(&PathTracer::default(), &rs, eye, Vec3::NEG_Y, 5, 4096);
        for k in 0..3 {
            assert!(rel(l[k], want[k]) < 0.02, "x = {x}: radiance {l}, expected {want}");
        }
        let albedo = (1.0 - share) * Vec3::splat(0.8) + share * tint;
        assert!(first.albedo.distance(albedo) < 1e-5, "x = {x}: albedo {}, expected {albedo}", first.albedo);
    }
    // a mix by the viewing angle (a Fresnel node, IOR 1.5): grey 0.8 mixed with the tinted white
    // by the dielectric reflectance at the view's angle, head-on and 60° off
    let mut fresnel = scene.clone();
    fresnel.materials[1].mix = None;
    fresnel.materials[2].mix = Some(MaterialMix {
        material: 1,
        weight: 1.0,
        weight_texture: None,
        weight_angle: Some(AngleWeight::Fresnel { ior: 1.5 }),
    });
    let rs = RenderScene::new(fresnel).unwrap();
    for theta in [0.0f32, 60f32.to_radians()] {
        let dir = Vec3::new(theta.sin(), -theta.cos(), 0.0);
        let eye = Vec3::new(0.0, 0.0, 0.2) - 2.0 * dir;
        let f = petzval_renderer::integrator::bsdf::fresnel_dielectric(theta.cos(), 1.5);
        let want = Vec3::splat(0.1) + (1.0 - f) * Vec3::splat(0.8) + f * tint;
        let (l, _) = mean_radiance(&PathTracer::default(), &rs, eye, dir, 6, 4096);
        for k in 0..3 {
            assert!(rel(l[k], want[k]) < 0.02, "θ = {theta}: radiance {l}, expected {want} (F = {f})");
        }
    }
    // malformed chains
    for (mix, expected) in [
        (MaterialMix { material: 2, weight: 0.5, weight_texture: None, weight_angle: None }, "cycle"),
        (MaterialMix { material: 7, weight: 0.5, weight_texture: None, weight_angle: None }, "out of range"),
        (MaterialMix { material: 0, weight: 1.5, weight_texture: None, weight_angle: None }, "outside [0, 1]"),
    ] {
        let mut bad = scene.clone();
        bad.materials[1].mix = Some(mix);
        let Err(e) = RenderScene::new(bad) else { panic!("{expected}: no error") };
        let e = e.to_string();
        assert!(e.contains("material 1") && e.contains(expected), "{e}");
    }
}

#[test]
fn alpha_blend_is_stochastic_coverage() {
    let rs = alpha_quads(AlphaMode::Blend, 0.3, false);
    let mut rng = Rng(5);
    let (mut front, mut occl) = (0, 0);
    let n = 40_000;
    for _ in 0..n {
        let o = Vec3::new(rng.next() * 1.6 - 0.8, rng.next() * 1.6 - 0.8, 1.0);
        let d = Vec3::new(rng.next() * 0.1 - 0.05, rng.next() * 0.1 - 0.05, -1.0).normalize();
        let h = rs.intersect(o, d, f32::INFINITY).unwrap();
        let hit_front = h.material_id == 0;
        front += hit_front as u32;
        // The same ray gets the same decision from the any-hit query.
        let t_front = 1.0 / d.z.abs();
        let blocked = rs.occluded(o, d, t_front * 1.01);
        assert_eq!(blocked, hit_front);
        occl += blocked as u32;
    }
    let frac = front as f32 / n as f32;
    assert!((frac - 0.3).abs() < 0.01, "blend coverage {frac}, expected 0.3");
    assert_eq!(front, occl);
}

// ------------------------------------------------------------------------------------------
// BSDF.

/// A clear coat that lives as long as the test (a scene holds its materials' coats).
fn coat(weight: f32, roughness: f32, ior: f32, tint: Vec3) -> Option<&'static Coat> {
    Coat::new(weight, roughness, ior, tint).map(|c| &*Box::leak(Box::new(c)))
}

/// A metallic-0 BSDF built once and given another base colour (`Bsdf::with_base`, what a
/// scene does per hit) is the BSDF `Bsdf::new` builds with that colour, field for field, for
/// any roughness, specular level, ior and base (out of range and non-finite included).
#[test]
fn bsdf_with_base_is_bsdf_new_bit_for_bit() {
    let mut rng = Rng(0x9e37_79b9);
    let mut next = || rng.next();
    let odd = [0.0, -0.0, 1.0, -0.3, 1.7, f32::NAN, f32::INFINITY];
    let mut cases = 0;
    for i in 0..3000 {
        let pick = |i: usize, v: f32| if i % 7 == 3 { odd[i % odd.len()] } else { v };
        let base = Vec3::new(pick(i, next() * 1.2), next(), pick(i / 3, next()));
        let template_base = Vec3::new(next(), next(), next());
        // (a few layer indices: each new one integrates its albedo tables)
        let specular = [0.0, 0.5, 1.0, 1.3, f32::NAN][i % 5];
        let ior = [1.0, 1.33, 1.5, 2.2, 0.5, f32::INFINITY][(i / 5) % 6];
        let roughness = pick(i / 5, next());
        for metallic in [0.0, -0.0] {
            let want = Bsdf::new(base, metallic, roughness, specular, ior);
            let got = Bsdf::new(template_base, metallic, roughness, specular, ior).with_base(base);
            assert_eq!(
                format!("{want:?}"),
                format!("{got:?}"),
                "base {base} roughness {roughness} specular {specular} ior {ior}"
            );
            cases += 1;
        }
    }
    assert_eq!(cases, 6000);
}

/// A Specular Tint for the BSDF cases.
static SPEC_TINT: Vec3 = Vec3::new(0.9, 0.4, 1.0);

fn bsdf_cases() -> Vec<(&'static str, Bsdf<'static>)> {
    vec![
        ("white diffuse", Bsdf::new(Vec3::ONE, 0.0, 1.0, 0.0, 1.5)),
        ("white dielectric r=0.05", Bsdf::new(Vec3::ONE, 0.0, 0.05, 1.0, 1.5)),
        ("white dielectric r=0.3", Bsdf::new(Vec3::ONE, 0.0, 0.3, 1.0, 1.5)),
        ("white dielectric r=0.7", Bsdf::new(Vec3::ONE, 0.0, 0.7, 1.0, 1.5)),
        ("white dielectric ior 2.5", Bsdf::new(Vec3::ONE, 0.0, 0.4, 1.0, 2.5)),
        ("white metal r=0.2", Bsdf::new(Vec3::ONE, 1.0, 0.2, 1.0, 1.5)),
        ("white metal r=0", Bsdf::new(Vec3::ONE, 1.0, 0.0, 1.0, 1.5)),
        ("gold metal r=0.5", Bsdf::new(Vec3::new(1.0, 0.78, 0.34), 1.0, 0.5, 1.0, 1.5)),
        ("half metal r=0.4", Bsdf::new(Vec3::new(0.9, 0.5, 0.2), 0.5, 0.4, 1.0, 1.5)),
        ("rough plastic", Bsdf::new(Vec3::new(0.2, 0.6, 0.9), 0.0, 0.9, 1.0, 1.5)),
        // Principled coats (Cycles' layering depends on wo alone: not reciprocal)
        (
            "coated red plastic",
            Bsdf::new(Vec3::new(0.8, 0.1, 0.1), 0.0, 0.6, 1.0, 1.5).with_coat(coat(1.0, 0.3, 1.5, Vec3::ONE)),
        ),
        (
            "coated gold, tinted",
            Bsdf::new(Vec3::new(1.0, 0.78, 0.34), 1.0, 0.5, 1.0, 1.5).with_coat(coat(
                0.6,
                0.4,
                1.6,
                Vec3::new(0.9, 0.6, 0.3),
            )),
        ),
        ("tinted plastic", Bsdf::new(Vec3::new(0.1, 0.3, 0.2), 0.0, 0.35, 1.0, 1.5).with_specular_tint(&SPEC_TINT)),
        (
            "tinted level-2 white, coated",
            Bsdf::new(Vec3::ONE, 0.0, 0.6, 2.0, 1.5).with_specular_tint(&SPEC_TINT).with_coat(coat(
                0.5,
                0.2,
                1.5,
                Vec3::ONE,
            )),
        ),
        (
            "coated white, sharp coat",
            Bsdf::new(Vec3::ONE, 0.0, 0.5, 1.0, 1.5).with_coat(coat(1.0, 0.03, 1.5, Vec3::ONE)),
        ),
    ]
}

/// The means of two estimators drawn together `n` times, and the standard error of their
/// difference (the two taken as independent).
fn paired_means(n: usize, mut draw: impl FnMut() -> (f64, f64)) -> (f64, f64, f64) {
    let (mut a, mut a2, mut c, mut c2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for _ in 0..n {
        let (x, y) = draw();
        a += x;
        a2 += x * x;
        c += y;
        c2 += y * y;
    }
    let nf = n as f64;
    let (ma, mc) = (a / nf, c / nf);
    let se = (((a2 / nf - ma * ma) / nf).max(0.0) + ((c2 / nf - mc * mc) / nf).max(0.0)).sqrt();
    (ma, mc, se)
}

fn wo_at(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin(), 0.0, t.cos())
}

/// White furnace for the BSDF alone: ∫ f cos dωi ≤ 1, estimated by importance sampling.
#[test]
fn bsdf_energy_at_most_one() {
    let mut rng = Rng(17);
    let mut report = String::new();
    for (name, b) in bsdf_cases() {
        for theta in [0.0f32, 30.0, 60.0, 75.0, 85.0, 89.0] {
            let wo = wo_at(theta);
            let n = 200_000;
            let mut sum = Vec3::ZERO;
            for _ in 0..n {
                if let Some(s) = b.sample(wo, rng.v2(), rng.next()) {
                    sum += s.weight;
                }
            }
            let e = sum / n as f32;
            report += &format!("{name} θ={theta}: {:.4}\n", e.max_element());
            assert!(e.max_element() <= 1.005, "{name} at θo = {theta}°: albedo {e:?} > 1");
        }
    }
    // The white dielectric conserves energy almost exactly (specular layer + scaled base).
    let b = Bsdf::new(Vec3::ONE, 0.0, 0.3, 1.0, 1.5);
    for theta in [0.0f32, 45.0, 80.0] {
        let wo = wo_at(theta);
        let mut sum = 0.0;
        let n = 400_000;
        for _ in 0..n {
            if let Some(s) = b.sample(wo, rng.v2(), rng.next()) {
                sum += s.weight.x;
            }
        }
        let e = sum / n as f32;
        assert!((e - 1.0).abs() < 0.01, "white dielectric albedo at {theta}° = {e}");
    }
    eprintln!("{report}");
}

/// Specular Tint on the dielectric layer, as Cycles' Principled BSDF has it: over a black base a
/// nearly smooth layer reflects F0·tint head-on (per channel) and approaches the untinted
/// reflectance at grazing; a grey tint over a white base loses no energy (the base takes exactly
/// what the tinted layer does not reflect), and a coloured one dims the base by its brightest
/// channel (Cycles' `closure_layering_weight`), so the channels with less tint lose energy; a
/// white tint changes nothing.
#[test]
fn specular_tint_on_the_dielectric_layer() {
    static TINT: Vec3 = Vec3::new(1.0, 0.5, 0.1);
    static GREY: Vec3 = Vec3::splat(0.5);
    static WHITE: Vec3 = Vec3::ONE;
    let mut rng = Rng(41);
    // 1. Black base, roughness 0.05: head-on F0·tint, F0 = 0.04.
    let black = Bsdf::new(Vec3::ZERO, 0.0, 0.05, 1.0, 1.5);
    let e = sampled_albedo(&black.with_specular_tint(&TINT), wo_at(0.0), 200_000, &mut rng);
    let want = TINT * 0.04;
    assert!(e.distance(want) < 0.0015, "head-on albedo {e}, expected F0·tint {want}");
    // ... and toward grazing every channel climbs toward the untinted layer's reflectance
    let (tinted, plain) = (
        sampled_albedo(&black.with_specular_tint(&TINT), wo_at(85.0), 200_000, &mut rng),
        sampled_albedo(&black, wo_at(85.0), 200_000, &mut rng),
    );
    assert!(
        tinted.z > 0.5 * plain.x && tinted.z < plain.x && tinted.x <= plain.x * 1.01,
        "at 85°: {tinted} vs {plain}"
    );
    // 2. White base under a grey tint: 1 at every angle (and the tint dims the layer itself).
    for theta in [0.0f32, 45.0, 80.0] {
        let wo = wo_at(theta);
        let b = Bsdf::new(Vec3::ONE, 0.0, 0.3, 1.0, 1.5).with_specular_tint(&GREY);
        let e = sampled_albedo(&b, wo, 400_000, &mut rng);
        assert!(
            (e.x - 1.0).abs() < 0.01 && e.distance(Vec3::splat(e.x)) < 1e-6,
            "grey tint over white at {theta}°: {e}"
        );
        // 3. A coloured tint: red (tint 1) keeps 1, the others lose what the red layer takes.
        let b = Bsdf::new(Vec3::ONE, 0.0, 0.3, 1.0, 1.5).with_specular_tint(&TINT);
        let e = sampled_albedo(&b, wo, 400_000, &mut rng);
        assert!((e.x - 1.0).abs() < 0.01 && e.z < e.y && e.y < e.x, "coloured tint over white at {theta}°: {e}");
    }
    // 4. White: the same BSDF.
    let b = Bsdf::new(Vec3::new(0.3, 0.5, 0.7), 0.0, 0.4, 1.0, 1.5);
    let (wo, wi) = (wo_at(30.0), wo_at(-50.0));
    assert_eq!(b.with_specular_tint(&WHITE).eval(wo, wi), b.eval(wo, wi));
}

/// ∫ f cos dωi at `wo`, estimated from `n` BSDF samples.
fn sampled_albedo(b: &Bsdf, wo: Vec3, n: usize, rng: &mut Rng) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for _ in 0..n {
        if let Some(s) = b.sample(wo, rng.v2(), rng.next()) {
            sum += s.weight;
        }
    }
    sum / n as f32
}

/// A clear coat (Blender's Principled Coat): over a white base nothing is lost or gained (the
/// coat passes on exactly what it does not reflect); over a black base the albedo is the coat
/// lobe's alone, w·E_c(μo), the Fresnel reflectance F0 = ((n − 1)/(n + 1))² head-on for a
/// smooth coat; a tint dims what lies under it by tint^(1/cos θt) (Beer's law along the
/// refracted view ray), and a weight of 0 changes nothing.
#[test]
fn coat_layers_conserve_energy_and_tint_the_base() {
    let mut rng = Rng(29);
    let albedo = |b: &Bsdf, wo: Vec3, rng: &mut Rng| sampled_albedo(b, wo, 400_000, rng);
    for (coat_roughness, theta) in [(0.05f32, 0.0f32), (0.05, 60.0), (0.5, 30.0), (0.5, 80.0)] {
        let wo = wo_at(theta);
        // 1. White base (a white dielectric conserves energy, see above): still 1.
        let white = Bsdf::new(Vec3::ONE, 0.0, 0.3, 1.0, 1.5).with_coat(coat(1.0, coat_roughness, 1.5, Vec3::ONE));
        let e = albedo(&white, wo, &mut rng);
        assert!((e.x - 1.0).abs() < 0.012, "coat r={coat_roughness} over white at {theta}°: {e}");
        // 2. Black base with no specular layer: the coat alone.
        let black = Bsdf::new(Vec3::ZERO, 0.0, 0.5, 0.0, 1.5).with_coat(coat(0.8, coat_roughness, 1.5, Vec3::ONE));
        let e = albedo(&black, wo, &mut rng).x;
        if coat_roughness < 0.1 && theta == 0.0 {
            let f0 = 0.04 * 0.8;
            assert!((e - f0).abs() < 0.002, "smooth coat head-on: {e}, expected {f0}");
        }
        assert!(e > 0.02 && e < 0.8, "coat over black at {theta}°: {e}");
    }
    // 3. The tint, head-on and at 60°, over a white Lambertian base (no specular layer): the
    //    base's share is (1 − w·E_c)·mix(1, tint^(1/cos θt), w).
    let tint = Vec3::new(0.8, 0.5, 0.2);
    for theta in [0.0f32, 60.0] {
        let wo = wo_at(theta);
        let plain = Bsdf::new(Vec3::ONE, 0.0, 1.0, 0.0, 1.5).with_coat(coat(0.5, 0.2, 1.5, Vec3::ONE));
        let tinted = Bsdf::new(Vec3::ONE, 0.0, 1.0, 0.0, 1.5).with_coat(coat(0.5, 0.2, 1.5, tint));
        let wi = wo_at(-20.0);
        let (a, b) = (plain.eval(wo, wi), tinted.eval(wo, wi));
        let coat_only =
            Bsdf::new(Vec3::ZERO, 0.0, 1.0, 0.0, 1.5).with_coat(coat(0.5, 0.2, 1.5, Vec3::ONE)).eval(wo, wi);
        let sin_t = theta.to_radians().sin() / 1.5;
        let path = 1.0 / (1.0 - sin_t * sin_t).sqrt();
        let expected_ratio =
            Vec3::ONE + (Vec3::new(tint.x.powf(path), tint.y.powf(path), tint.z.powf(path)) - Vec3::ONE) * 0.5;
        let ratio = (b - coat_only) / (a - coat_only);
        assert!((ratio - expected_ratio).abs().max_element() < 1e-4, "tint at {theta}°: {ratio} vs {expected_ratio}");
    }
    // 4. A weight of 0 is no coat at all.
    let base = Bsdf::new(Vec3::new(0.3, 0.5, 0.7), 0.2, 0.4, 1.0, 1.5);
    let none = base.with_coat(coat(0.0, 0.1, 1.5, tint));
    for _ in 0..100 {
        let (wo, wi) = (sample_cosine_hemisphere(rng.v2()), sample_cosine_hemisphere(rng.v2()));
        assert_eq!(base.eval(wo, wi), none.eval(wo, wi));
        assert_eq!(base.pdf(wo, wi), none.pdf(wo, wi));
    }
}

/// Glass (`Bsdf::with_transmission`), smooth and rough, seen from outside and from inside:
/// each sample's pdf and weight agree with pdf() and eval() over the whole sphere; ∫pdf = 1
/// less the samples refused; BSDF sampling and uniform sphere sampling of eval estimate the
/// same ∫ f |cos|; rough glass loses no energy between microfacets (Cycles' multiscatter
/// glass); head-on, smooth glass reflects R = ((η − 1)/(η + 1))² and refracts 1 − R, carrying
/// radiance × 1/η² into the glass and × η² out of it.
#[test]
fn glass_sample_pdf_eval_consistent() {
    let mut rng = Rng(71);
    let uniform_sphere = |u: Vec2| {
        let z = 1.0 - 2.0 * u.x;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    for roughness in [0.0f32, 0.3, 0.7] {
        for inside in [false, true] {
            let b = Bsdf::new(Vec3::new(1.0, 0.9, 0.8), 0.0, roughness, 1.0, 1.5)
                .with_transmission(1.0, 1.5)
                .seen_from_inside(inside);
            assert!(b.transmits());
            for theta in [5.0f32, 40.0, 75.0] {
                let wo = wo_at(theta);
                let name = format!("glass r={roughness} inside={inside} θ={theta}");
                let (mut refracted, mut n_ok) = (0usize, 0usize);
                for _ in 0..20_000 {
                    if let Some(s) = b.sample(wo, rng.v2(), rng.next()) {
                        n_ok += 1;
                        refracted += (s.wi.z < 0.0) as usize;
                        let pdf = b.pdf(wo, s.wi);
                        assert!(rel(pdf, s.pdf) < 1e-3, "{name}: pdf {} vs {}", s.pdf, pdf);
                        let w = b.eval(wo, s.wi) / pdf;
                        assert!(
                            (w - s.weight).abs().max_element() <= 1e-3 * w.max_element().max(1.0),
                            "{name}: weight"
                        );
                    }
                }
                assert!(refracted > 0 || inside, "{name}: nothing refracted");
                assert!(n_ok > 15_000, "{name}: {n_ok} of 20000 samples");
                if roughness >= 0.3 {
                    // ∫ f |cos| by BSDF sampling and by uniform sphere sampling, with errors
                    let (ma, mc, se) = paired_means(400_000, || {
                        let sampled = b.sample(wo, rng.v2(), rng.next()).map_or(0.0, |s| luminance(s.weight) as f64);
                        let wi = uniform_sphere(rng.v2());
                        (sampled, luminance(b.eval(wo, wi)) as f64 * 4.0 * std::f64::consts::PI)
                    });
                    assert!((ma - mc).abs() < 4.0 * se + 2e-3, "{name}: sampled {ma} vs uniform {mc} (σ {se})");
                }
            }
        }
    }
    // Rough glass keeps its energy, as Cycles' multiscatter glass does: reflected plus
    // refracted light (radiance scaling taken out) is 1 at every angle and roughness.
    for roughness in [0.3f32, 0.7, 1.0] {
        for inside in [false, true] {
            let b =
                Bsdf::new(Vec3::ONE, 0.0, roughness, 1.0, 1.45).with_transmission(1.0, 1.45).seen_from_inside(inside);
            let eta2 = if inside { 1.0 / (1.45f32 * 1.45) } else { 1.45 * 1.45 };
            for theta in [0.0f32, 45.0, 75.0] {
                let n = 100_000;
                let mut e = 0.0f64;
                for _ in 0..n {
                    if let Some(s) = b.sample(wo_at(theta), rng.v2(), rng.next()) {
                        e += (s.weight.y * if s.wi.z < 0.0 { eta2 } else { 1.0 }) as f64;
                    }
                }
                let e = e / n as f64;
                assert!((e - 1.0).abs() < 0.02, "glass r={roughness} inside={inside} θ={theta}: energy {e}");
            }
        }
    }
    // Head-on smooth glass of η = 1.5: R = 0.04; refraction carries (1 − R)/η² into it and
    // (1 − R)·η² out of it (white tint).
    let r = (0.5f32 / 2.5).powi(2);
    for (inside, expect_t) in [(false, (1.0 - r) / 2.25), (true, (1.0 - r) * 2.25)] {
        let b = Bsdf::new(Vec3::ONE, 0.0, 0.0, 1.0, 1.5).with_transmission(1.0, 1.5).seen_from_inside(inside);
        let (mut refl, mut refr) = (0.0f64, 0.0f64);
        let n = 200_000;
        for _ in 0..n {
            if let Some(s) = b.sample(Vec3::Z, rng.v2(), rng.next()) {
                if s.wi.z > 0.0 {
                    refl += s.weight.y as f64;
                } else {
                    refr += s.weight.y as f64;
                }
            }
        }
        let (refl, refr) = (refl / n as f64, refr / n as f64);
        assert!((refl - r as f64).abs() < 0.002, "inside={inside}: reflected {refl} vs R {r}");
        assert!((refr / expect_t as f64 - 1.0).abs() < 0.01, "inside={inside}: refracted {refr} vs {expect_t}");
    }
}

/// A smooth glass block (η 1.5) in front of an emitter of radiance 1, seen head-on: the camera
/// sees the emitter through both faces, (1 − R)² plus the light reflected to and fro inside,
/// (1 − R)/(1 + R) = 0.9231 in all (R = 0.04), and the block's own outline, not the emitter, at
/// its surface's depth. An opaque block of the same material hides the emitter.
#[test]
fn light_passes_through_a_glass_block() {
    let glass = |transmission: f32| Material {
        name: "glass".into(),
        base_color: glam::Vec4::ONE,
        metallic: 0.0,
        roughness: 0.0,
        specular: 1.0,
        ior: 1.5,
        transmission,
        ..Material::default()
    };
    let block = crate::common::box_mesh(Vec3::new(-0.5, -0.5, -0.2), Vec3::new(0.5, 0.5, 0.2), 0);
    let panel = quad(Vec3::new(-2.0, -2.0, -1.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 4.0, 0.0), 1);
    assert!(panel.normals[0].z > 0.0, "the panel faces the camera");
    let scene = |transmission: f32| {
        RenderScene::new(scene_of(
            &[block.clone(), panel.clone()],
            vec![glass(transmission), emitter(Vec3::ONE, false)],
        ))
        .unwrap()
    };
    let tracer = PathTracer { max_depth: 12, ..PathTracer::default() };
    let eye = Vec3::new(0.0, 0.0, 3.0);
    let (through, first) = mean_radiance(&tracer, &scene(1.0), eye, -Vec3::Z, 2, 4096);
    let r = 0.04f32;
    let expected = (1.0 - r) / (1.0 + r);
    assert!((through.y - expected).abs() < 0.003, "through glass: {through} vs {expected}");
    // with light sampling off, the same within noise (the emitter found by refraction alone)
    let bsdf_only = PathTracer { strategy: LightStrategy::BsdfOnly, ..tracer };
    let (alone, _) = mean_radiance(&bsdf_only, &scene(1.0), eye, -Vec3::Z, 2, 4096);
    assert!((alone.y - expected).abs() < 0.003, "BSDF sampling alone: {alone} vs {expected}");
    assert!((first.depth_m - 2.8).abs() < 1e-3, "the block's surface is the first hit: {}", first.depth_m);
    let (opaque, _) = mean_radiance(&tracer, &scene(0.0), eye, -Vec3::Z, 2, 256);
    assert!(opaque.y < 0.05, "an opaque block: {opaque}");
}

/// Multiple scattering: a white metal reflects all the light at every roughness and angle, as
/// Blender's multiscatter GGX does (single-scatter GGX alone reflects 0.32 at roughness 1 head
/// on), and a coloured one keeps less than white, but all of it where its F0 is 1; glossy
/// metals sample the lobe M rarely (its albedo is small), so their weights stay low-noise.
#[test]
fn rough_white_metal_keeps_its_energy() {
    let mut rng = Rng(53);
    let albedo = |b: &Bsdf, wo: Vec3, rng: &mut Rng| sampled_albedo(b, wo, 200_000, rng);
    // Glossy metals pick the multiple-scattering lobe by its albedo, F_ms·(1 − E(μo)), so
    // nearly every sample goes to the GGX lobe: the one-sample weights of a white metal at
    // roughness 0.15 stay close to 1 (variance 1.96 at 75° when M was weighted 1/(1 − Ē) ≈
    // 170× too much; the mean was right, the noise was not).
    let white = Bsdf::new(Vec3::ONE, 1.0, 0.15, 1.0, 1.5);
    for theta in [0.0f32, 45.0, 75.0] {
        let wo = wo_at(theta);
        let n = 100_000;
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let w = white.sample(wo, rng.v2(), rng.next()).map_or(0.0, |s| s.weight.x as f64);
            (sum, sum2) = (sum + w, sum2 + w * w);
        }
        let mean = sum / n as f64;
        let var = sum2 / n as f64 - mean * mean;
        assert!(var < 0.1, "white metal, roughness 0.15, θ={theta}: weight variance {var} (mean {mean})");
    }
    for roughness in [0.3f32, 0.6, 1.0] {
        let white = Bsdf::new(Vec3::ONE, 1.0, roughness, 1.0, 1.5);
        let gold = Bsdf::new(Vec3::new(1.0, 0.78, 0.34), 1.0, roughness, 1.0, 1.5);
        for theta in [0.0f32, 45.0, 80.0] {
            let wo = wo_at(theta);
            let e = albedo(&white, wo, &mut rng);
            assert!((e.x - 1.0).abs() < 0.01, "white metal, roughness {roughness}, θ={theta}: albedo {}", e.x);
            let g = albedo(&gold, wo, &mut rng);
            // gold's red channel has F0 = 1, so it is white; its green and blue keep less
            assert!((g.x - 1.0).abs() < 0.01, "gold, roughness {roughness}, θ={theta}: albedo {g:?}");
            assert!(g.y < 0.99 && g.z < g.y && g.z > 0.0, "gold, roughness {roughness}, θ={theta}: albedo {g:?}");
        }
    }
}

/// Each sample's pdf equals pdf(), its weight equals eval/pdf; and the estimate of ∫ f cos by
/// BSDF sampling agrees with uniform hemisphere sampling of eval.
#[test]
fn bsdf_sample_pdf_eval_consistent() {
    let mut rng = Rng(23);
    for (name, b) in bsdf_cases() {
        for theta in [10.0f32, 50.0, 80.0] {
            let wo = wo_at(theta);
            for _ in 0..20_000 {
                if let Some(s) = b.sample(wo, rng.v2(), rng.next()) {
                    let pdf = b.pdf(wo, s.wi);
                    assert!(rel(pdf, s.pdf) < 1e-4, "{name}: pdf {} vs {}", s.pdf, pdf);
                    let w = b.eval(wo, s.wi) / pdf;
                    assert!((w - s.weight).abs().max_element() <= 1e-4 * w.max_element().max(1.0), "{name}: weight");
                    assert!(!s.is_delta);
                }
            }
            // Compare ∫ f cos: BSDF sampling vs cosine-hemisphere sampling of eval (rough lobes
            // only; sharp lobes are not resolved by blind sampling).
            if b.alpha() >= 0.09 {
                // Luminance estimates with their standard errors.
                let (ma, mc, se) = paired_means(400_000, || {
                    let sampled = b.sample(wo, rng.v2(), rng.next()).map_or(0.0, |s| luminance(s.weight) as f64);
                    let wi = sample_cosine_hemisphere(rng.v2());
                    let uniform = if wi.z > 0.0 { luminance(b.eval(wo, wi) * (PI / wi.z)) as f64 } else { 0.0 };
                    (sampled, uniform)
                });
                assert!((ma - mc).abs() < 4.0 * se + 2e-3, "{name} θ={theta}: sampled {ma} vs uniform {mc} (σ = {se})");
            }
        }
    }
}

/// Histogram of sampled directions vs ∫ pdf over each bin (θ: cos² bins, φ: 16 bins).
#[test]
fn bsdf_sample_histogram_matches_pdf() {
    let mut rng = Rng(31);
    const NT: usize = 16;
    const NP: usize = 16;
    for (name, b) in bsdf_cases() {
        if b.alpha() < 0.05 {
            continue; // peaked lobes need finer bins than this test uses
        }
        for theta in [20.0f32, 70.0] {
            let wo = wo_at(theta);
            let n = 400_000usize;
            let mut hist = vec![0f64; NT * NP];
            let mut none = 0usize;
            for _ in 0..n {
                match b.sample(wo, rng.v2(), rng.next()) {
                    Some(s) => {
                        let c2 = (s.wi.z * s.wi.z).clamp(0.0, 0.999_999);
                        let ti = ((1.0 - c2) * NT as f32) as usize; // bins uniform in sin²θ
                        let phi = s.wi.y.atan2(s.wi.x).rem_euclid(2.0 * PI);
                        let pi = ((phi / (2.0 * PI)) * NP as f32) as usize % NP;
                        hist[ti.min(NT - 1) * NP + pi] += 1.0;
                    }
                    None => none += 1,
                }
            }
            // Expected: ∫_bin pdf dω with 8×8 sub-samples per bin. dω = dφ·d(cosθ); with
            // s = sin²θ, d(cosθ) = ds / (2 cosθ).
            let mut chi2 = 0.0f64;
            let mut dof = 0;
            let mut total_expected = 0.0;
            for ti in 0..NT {
                for pi in 0..NP {
                    let mut p = 0.0f64;
                    const K: usize = 8;
                    for a in 0..K {
                        for c in 0..K {
                            let s = (ti as f32 + (a as f32 + 0.5) / K as f32) / NT as f32;
                            let phi = (pi as f32 + (c as f32 + 0.5) / K as f32) / NP as f32 * 2.0 * PI;
                            let cos = (1.0 - s).sqrt();
                            let sin = s.sqrt();
                            let wi = Vec3::new(sin * phi.cos(), sin * phi.sin(), cos);
                            let jac = 1.0 / (2.0 * cos);
                            p += (b.pdf(wo, wi) * jac) as f64;
                        }
                    }
                    let area = (1.0 / NT as f64) * (2.0 * std::f64::consts::PI / NP as f64);
                    let expected = p / (K * K) as f64 * area * n as f64;
                    total_expected += expected;
                    let obs = hist[ti * NP + pi];
                    if expected > 20.0 {
                        chi2 += (obs - expected).powi(2) / expected;
                        dof += 1;
                    }
                }
            }
            // Integral of pdf is 1 (minus samples rejected below the horizon).
            let accepted = (n - none) as f64;
            assert!(
                (total_expected - n as f64).abs() / (n as f64) < 0.02 + none as f64 / n as f64,
                "{name}: ∫pdf = {}",
                total_expected / n as f64
            );
            assert!(accepted > 0.0);
            // Generous bound (bin integration error dominates for peaked bins): χ²/dof < 3.
            let ratio = chi2 / dof.max(1) as f64;
            assert!(ratio < 3.0, "{name} θ={theta}: χ²/dof = {ratio:.2} over {dof} bins");
        }
    }
}

/// Lambertian lobes and a smooth metal are reciprocal; rough metals (whose lobe carries the
/// energy of multiple scattering by a factor of μo, as Cycles' multiscatter GGX), dielectric
/// layers and coats are layered by the outgoing direction, as Cycles layers its Principled
/// BSDF, and are not.
#[test]
fn bsdf_reciprocity() {
    let mut rng = Rng(41);
    let reciprocal = |name: &str| ["white diffuse", "white metal r=0"].contains(&name);
    for (name, b) in bsdf_cases().into_iter().filter(|(name, _)| reciprocal(name)) {
        for _ in 0..5_000 {
            let wo = sample_cosine_hemisphere(rng.v2());
            let wi = sample_cosine_hemisphere(rng.v2());
            if wo.z < 1e-3 || wi.z < 1e-3 {
                continue;
            }
            let f1 = b.eval(wo, wi) / wi.z;
            let f2 = b.eval(wi, wo) / wo.z;
            let m = f1.max_element().max(f2.max_element());
            assert!(
                (f1 - f2).abs().max_element() <= 1e-4 * m.max(1e-3),
                "{name}: f(wo,wi) = {f1:?} ≠ f(wi,wo) = {f2:?}"
            );
        }
        assert_eq!(b.eval(Vec3::new(0.0, 0.6, 0.8), Vec3::new(0.0, 0.6, -0.8)), Vec3::ZERO, "no transmission");
    }
}

#[test]
fn bsdf_pure_lambertian_when_specular_zero() {
    let b = Bsdf::new(Vec3::splat(0.8), 0.0, 1.0, 0.0, 1.5);
    let wo = wo_at(40.0);
    for wi in [wo_at(0.0), wo_at(-60.0), Vec3::new(0.3, 0.4, 0.866).normalize()] {
        let f = b.eval(wo, wi);
        assert!((f - Vec3::splat(0.8 / PI * wi.z)).abs().max_element() < 1e-6);
    }
    assert!(luminance(Vec3::ONE) > 0.999);
}

// ------------------------------------------------------------------------------------------
// Path tracer.

/// A diffuse convex object under a uniform environment reflects exactly albedo × L.
#[test]
fn furnace_diffuse_sphere() {
    for albedo in [0.8f32, 1.0] {
        let c = Vec3::new(0.0, 1.0, 0.0);
        let mut scene = scene_of(&[icosphere(c, 1.0, 5, 0)], vec![diffuse(Vec3::splat(albedo))]);
        scene.environment = Environment::Constant(Vec3::ONE);
        let rs = RenderScene::new(scene).unwrap();
        let tracer = PathTracer { max_depth: 64, ..PathTracer::default() };
        let eye = Vec3::new(0.3, 1.4, 4.0);
        let mut rng = Rng(7);
        let mut worst = 0.0f32;
        for px in 0..24 {
            let target = c + rng.dir() * 0.95;
            let d = (target - eye).normalize();
            let (l, first) = mean_radiance(&tracer, &rs, eye, d, px, 2048);
            assert_eq!(first.alpha, 1.0);
            assert!(first.depth_m.is_finite() && first.depth_m > 2.0 && first.depth_m < 4.2);
            assert!((first.albedo - Vec3::splat(albedo)).abs().max_element() < 1e-6);
            assert!(first.normal.dot(d) < 0.0, "normal faces the camera");
            for k in 0..3 {
                worst = worst.max(rel(l[k], albedo));
                assert!(rel(l[k], albedo) < 0.01, "albedo {albedo}: pixel {px} radiance {l:?}");
            }
        }
        eprintln!("furnace albedo {albedo}: worst relative error {worst:.4}");
        // Missed rays: environment radiance, alpha 0.
        let s = tracer.trace(&rs, eye, Vec3::new(0.0, 1.0, 0.0), &mut sampler(0, 0));
        assert_eq!(s.alpha, 0.0);
        assert_eq!(s.radiance, Vec3::ONE);
    }
}

fn plane_scene(albedo: f32) -> Scene {
    // Ground plane y = 0 facing +y (quad with a × b along +y), 20 m wide.
    let q = quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0);
    scene_of(&[q], vec![diffuse(Vec3::splat(albedo))])
}

/// Radiance leaving the plane toward a camera ray hitting `p`.
fn plane_radiance(scene: Scene, p: Vec3, spp: u32) -> Vec3 {
    let rs = RenderScene::new(scene).unwrap();
    let eye = Vec3::new(1.0, 1.5, 2.0);
    mean_radiance(&PathTracer::default(), &rs, eye, p - eye, 3, spp).0
}

#[test]
fn point_and_spot_lights_on_diffuse_plane() {
    let albedo = 0.5;
    let p = Vec3::new(0.1, 0.0, 0.2);
    let lp = Vec3::new(0.3, 2.0, -0.2);
    let intensity = Vec3::new(10.0, 20.0, 30.0);
    let d = lp - p;
    let r2 = d.length_squared();
    let cos = d.normalize().y;
    let expected = intensity * (albedo / PI * cos / r2);

    let mut s = plane_scene(albedo);
    s.lights.push(Light::Point { position: lp, intensity, range: None, radius_m: 0.0, sphere: false });
    let l = plane_radiance(s, p, 16);
    for k in 0..3 {
        assert!(rel(l[k], expected[k]) < 0.01, "point: {l:?} vs {expected:?}");
    }

    // glTF range window: clamp(1 − (d/range)⁴, 0, 1)².
    let range = 3.0;
    let x = r2.sqrt() / range;
    let win = (1.0 - x.powi(4)).clamp(0.0, 1.0).powi(2);
    let mut s = plane_scene(albedo);
    s.lights.push(Light::Point { position: lp, intensity, range: Some(range), radius_m: 0.0, sphere: false });
    let l = plane_radiance(s, p, 16);
    assert!(rel(l.y, expected.y * win) < 0.01, "range: {l:?} vs {:?}", expected * win);

    // Spot pointing at p: inside the inner cone = point light; between the cones: glTF's
    // squared linear ramp in cos, or Blender's (Cycles') smoothstep in cos over
    // (1 − cos outer)·blend with blend = 1 − inner/outer; outside: dark.
    let axis = -d.normalize();
    for falloff in [SpotFalloff::Gltf, SpotFalloff::Blender] {
        for (inner, outer, tilt_deg) in [(0.3f32, 0.6f32, 0.0f32), (0.2, 0.6, 25.0), (0.1, 0.3, 30.0), (0.3, 0.6, 30.0)]
        {
            // Tilt the spot axis about z by `tilt_deg`.
            let t = tilt_deg.to_radians();
            let dir = glam::Quat::from_rotation_z(t) * axis;
            let cd = dir.dot(-d.normalize());
            let ramp = match falloff {
                SpotFalloff::Gltf => ((cd - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0).powi(2),
                SpotFalloff::Blender => {
                    let x = ((cd - outer.cos()) / ((1.0 - outer.cos()) * (1.0 - inner / outer))).clamp(0.0, 1.0);
                    x * x * (3.0 - 2.0 * x)
                }
            };
            let mut s = plane_scene(albedo);
            s.lights.push(Light::Spot {
                position: lp,
                direction: dir,
                intensity,
                inner_cone_rad: inner,
                outer_cone_rad: outer,
                range: None,
                falloff,
                radius_m: 0.0,
                sphere: false,
            });
            let l = plane_radiance(s, p, 16);
            let e = expected * ramp;
            assert!(
                (l.y - e.y).abs() <= 0.01 * expected.y * ramp.max(1e-6) + 1e-7,
                "spot {falloff:?} {inner}/{outer} tilt {tilt_deg}: {l:?} vs {e:?}"
            );
        }
    }

    // Directional: E·cosθ·albedo/π.
    let mut s = plane_scene(albedo);
    let dir = Vec3::new(0.3, -1.0, 0.2).normalize();
    s.lights.push(Light::Directional { direction: dir, irradiance: Vec3::splat(3.0), angle_rad: 0.0 });
    let l = plane_radiance(s, p, 16);
    let e = 3.0 * (-dir.y) * albedo / PI;
    assert!(rel(l.x, e) < 0.01, "directional: {l:?} vs {e}");
}

/// Lights with a size (Blender's Radius and sun Angle, as Cycles renders them): a point light
/// of radius r is a disc facing the shading point, so straight above a plane at height h its
/// irradiance is I/(h² + r²) (I/h² for a point), or a sphere (I/h²; inside it, I/r²); a sun of angular diameter 2θ spreads its
/// directions uniformly over the cone and keeps the irradiance E·cos α of the parallel sun on
/// a plane it lights wholly (the cone's mean cosine cos α·(1 + cos θ)/2 times Cycles'
/// normalisation 2/(1 + cos θ)).
#[test]
fn lights_with_a_radius_or_an_angle_give_their_analytic_irradiance() {
    let albedo = 0.5;
    let p = Vec3::new(0.1, 0.0, 0.2);
    let (h, i) = (1.5f32, 10.0f32);
    for sphere in [false, true] {
        for radius in [0.0f32, 0.3, 1.2] {
            let mut s = plane_scene(albedo);
            s.lights.push(Light::Point {
                position: p + Vec3::Y * h,
                intensity: Vec3::splat(i),
                range: None,
                radius_m: radius,
                sphere,
            });
            let l = plane_radiance(s, p, 4096);
            // a sphere's irradiance is its centre's as a point (a Lambertian sphere wholly above)
            let expected = if sphere { i / (h * h) } else { i / (h * h + radius * radius) } * albedo / PI;
            assert!(rel(l.y, expected) < 0.01, "point of radius {radius} (sphere {sphere}): {} vs {expected}", l.y);
        }
    }
    // a small sphere far away (sin²θmax = 1e-8: cos θmax rounds to 1 in f32) keeps its light
    let mut s = plane_scene(albedo);
    let far = 50.0f32;
    s.lights.push(Light::Point {
        position: p + Vec3::Y * far,
        intensity: Vec3::splat(i),
        range: None,
        radius_m: 0.005,
        sphere: true,
    });
    let l = plane_radiance(s, p, 256);
    let expected = i / (far * far) * albedo / PI;
    assert!(rel(l.y, expected) < 0.01, "a far small sphere: {} vs {expected}", l.y);
    // inside a sphere light of radius r, a uniform direction: I/(πr²)·π = I/r² on the plane
    let mut s = plane_scene(albedo);
    s.lights.push(Light::Point {
        position: p + Vec3::Y * 0.2,
        intensity: Vec3::splat(i),
        range: None,
        radius_m: 0.5,
        sphere: true,
    });
    let l = plane_radiance(s, p, 8192);
    // (the sphere's lower cap is below the plane: only its radiance above counts, L·π·1)
    let expected = i / (PI * 0.25) * PI * albedo / PI;
    assert!(rel(l.y, expected) < 0.02, "inside a sphere: {} vs {expected}", l.y);
    let e = 3.0f32;
    for (angle_deg, tilt_deg) in [(0.0f32, 0.0f32), (20.0, 0.0), (20.0, 40.0), (60.0, 25.0)] {
        let tilt = tilt_deg.to_radians();
        let direction = Vec3::new(tilt.sin(), -tilt.cos(), 0.0);
        let mut s = plane_scene(albedo);
        s.lights.push(Light::Directional { direction, irradiance: Vec3::splat(e), angle_rad: angle_deg.to_radians() });
        let l = plane_radiance(s, p, 4096);
        let expected = e * tilt.cos() * albedo / PI;
        assert!(rel(l.y, expected) < 0.01, "sun {angle_deg}° tilted {tilt_deg}°: {} vs {expected}", l.y);
    }
}

/// A light's emitting surface (`Material::light_emitter`: an area light from USD or the
/// add-on) is not geometry, as in Cycles: a sun shining through it still lights the ground
/// below (an ordinary emissive quad shadows it), a camera ray reaching its back passes through
/// to the ground, and from the front it is seen with its emission.
#[test]
fn light_emitters_cast_no_shadow_and_are_seen_from_the_front_only() {
    let albedo = 0.5;
    let ground = quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0);
    // a 1 m panel 1 m up, facing down (its front toward the ground)
    let panel = quad(Vec3::new(-0.5, 1.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0), 1);
    assert!(panel.normals[0].y < 0.0, "the panel faces down");
    let emitter = |light_emitter: bool| Material {
        name: "panel".into(),
        base_color: glam::Vec4::new(0.0, 0.0, 0.0, 1.0),
        metallic: 0.0,
        specular: 0.0,
        emissive: Vec3::splat(2.0),
        light_emitter,
        ..Material::default()
    };
    let scene = |light_emitter: bool| {
        let mut s =
            scene_of(&[ground.clone(), panel.clone()], vec![diffuse(Vec3::splat(albedo)), emitter(light_emitter)]);
        s.lights.push(Light::Directional { direction: -Vec3::Y, irradiance: Vec3::splat(3.0), angle_rad: 0.0 });
        RenderScene::new(s).unwrap()
    };
    let tracer = PathTracer { max_depth: 1, ..PathTracer::default() };
    let (light, solid) = (scene(true), scene(false));
    // 1. the ground under the panel, seen from the side: the sun (3 W/m², albedo 0.5) plus the
    //    panel's light; an ordinary emitter shadows the sun
    let eye = Vec3::new(3.0, 0.5, 0.0);
    let below = Vec3::new(0.0, 0.0, 0.0) - eye;
    let (l_light, _) = mean_radiance(&tracer, &light, eye, below, 1, 1024);
    let (l_solid, _) = mean_radiance(&tracer, &solid, eye, below, 1, 1024);
    let sun = 3.0 * albedo / PI;
    assert!(l_light.y > sun && l_light.y - l_solid.y > 0.9 * sun, "light {l_light}, solid {l_solid}");
    assert!(rel(l_light.y - l_solid.y, sun) < 0.02, "the sun's share {} vs {sun}", l_light.y - l_solid.y);
    // 2. from above, through the panel's back: the same (Lambertian) ground point, not the back
    let top = Vec3::new(0.0, 3.0, 0.0);
    let (through, first) = mean_radiance(&tracer, &light, top, -Vec3::Y, 2, 1024);
    assert!(first.depth_m > 2.5 && rel(through.y, l_light.y) < 0.02, "seen through: {through} at {}", first.depth_m);
    let (back, first) = mean_radiance(&tracer, &solid, top, -Vec3::Y, 2, 256);
    assert!(first.depth_m < 2.5 && back.y < 1e-6, "an ordinary emitter's back: {back} at {}", first.depth_m);
    // 3. from below, its front: its emission
    let (front, _) = mean_radiance(&tracer, &light, Vec3::new(0.0, 0.2, 0.0), Vec3::Y, 3, 16);
    assert!(rel(front.y, 2.0) < 1e-4, "its front: {front}");
}

/// A surface hidden from the camera (`Material::visible_to_camera` false: Blender's Ray
/// Visibility > Camera, off for lights in Blender 5) is not seen by camera rays, which go on
/// to what lies behind it (depth and alpha included), yet it lights the scene as before and is
/// seen in a mirror. Autofocus looks through it too.
#[test]
fn surfaces_hidden_from_the_camera_are_seen_only_by_other_rays() {
    let ground = quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0);
    // a 1 m light panel 1 m up, facing down, and a mirror on the ground beside it
    let panel = quad(Vec3::new(-0.5, 1.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0), 1);
    let mirror = quad(Vec3::new(1.5, 0.01, 0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -1.0), 2);
    let chrome = Material {
        name: "mirror".into(),
        base_color: glam::Vec4::ONE,
        metallic: 1.0,
        roughness: 0.0,
        ..Material::default()
    };
    let scene = |visible: bool| {
        let panel_mat = Material {
            name: "panel".into(),
            base_color: glam::Vec4::new(0.0, 0.0, 0.0, 1.0),
            metallic: 0.0,
            specular: 0.0,
            emissive: Vec3::splat(2.0),
            light_emitter: true,
            visible_to_camera: visible,
            ..Material::default()
        };
        let mut s = scene_of(
            &[ground.clone(), panel.clone(), mirror.clone()],
            vec![diffuse(Vec3::splat(0.5)), panel_mat, chrome.clone()],
        );
        s.environment = Environment::Constant(Vec3::splat(0.25));
        RenderScene::new(s).unwrap()
    };
    let (seen, hidden) = (scene(true), scene(false));
    let tracer = PathTracer { max_depth: 2, ..PathTracer::default() };
    // 1. Looking up at the panel's front from 0.2 m: its emission, or through it the sky.
    let below = Vec3::new(0.0, 0.2, 0.0);
    let (front, first) = mean_radiance(&tracer, &seen, below, Vec3::Y, 3, 16);
    assert!(rel(front.y, 2.0) < 1e-4 && first.alpha == 1.0, "seen: {front}");
    let (sky, first) = mean_radiance(&tracer, &hidden, below, Vec3::Y, 3, 16);
    assert!(rel(sky.y, 0.25) < 1e-6, "hidden: the sky behind it, {sky}");
    assert!(first.alpha == 0.0 && first.depth_m.is_infinite(), "hidden: a miss ({} at {})", first.alpha, first.depth_m);
    // 2. The ground it lights, seen from the side: the same light, path for path.
    let eye = Vec3::new(3.0, 0.5, 2.0);
    let to_ground = Vec3::new(0.0, 0.0, 0.0) - eye;
    let (lit_seen, _) = mean_radiance(&tracer, &seen, eye, to_ground, 1, 512);
    let (lit_hidden, _) = mean_radiance(&tracer, &hidden, eye, to_ground, 1, 512);
    assert!(lit_seen.y > 0.25 * 0.5 * 1.05, "the panel lights the ground: {lit_seen}");
    assert_eq!(lit_seen, lit_hidden, "the panel's light on the ground");
    // 3. In the mirror (x 1.5…2.5 on the ground): the camera ray toward the panel's mirror
    //    image (0, −0.98, 0) meets the mirror 1.12 m away and goes on up to the panel's front.
    let eye = Vec3::new(3.0, 0.5, -0.5);
    let toward_image = Vec3::new(0.0, -0.98, 0.0) - eye;
    let (m_seen, first) = mean_radiance(&tracer, &seen, eye, toward_image, 5, 16);
    let (m_hidden, _) = mean_radiance(&tracer, &hidden, eye, toward_image, 5, 16);
    assert!((first.depth_m - 1.12).abs() < 0.01, "the camera ray hits the mirror first ({} m)", first.depth_m);
    assert!(m_seen.y > 1.5 && m_seen == m_hidden, "the panel in the mirror: seen {m_seen}, hidden {m_hidden}");
    // 4. Autofocus from below the panel looks through it (to nothing: infinity).
    let look_up = glam::DAffine3::from_cols(glam::DVec3::X, glam::DVec3::Z, glam::DVec3::NEG_Y, below.as_dvec3());
    assert!((petzval_renderer::shot::autofocus_m(&seen, &look_up).unwrap() - 0.8).abs() < 1e-3);
    assert_eq!(petzval_renderer::shot::autofocus_m(&hidden, &look_up), None);
}

/// Blender's Shadow Terminator > Geometry Offset (0.1 by default): a smooth-shaded low-poly
/// sphere is lit up to its terminator like the smooth sphere its normals describe, as Cycles
/// renders it. Without the offset (shadow rays from the flat facets, light below a facet's
/// plane dropped) the band next to the terminator of an 80-face icosphere came out 29 % darker
/// than that of a 20 480-face one (now 4 % brighter).
#[test]
fn smooth_low_poly_meshes_are_lit_to_the_terminator() {
    let band = |level: u32| {
        let mut s = scene_of(&[icosphere(Vec3::ZERO, 1.0, level, 0)], vec![diffuse(Vec3::splat(0.8))]);
        s.lights.push(Light::Directional { direction: -Vec3::X, irradiance: Vec3::ONE, angle_rad: 0.0 });
        let rs = RenderScene::new(s).unwrap();
        let tracer = PathTracer { max_depth: 1, ..PathTracer::default() };
        // camera rays from +z onto the lit side next to the terminator (0 < x < 0.15)
        let (mut sum, mut n) = (0.0f64, 0u32);
        for i in 0..24 {
            for j in 0..48 {
                let (x, y) = (0.15 * (i as f32 + 0.5) / 24.0, -0.9 + 1.8 * (j as f32 + 0.5) / 48.0);
                let (l, first) = mean_radiance(&tracer, &rs, Vec3::new(x, y, 5.0), -Vec3::Z, i * 48 + j, 4);
                if first.alpha == 1.0 {
                    sum += l.y as f64;
                    n += 1;
                }
            }
        }
        sum / n as f64
    };
    let (low, smooth) = (band(1), band(5));
    assert!(smooth > 0.01, "the smooth sphere's band is lit: {smooth}");
    assert!((low / smooth - 1.0).abs() < 0.08, "80 faces {low} against 20 480 faces {smooth}: {}", low / smooth);
}

#[test]
fn shadows_block_lights() {
    let p = Vec3::new(0.1, 0.0, 0.2);
    let lp = Vec3::new(0.3, 2.0, -0.2);
    // A blocker halfway between p and the light (both sides: a single-sided quad still casts).
    let mid = 0.5 * (p + lp);
    let blocker = quad(mid + Vec3::new(-0.2, 0.0, 0.2), Vec3::new(0.4, 0.0, 0.0), Vec3::new(0.0, 0.0, -0.4), 0);
    let ground = quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0);
    let mut s = scene_of(&[ground, blocker], vec![diffuse(Vec3::splat(0.5))]);
    s.lights.push(Light::Point {
        position: lp,
        intensity: Vec3::splat(10.0),
        range: None,
        radius_m: 0.0,
        sphere: false,
    });
    let rs = RenderScene::new(s).unwrap();
    let eye = Vec3::new(2.0, 1.0, 2.0);
    // max_depth 1: direct light only (the blocker's top would otherwise bounce light down).
    let tracer = PathTracer { max_depth: 1, ..PathTracer::default() };
    let (l, _) = mean_radiance(&tracer, &rs, eye, p - eye, 0, 16);
    assert_eq!(l, Vec3::ZERO, "point in the blocker's shadow");
    let q = Vec3::new(-1.5, 0.0, 1.0);
    let (l, _) = mean_radiance(&tracer, &rs, eye, q - eye, 0, 16);
    assert!(l.x > 0.0, "point outside the shadow is lit");
}

#[test]
fn shared_types_are_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<RenderScene>();
    check::<PathTracer>();
    check::<PathSample>();
}

/// Irradiance at a point below the centre of a parallel square emitter (side `s`, height `h`).
fn square_irradiance(le: f32, s: f32, h: f32) -> f32 {
    let a = (s / 2.0) / h;
    let b = a;
    let fq = 1.0 / (2.0 * PI)
        * (a / (1.0 + a * a).sqrt() * (b / (1.0 + a * a).sqrt()).atan()
            + b / (1.0 + b * b).sqrt() * (a / (1.0 + b * b).sqrt()).atan());
    le * PI * 4.0 * fq
}

#[test]
fn area_light_strategies_agree_with_analytic() {
    let le = 5.0;
    let (side, h) = (1.0f32, 1.0f32);
    let albedo = 0.7;
    // Emitter at y = h facing down (a × b along −y).
    let light = quad(Vec3::new(-0.5, h, -0.5), Vec3::new(side, 0.0, 0.0), Vec3::new(0.0, 0.0, side), 1);
    assert!(light.normals[0].y < -0.99);
    let ground = quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0);
    let scene = scene_of(&[ground, light], vec![diffuse(Vec3::splat(albedo)), emitter(Vec3::splat(le), false)]);
    let rs = RenderScene::new(scene).unwrap();
    assert_eq!(rs.light_count(), 2);
    let p = Vec3::ZERO;
    let eye = Vec3::new(1.5, 0.5, 1.5);
    let expected = albedo / PI * square_irradiance(le, side, h);
    let mut results = vec![];
    for (strategy, spp) in
        [(LightStrategy::Mis, 4096), (LightStrategy::LightOnly, 4096), (LightStrategy::BsdfOnly, 65536)]
    {
        let tracer = PathTracer { strategy, ..PathTracer::default() };
        let (l, _) = mean_radiance(&tracer, &rs, eye, p - eye, 9, spp);
        results.push((strategy, l.x));
        assert!(rel(l.x, expected) < 0.02, "{strategy:?}: {} vs analytic {expected}", l.x);
    }
    eprintln!("area light: analytic {expected:.5}, {results:?}");

    // Seen directly: Le from the front, nothing from the back (single sided), Le from both
    // sides when double sided.
    let tracer = PathTracer::default();
    let below = tracer.trace(&rs, Vec3::new(0.1, 0.5, 0.1), Vec3::Y, &mut sampler(0, 0));
    assert!((below.radiance - Vec3::splat(le)).abs().max_element() < 1e-5, "{:?}", below.radiance);
    let above = tracer.trace(&rs, Vec3::new(0.1, 2.0, 0.1), Vec3::NEG_Y, &mut sampler(0, 0));
    assert_eq!(above.radiance, Vec3::ZERO);
    assert_eq!(above.alpha, 1.0);
    let light = quad(Vec3::new(-0.5, h, -0.5), Vec3::new(side, 0.0, 0.0), Vec3::new(0.0, 0.0, side), 0);
    let rs2 = RenderScene::new(scene_of(&[light], vec![emitter(Vec3::splat(le), true)])).unwrap();
    let above = tracer.trace(&rs2, Vec3::new(0.1, 2.0, 0.1), Vec3::NEG_Y, &mut sampler(0, 0));
    assert!((above.radiance - Vec3::splat(le)).abs().max_element() < 1e-5);
}

/// A clear coat over an emitter dims its emission as it dims a base (Cycles' Principled BSDF):
/// seen head-on by w·E_c(1) = w·F0 for a smooth coat; lighting a plane, light sampling and BSDF
/// sampling find the same dimmed emission (the coat's weight at each direction).
#[test]
fn a_coat_dims_the_emission_under_it() {
    let le = 5.0;
    let (side, h) = (1.0f32, 1.0f32);
    let coated = |w: f32| Material { coat: w, coat_roughness: 0.02, ..emitter(Vec3::splat(le), false) };
    let light = quad(Vec3::new(-0.5, h, -0.5), Vec3::new(side, 0.0, 0.0), Vec3::new(0.0, 0.0, side), 1);
    let ground = quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0);
    let rs = RenderScene::new(scene_of(&[ground, light], vec![diffuse(Vec3::splat(0.7)), coated(0.8)])).unwrap();
    // 1. Head-on: Le·(1 − 0.8·0.04) within the table's accuracy.
    let tracer = PathTracer::default();
    let below = tracer.trace(&rs, Vec3::new(0.1, 0.5, 0.1), Vec3::Y, &mut sampler(0, 0));
    let expected = le * (1.0 - 0.8 * 0.04);
    assert!((below.radiance.x - expected).abs() < 2e-3 * le, "head-on {} vs {expected}", below.radiance.x);
    // 2. The plane below: the three strategies agree, and the coat took w·F ≈ 3.2–4 % off the
    //    emitter's light (the plane sees it within 35° of its normal), less the little the
    //    coat reflects back of the lit plane.
    let p = Vec3::ZERO;
    let eye = Vec3::new(1.5, 0.5, 1.5);
    let mut results = vec![];
    for (strategy, spp) in
        [(LightStrategy::Mis, 4096), (LightStrategy::LightOnly, 4096), (LightStrategy::BsdfOnly, 65536)]
    {
        let tracer = PathTracer { strategy, ..PathTracer::default() };
        let (l, _) = mean_radiance(&tracer, &rs, eye, p - eye, 9, spp);
        results.push(l.x);
    }
    let uncoated = RenderScene::new(scene_of(
        &[
            quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0),
            quad(Vec3::new(-0.5, h, -0.5), Vec3::new(side, 0.0, 0.0), Vec3::new(0.0, 0.0, side), 1),
        ],
        vec![diffuse(Vec3::splat(0.7)), coated(0.0)],
    ))
    .unwrap();
    let (plain, _) = mean_radiance(&PathTracer::default(), &uncoated, eye, p - eye, 9, 4096);
    eprintln!("coated emitter: MIS, light, BSDF {results:?}; uncoated {}", plain.x);
    for r in &results[1..] {
        assert!(rel(*r, results[0]) < 0.02, "strategies disagree: {results:?}");
    }
    let dimming = results[0] / plain.x;
    assert!(dimming > 0.955 && dimming < 0.975, "coated/uncoated {dimming}");
}

/// Environment lighting a plane: MIS, light-only and BSDF-only agree (E = π·L, L_o = albedo·L).
#[test]
fn environment_strategies_agree() {
    let mut scene = plane_scene(0.6);
    scene.environment = Environment::Constant(Vec3::new(0.5, 1.0, 2.0));
    let rs = RenderScene::new(scene).unwrap();
    let eye = Vec3::new(1.0, 1.5, 2.0);
    for strategy in [LightStrategy::Mis, LightStrategy::LightOnly, LightStrategy::BsdfOnly] {
        let tracer = PathTracer { strategy, ..PathTracer::default() };
        let (l, _) = mean_radiance(&tracer, &rs, eye, -eye, 1, 4096);
        let e = Vec3::new(0.5, 1.0, 2.0) * 0.6;
        assert!((l - e).abs().max_element() < 0.01 * e.max_element(), "{strategy:?}: {l:?} vs {e:?}");
    }
}

#[test]
fn deterministic_and_finite() {
    // Glossy metal + emitter + point light + environment, deep paths.
    let c = Vec3::new(0.0, 1.0, 0.0);
    let mut scene = scene_of(
        &[
            icosphere(c, 1.0, 3, 1),
            quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0),
            quad(Vec3::new(-0.5, 3.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0), 2),
        ],
        vec![
            diffuse(Vec3::splat(0.5)),
            Material {
                base_color: Vec4::new(0.9, 0.6, 0.3, 1.0),
                metallic: 1.0,
                roughness: 0.0,
                ..Material::default()
            },
            emitter(Vec3::splat(10.0), false),
        ],
    );
    scene.lights.push(Light::Point {
        position: Vec3::new(2.0, 3.0, 1.0),
        intensity: Vec3::splat(5.0),
        range: None,
        radius_m: 0.0,
        sphere: false,
    });
    scene.environment = Environment::Constant(Vec3::splat(0.1));
    let rs = RenderScene::new(scene).unwrap();
    let tracer = PathTracer { max_depth: 32, ..PathTracer::default() };
    let eye = Vec3::new(0.5, 1.2, 4.0);
    let mut rng = Rng(9);
    for px in 0..64 {
        let d = (c + rng.dir() * 1.5 - eye).normalize();
        for s in 0..64 {
            let a = tracer.trace(&rs, eye, d, &mut sampler(px, s));
            let b = tracer.trace(&rs, eye, d, &mut sampler(px, s));
            assert_eq!(a, b);
            assert!(!a.dropped && a.radiance.is_finite() && a.radiance.min_element() >= 0.0);
        }
    }
}

#[test]
fn malformed_meshes_are_repaired() {
    let mut q = quad(Vec3::ZERO, Vec3::X, Vec3::Y, 5); // material 5 does not exist
    q.indices.push([0, 1, 99]); // bad index
    q.material_ids.push(0);
    q.indices.push([0, 0, 1]); // degenerate
    q.material_ids.push(0);
    q.normals = vec![Vec3::NAN; 4];
    let scene = scene_of(&[q], vec![diffuse(Vec3::ONE)]);
    let rs = RenderScene::new(scene).unwrap();
    assert_eq!(rs.triangle_count(), 2);
    assert!(!rs.scene().warnings.is_empty());
    let h = rs.intersect(Vec3::new(0.3, 0.3, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert!(h.shading_normal.is_finite());
    let s = PathTracer::default().trace(&rs, Vec3::new(0.3, 0.3, 1.0), Vec3::NEG_Z, &mut sampler(0, 0));
    assert!(s.radiance.is_finite() && !s.dropped);
    // Empty scene.
    let rs = RenderScene::new(Scene::default()).unwrap();
    assert!(rs.intersect(Vec3::ZERO, Vec3::Z, f32::INFINITY).is_none());
    assert!(!rs.occluded(Vec3::ZERO, Vec3::Z, f32::INFINITY));
}

// ------------------------------------------------------------------------------------------
// Throughput.

/// ~1.05 M triangles: a 600×600 height-field grid and a displaced level-7 icosphere.
fn million_triangle_scene() -> Scene {
    million_triangle_scene_sized(600)
}

/// The benchmark's height field (2 n² triangles) and displaced sphere.
fn million_triangle_scene_sized(n: usize) -> Scene {
    let mut grid = Mesh::default();
    for j in 0..=n {
        for i in 0..=n {
            let (x, z) = (i as f32 / n as f32 * 40.0 - 20.0, j as f32 / n as f32 * 40.0 - 20.0);
            let y = 0.3 * (x * 0.7).sin() * (z * 0.5).cos() + 0.05 * (x * 5.0).sin();
            grid.positions.push(Vec3::new(x, y, z));
            grid.normals.push(Vec3::Y);
            grid.uv0.push(Vec2::new(i as f32 / n as f32, j as f32 / n as f32));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = (j * (n + 1) + i) as u32;
            let b = a + 1;
            let c = a + (n + 1) as u32;
            let d = c + 1;
            grid.indices.push([a, c, b]);
            grid.indices.push([b, c, d]);
        }
    }
    grid.material_ids = vec![0; grid.indices.len()];
    grid.tangents = vec![Vec4::ZERO; grid.positions.len()];
    let mut sphere = icosphere(Vec3::new(0.0, 3.0, 0.0), 3.0, if n >= 600 { 7 } else { 5 }, 0);
    for p in sphere.positions.iter_mut() {
        let q = *p - Vec3::new(0.0, 3.0, 0.0);
        *p += q * 0.05 * (q.x * 4.0).sin() * (q.y * 3.0).cos();
    }
    scene_of(&[grid, sphere], vec![diffuse(Vec3::splat(0.5))])
}

#[test]
fn throughput_smoke() {
    let rs = RenderScene::new(scene_of(&[icosphere(Vec3::ZERO, 1.0, 3, 0)], vec![diffuse(Vec3::ONE)])).unwrap();
    assert!(primary_ray_throughput(&rs, 10_000) > 0.0);
    assert!(rs.bvh_memory_bytes() > 0);
}

/// Packets of rays give each ray the hit `intersect` gives it alone, bit for bit: coherent
/// camera rays (a row of pixels, one pixel's samples), incoherent rays from random origins in all
/// octants, partial packets, invalid lanes (zero direction, NaN origin, t_max ≤ 0, short t_max),
/// instanced meshes (the top level), stochastic alpha, and rays through mesh vertices and along
/// edges (exact zeros in the triangle test). Exact ties between two primitives could in
/// principle resolve differently; none occurs in these 99 000 rays. Run with and without
/// `PETZVAL_SIMD=baseline` (tests/run does both).
#[test]
fn packets_match_single_rays() {
    let mut scene = million_triangle_scene_sized(120);
    // Instanced spheres (two instances → a top-level BVH) and a stochastic-alpha quad.
    let ball = scene.add_mesh(icosphere(Vec3::ZERO, 1.0, 3, 0));
    scene.add_instance(ball, Affine3A::from_translation(Vec3::new(4.0, 1.5, 2.0)));
    scene.add_instance(
        ball,
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(1.5),
            Quat::from_rotation_y(0.7),
            Vec3::new(-5.0, 2.0, -3.0),
        ),
    );
    let mut veil = diffuse(Vec3::ONE);
    veil.base_color.w = 0.5;
    veil.alpha_mode = AlphaMode::Blend;
    scene.materials.push(veil);
    let m = (scene.materials.len() - 1) as u32;
    scene.add_world_mesh(quad(Vec3::new(-6.0, 0.5, 5.0), Vec3::new(12.0, 0.0, 0.0), Vec3::new(0.0, 5.0, 0.0), m));
    let rs = RenderScene::new(scene).unwrap();
    let mut state = 7u32;
    let mut next = || {
        state = state.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
        ((state >> 8) as f32) / (1u32 << 24) as f32
    };
    let (mut rays, mut hits, mut ties) = (0usize, 0usize, 0usize);
    let mut check = |batch: &[(Vec3, Vec3, f32)]| {
        let got = rs.intersect_packet(batch);
        for (i, &(o, d, t)) in batch.iter().enumerate() {
            let want = rs.intersect(o, d, t);
            if got[i] != want {
                // Tolerated only for an exact tie: same distance, another primitive.
                let tie = matches!((got[i], want), (Some(a), Some(b)) if a.t == b.t);
                assert!(tie, "lane {i} of {batch:?}: packet {:?}, single {:?}", got[i], want);
                ties += 1;
            }
            hits += want.is_some() as usize;
            rays += 1;
        }
        for g in &got[batch.len()..] {
            assert!(g.is_none());
        }
    };
    let eye = Vec3::new(8.0, 12.0, 14.0);
    let (fwd, up) = ((-eye).normalize(), Vec3::Y);
    let right = fwd.cross(up).normalize();
    let up = right.cross(fwd);
    // 1. Rows of 8 pixels and 8 samples of one pixel, 200×200 pixels.
    for y in 0..200 {
        for x0 in (0..200).step_by(8) {
            let pixel = |x: f32, y: f32| fwd + right * ((x / 200.0) * 1.2 - 0.6) + up * (0.6 - (y / 200.0) * 1.2);
            let mut jitter = || (next(), next());
            let row: Vec<_> =
                (0..8).map(|k| (eye, pixel((x0 + k) as f32 + 0.5, y as f32 + 0.5), f32::INFINITY)).collect();
            check(&row);
            let samples: Vec<_> = (0..8)
                .map(|_| {
                    let (a, b) = jitter();
                    (eye, pixel(x0 as f32 + a, y as f32 + b), f32::INFINITY)
                })
                .collect();
            check(&samples);
        }
    }
    // 2. Incoherent rays, partial packets and invalid lanes.
    for n in 0..4000 {
        let len = 1 + n % 8;
        let batch: Vec<_> = (0..len)
            .map(|k| {
                let o = Vec3::new(next() * 30.0 - 15.0, next() * 8.0 - 1.0, next() * 30.0 - 15.0);
                let d = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                match (n + k) % 23 {
                    0 => (o, Vec3::ZERO, f32::INFINITY),
                    1 => (Vec3::new(f32::NAN, 0.0, 0.0), d, f32::INFINITY),
                    2 => (o, d, 0.0),
                    3 => (o, d, next() * 3.0),
                    4 => (o, Vec3::new(0.0, -1.0, -0.0), f32::INFINITY),
                    _ => (o, d, f32::INFINITY),
                }
            })
            .collect();
        check(&batch);
    }
    // 3. Straight down through the middles of the grid's border edges, 8 to a packet (one
    //    shared axis permutation): an exact zero in an edge function, which the 8-lane triangle
    //    test leaves to the scalar test's double-precision retry. (Inner edges and vertices
    //    are shared, so their hits are exact ties.)
    let n = 120;
    let at = |i: f32| i / n as f32 * 40.0 - 20.0;
    let border: Vec<Vec3> = (0..n)
        .flat_map(|i| {
            let m = at(i as f32 + 0.5);
            [Vec3::new(-20.0, 10.0, m), Vec3::new(20.0, 10.0, m), Vec3::new(m, 10.0, -20.0), Vec3::new(m, 10.0, 20.0)]
        })
        .collect();
    for chunk in border.chunks(8) {
        let batch: Vec<_> = chunk.iter().map(|&o| (o, Vec3::new(0.0, -1.0, 0.0), f32::INFINITY)).collect();
        check(&batch);
    }
    assert!(rays > 90_000 && hits > rays / 3, "{hits} hits of {rays} rays");
    assert_eq!(ties, 0, "{ties} ties resolved differently");
}

/// `cargo test -p petzval-renderer --release --test renderer integrator::bench -- --ignored --nocapture`
#[test]
#[ignore]
fn bench_million_triangles() {
    for quality in [BvhQuality::Fast, BvhQuality::Medium, BvhQuality::High] {
        let scene = million_triangle_scene();
        let t0 = std::time::Instant::now();
        let rs = RenderScene::with_quality(scene, quality).unwrap();
        let total = t0.elapsed();
        let tris = rs.triangle_count();
        let rays = 2_000_000;
        let _ = primary_ray_throughput(&rs, 100_000); // warm-up
        let rps = primary_ray_throughput(&rs, rays);
        let _ = primary_ray_throughput_packets(&rs, 100_000); // warm-up
        let rps_packets = primary_ray_throughput_packets(&rs, rays);
        // Hit fraction of the same camera (see `primary_ray_throughput`).
        let hit_fraction = {
            let (bmin, bmax) = rs.bounds();
            let center = 0.5 * (bmin + bmax);
            let back = Vec3::new(0.35, 0.8, 0.6).normalize();
            let eye = center + back * (0.8 * (bmax - bmin).length());
            let (right, half, side) = (Vec3::Y.cross(back).normalize(), 25f32.to_radians().tan(), 200);
            let up = back.cross(right);
            let mut hits = 0;
            for i in 0..side * side {
                let (x, y) = ((i % side) as f32 + 0.5, (i / side) as f32 + 0.5);
                let d =
                    right * ((x / side as f32) * 2.0 - 1.0) * half + up * (1.0 - (y / side as f32) * 2.0) * half - back;
                hits += rs.intersect(eye, d, f32::INFINITY).is_some() as u32;
            }
            hits as f64 / (side * side) as f64
        };
        eprintln!(
            "{quality:?}: {tris} triangles, BVH build {:.3} s (RenderScene::new {:.3} s), {:.1} MB = {:.1} B/triangle, primary rays {:.2} M/s/core, in packets of 8 {:.2} M/s/core ({:.0}% hit)",
            rs.bvh_build_time().as_secs_f64(),
            total.as_secs_f64(),
            rs.bvh_memory_bytes() as f64 / 1e6,
            rs.bvh_memory_bytes() as f64 / tris as f64,
            rps / 1e6,
            rps_packets / 1e6,
            hit_fraction * 100.0
        );
    }
}

// ------------------------------------------------------------------------------------------
// Many lights: the light tree.

/// Irradiance at `p` (normal `n`) from a Lambertian polygon of radiance `le` seen from its
/// front side, unoccluded: Lambert's formula E = (le/2)·Σ Θk (n·uk), f64.
fn polygon_irradiance(le: f64, p: Vec3, n: Vec3, verts: &[Vec3]) -> f64 {
    let v: Vec<glam::DVec3> = verts.iter().map(|&q| (q - p).as_dvec3().normalize()).collect();
    let mut sum = 0.0;
    for k in 0..v.len() {
        let (a, b) = (v[k], v[(k + 1) % v.len()]);
        let theta = a.dot(b).clamp(-1.0, 1.0).acos();
        sum += theta * n.as_dvec3().dot(a.cross(b).normalize());
    }
    0.5 * le * sum.abs()
}

/// 10 × 10 small emissive quads (0.1 m, facing down, 0.5 m up, 0.25 m apart, five radiance
/// levels) over a diffuse plane: (scene, [(radiance, corners)] of the emitters).
fn light_grid(albedo: f32) -> (Scene, Vec<(f32, [Vec3; 4])>) {
    let (s, h, pitch) = (0.1f32, 0.5f32, 0.25f32);
    let mut meshes = vec![quad(Vec3::new(-10.0, 0.0, 10.0), Vec3::new(20.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -20.0), 0)];
    let mut emitters = vec![];
    let levels = [1.0f32, 2.0, 4.0, 8.0, 16.0];
    for i in 0..10 {
        for j in 0..10 {
            let c = Vec3::new((i as f32 - 4.5) * pitch, h, (j as f32 - 4.5) * pitch);
            let o = c - Vec3::new(s / 2.0, 0.0, s / 2.0);
            let level = (i * 7 + j * 3) % levels.len();
            let q = quad(o, Vec3::new(s, 0.0, 0.0), Vec3::new(0.0, 0.0, s), 1 + level as u32);
            assert!(q.normals[0].y < -0.99);
            emitters.push((
                levels[level],
                [o, o + Vec3::new(s, 0.0, 0.0), o + Vec3::new(s, 0.0, s), o + Vec3::new(0.0, 0.0, s)],
            ));
            meshes.push(q);
        }
    }
    let mut materials = vec![diffuse(Vec3::splat(albedo))];
    materials.extend(levels.iter().map(|&l| emitter(Vec3::splat(l), false)));
    (scene_of(&meshes, materials), emitters)
}

/// Radiance leaving the plane at `p` toward `eye`, and its standard error.
fn plane_estimate(tracer: &PathTracer, rs: &RenderScene, eye: Vec3, p: Vec3, px: u32, n: u32) -> (f64, f64) {
    let (mut s1, mut s2) = (0.0f64, 0.0f64);
    for s in 0..n {
        let r = tracer.trace(rs, eye, p - eye, &mut sampler(px, s));
        assert!(!r.dropped && r.radiance.is_finite());
        let x = r.radiance.x as f64;
        s1 += x;
        s2 += x * x;
    }
    let mean = s1 / n as f64;
    let var = (s2 / n as f64 - mean * mean).max(0.0);
    (mean, (var / n as f64).sqrt())
}

#[test]
fn light_tree_many_lights_matches_analytic() {
    use petzval_renderer::integrator::LightSelection;
    let albedo = 0.6f32;
    let (scene, emitters) = light_grid(albedo);
    let mut rs = RenderScene::new(scene).unwrap();
    assert_eq!(rs.light_count(), 200);
    assert_eq!(rs.light_selection(), LightSelection::Tree);
    // Under a quad, between quads, at the grid's edge, outside the grid.
    let points =
        [Vec3::new(-0.375, 0.0, 0.125), Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.1, 0.0, -0.9), Vec3::new(1.9, 0.0, 0.4)];
    // Tree: 32768 samples (error ≲ 0.5% at 1σ even without the sampler's stratification);
    // power-proportional selection, for comparison only, 8192.
    for (k, &p) in points.iter().enumerate() {
        let e: f64 = emitters.iter().map(|(le, v)| polygon_irradiance(*le as f64, p, Vec3::Y, v)).sum();
        let expected = albedo as f64 / std::f64::consts::PI * e;
        let mut line = format!("p {p}: analytic {expected:.5}");
        for selection in [LightSelection::Tree, LightSelection::Power] {
            rs.set_light_selection(selection);
            for strategy in [LightStrategy::Mis, LightStrategy::LightOnly] {
                let tracer = PathTracer { strategy, ..PathTracer::default() };
                // Camera below the emitters' plane (their black backs would hide the floor).
                let spp = if selection == LightSelection::Tree { 32768 } else { 8192 };
                let (mean, se) = plane_estimate(&tracer, &rs, p + Vec3::new(0.6, 0.3, 0.8), p, k as u32, spp);
                let err = (mean - expected).abs() / expected;
                line += &format!(
                    ", {selection:?}/{strategy:?} {mean:.5} (err {:.2}%, rel. std. dev. per sample {:.3})",
                    err * 100.0,
                    se / mean * (spp as f64).sqrt()
                );
                if selection == LightSelection::Tree {
                    assert!(err < 0.01, "{selection:?}/{strategy:?} at {p}: {mean} vs analytic {expected}");
                }
            }
        }
        eprintln!("{line}");
    }
}

/// Selection consistency: the pmf a pick returns equals `light_pmf` for that light, the pmfs
/// of all lights sum to one, picks follow the pmf, and the MIS light pdf of an emitter hit
/// equals the pdf of the light sample that produced it.
#[test]
fn light_tree_pmf_consistent() {
    // The grid plus a point light and a spot; then also lights at infinity (directional,
    // environment) and a double-sided emitter facing sideways.
    let (mut scene, _) = light_grid(0.5);
    scene.lights.push(Light::Point {
        position: Vec3::new(0.7, 0.8, 0.2),
        intensity: Vec3::splat(3.0),
        range: None,
        radius_m: 0.0,
        sphere: false,
    });
    scene.lights.push(Light::Spot {
        position: Vec3::new(-0.6, 1.0, -0.3),
        direction: Vec3::new(0.2, -1.0, 0.1),
        intensity: Vec3::splat(8.0),
        inner_cone_rad: 0.3,
        outer_cone_rad: 0.5,
        range: None,
        falloff: SpotFalloff::Gltf,
        radius_m: 0.0,
        sphere: false,
    });
    let mixed = {
        let mut s = scene.clone();
        s.lights.push(Light::Directional {
            direction: Vec3::new(0.3, -1.0, -0.2),
            irradiance: Vec3::splat(0.5),
            angle_rad: 0.0,
        });
        s.environment = Environment::Constant(Vec3::splat(0.05));
        let n = s.materials.len() as u32;
        s.materials.push(emitter(Vec3::splat(3.0), true));
        let side = quad(Vec3::new(1.5, 0.1, -0.2), Vec3::new(0.0, 0.0, 0.4), Vec3::new(0.0, 0.3, 0.0), n);
        s.meshes[0].append(&side, 0);
        s
    };
    let mut worst_pick = 0.0f32;
    let mut worst_sum = 0.0f32;
    let mut rng = Rng(31);
    for (name, scene) in [("grid+punctual", scene), ("mixed", mixed)] {
        let rs = RenderScene::new(scene).unwrap();
        assert_eq!(rs.light_selection(), petzval_renderer::integrator::LightSelection::Tree); // spots too
        let nl = rs.light_count();
        for trial in 0..60 {
            // Points on the plane (normal up) and, for the rest, anywhere with any normal or none.
            let (p, n) = match trial % 3 {
                0 => (Vec3::new(rng.next() * 5.0 - 2.5, 0.0, rng.next() * 5.0 - 2.5), Vec3::Y),
                1 => (Vec3::new(rng.next() * 4.0 - 2.0, rng.next() * 0.45, rng.next() * 4.0 - 2.0), rng.dir()),
                _ => (Vec3::new(rng.next() * 4.0 - 2.0, rng.next() * 1.5 - 0.2, rng.next() * 4.0 - 2.0), Vec3::ZERO),
            };
            let pmfs: Vec<f32> = (0..nl).map(|i| rs.light_pmf(p, n, i)).collect();
            let sum: f32 = pmfs.iter().sum();
            assert!(sum <= 1.0 + 1e-4, "{name}: pmfs sum to {sum} at {p}, {n}");
            // Below the emitters and facing them, every light can contribute: the sum is one.
            if trial % 3 == 0 || (name == "grid+punctual" && n == Vec3::ZERO && p.y < 0.5) {
                worst_sum = worst_sum.max((sum - 1.0).abs());
                assert!((sum - 1.0).abs() < 1e-4, "{name}: pmfs sum to {sum} at {p}, {n}");
            }
            // Picks: stratified u; returned pmf = light_pmf; frequencies follow the pmf.
            let m = 20000;
            let mut counts = vec![0u32; nl];
            for j in 0..m {
                let u = (j as f32 + 0.5) / m as f32;
                if let Some((i, pmf)) = rs.pick_light(p, n, u) {
                    assert!(pmf > 0.0);
                    let r = (pmf - pmfs[i]).abs() / pmfs[i];
                    worst_pick = worst_pick.max(r);
                    assert!(r < 1e-5, "{name}: pick pmf {pmf} vs light_pmf {}", pmfs[i]);
                    counts[i] += 1;
                }
            }
            for i in 0..nl {
                let expected = pmfs[i] as f64 * m as f64;
                // Stratified u: counts are within a few of the expectation.
                assert!(
                    (counts[i] as f64 - expected).abs() <= 2.0 + 1e-3 * expected,
                    "{name}: light {i}: {} picks, expected {expected:.1}",
                    counts[i]
                );
            }
        }
        // MIS: the light pdf of the emitter hit by a light sample's ray is the sample's pdf.
        let mut checked = 0;
        for _ in 0..1000 {
            let p = Vec3::new(rng.next() * 4.0 - 2.0, 0.001, rng.next() * 4.0 - 2.0);
            let Some(ls) = rs.sample_light_at(p, Vec3::Y, rng.next(), rng.v2()) else { continue };
            if ls.delta || ls.target.is_none() {
                continue;
            }
            let hit = rs.intersect(p, ls.wi, f32::INFINITY).expect("the sampled emitter is hit");
            if (hit.t - (ls.target.unwrap() - p).length()).abs() > 1e-3 {
                continue; // another emitter in the way
            }
            let pdf = rs.triangle_light_pdf(p, Vec3::Y, &hit, ls.wi);
            assert!((pdf - ls.pdf).abs() <= 1e-3 * ls.pdf, "{name}: MIS light pdf {pdf} vs sample pdf {}", ls.pdf);
            checked += 1;
        }
        assert!(checked > 200, "{name}: {checked} area-light samples checked");
    }
    eprintln!("light tree: worst |pick pmf − light_pmf|/pmf {worst_pick:.2e}, worst |Σ pmf − 1| {worst_sum:.2e}");
}

// ------------------------------------------------------------------------------------------
// Value limits (issue 12): an emitter the film cannot sum is refused, naming it.

#[test]
fn emitted_values_beyond_the_limit_are_refused_by_name() {
    use petzval_renderer::limits::MAX_RADIANCE;
    use petzval_renderer::scene::environment::EnvironmentMap;
    let q = quad(Vec3::new(-1.0, -1.0, 0.0), Vec3::X * 2.0, Vec3::Y * 2.0, 0);
    let build = |materials: Vec<Material>, lights: Vec<Light>, environment: Environment| {
        let scene =
            Scene { lights, environment, source: "lamps.gltf".into(), ..scene_of(std::slice::from_ref(&q), materials) };
        RenderScene::new(scene).map(|_| ()).map_err(|e| e.to_string())
    };
    let lamp = |le: f32| Material { name: "Lamp".into(), ..emitter(Vec3::splat(le), false) };
    // at the limit: accepted; beyond it, non-finite or negative: refused, naming file and emitter
    assert!(build(vec![lamp(MAX_RADIANCE)], vec![], Environment::Black).is_ok());
    for le in [MAX_RADIANCE * 2.0, f32::INFINITY, f32::NAN, -1.0] {
        let e = build(vec![lamp(le)], vec![], Environment::Black).unwrap_err();
        assert!(e.contains("lamps.gltf") && e.contains("material 0 'Lamp'") && e.contains("emission"), "{e}");
    }
    let sun = Light::Directional { direction: -Vec3::Y, irradiance: Vec3::new(1.0, f32::NAN, 1.0), angle_rad: 0.0 };
    let e = build(vec![diffuse(Vec3::ONE)], vec![sun], Environment::Black).unwrap_err();
    assert!(e.contains("light 0 (directional)") && e.contains("irradiance"), "{e}");
    let e = build(vec![diffuse(Vec3::ONE)], vec![], Environment::Constant(Vec3::splat(1e20))).unwrap_err();
    assert!(e.contains("environment") && e.contains("radiance"), "{e}");
    let map = |texel: f32, strength: f32| {
        let texels = vec![Vec3::splat(0.5), Vec3::splat(texel), Vec3::splat(0.5), Vec3::splat(0.5)];
        Environment::Map(EnvironmentMap::new("sky.exr", 2, 2, texels, strength, 0.0).unwrap())
    };
    assert!(build(vec![diffuse(Vec3::ONE)], vec![], map(1e6, 1.0)).is_ok());
    // a bright texel times the strength, not either alone, is what the film sums
    let e = build(vec![diffuse(Vec3::ONE)], vec![], map(1e6, 1e10)).unwrap_err();
    assert!(e.contains("sky.exr") && e.contains("brightest texel"), "{e}");
}

// ------------------------------------------------------------------------------------------
// Spot cone edges with the light tree.

/// As [`plane_estimate`] with independent samples (each its own seed: a scramble of sample 0),
/// so that the standard error is that of i.i.d. samples, not an overestimate for stratified ones.
fn plane_estimate_iid(tracer: &PathTracer, rs: &RenderScene, eye: Vec3, p: Vec3, px: u32, n: u32) -> (f64, f64) {
    let (mut s1, mut s2) = (0.0f64, 0.0f64);
    for s in 0..n {
        let mut sp = PixelSampler::new(px, 11, 0, s);
        sp.next_2d();
        sp.next_2d();
        sp.next_1d();
        let r = tracer.trace(rs, eye, p - eye, &mut sp);
        assert!(!r.dropped && r.radiance.is_finite());
        let x = r.radiance.x as f64;
        s1 += x;
        s2 += x * x;
    }
    let mean = s1 / n as f64;
    let var = (s2 / n as f64 - mean * mean).max(0.0) * n as f64 / (n as f64 - 1.0);
    (mean, (var / n as f64).sqrt())
}

/// Shading points on the plane y = 0 seen from spot (`pos`, unit `axis`) at angle `theta` from
/// its axis, in four azimuths about it (those whose ray reaches the plane).
fn spot_ray_points(pos: Vec3, axis: Vec3, theta: f32) -> Vec<Vec3> {
    let e1 = axis.cross(Vec3::Z).normalize();
    let e2 = axis.cross(e1);
    (0..4)
        .filter_map(|k| {
            let phi = k as f32 * PI / 2.0 + 0.3;
            let d = axis * theta.cos() + (e1 * phi.cos() + e2 * phi.sin()) * theta.sin();
            (d.y < -0.05).then(|| {
                let p = pos + d * (-pos.y / d.y);
                Vec3::new(p.x, 0.0, p.z)
            })
        })
        .collect()
}

/// Spot cone edges with the light tree: a hard spot (inner = outer, Blender's blend 0 as its
/// glTF exporter writes it) and a soft one (inner < outer) among 100 emissive quads and a point
/// light, shading points on the floor just inside and outside the cones' edges (down to 50 µrad
/// from them). At each point:
/// * the tree's picks (stratified u) follow the pmf they return (and `light_pmf`);
/// * the direct lighting estimated with the tree and with power-proportional selection agree
///   with each other, and with the analytic value (Lambert's polygon formula for the quads,
///   I·att·cosθ/d² for the punctual lights, att = KHR_lights_punctual's ramp for the soft
///   spot and a step at the outer angle for the hard one), within 4.5 standard errors
///   (independent samples, 16384 per estimate; ~250 comparisons, so a false alarm has a
///   probability of ~0.2 %).
#[test]
fn spot_cone_edges_unbiased_with_light_tree() {
    use petzval_renderer::integrator::LightSelection;
    let albedo = 0.5f32;
    let (mut scene, emitters) = light_grid(albedo);
    // Spots below the quads (0.5 m up) and a point light beside the grid: nothing is occluded.
    let spots = [
        // (position, aim, inner, outer, intensity)
        (Vec3::new(2.4, 0.4, -0.6), Vec3::new(1.7, 0.0, -0.6), 0.3f32, 0.3f32, 3.0f32),
        (Vec3::new(-2.4, 0.4, 0.5), Vec3::new(-1.7, 0.0, 0.5), 0.2, 0.35, 3.0),
    ];
    for &(position, aim, inner, outer, i) in &spots {
        scene.lights.push(Light::Spot {
            position,
            direction: (aim - position).normalize(),
            intensity: Vec3::splat(i),
            inner_cone_rad: inner,
            outer_cone_rad: outer,
            range: None,
            falloff: SpotFalloff::Gltf,
            radius_m: 0.0,
            sphere: false,
        });
    }
    let point = (Vec3::new(0.0, 0.3, 2.0), 2.0f32);
    scene.lights.push(Light::Point {
        position: point.0,
        intensity: Vec3::splat(point.1),
        range: None,
        radius_m: 0.0,
        sphere: false,
    });
    let lights = scene.lights.clone();
    let mut rs = RenderScene::new(scene).unwrap();
    assert_eq!(rs.light_selection(), LightSelection::Tree, "the tree is the default, with spots too");
    let nl = rs.light_count();
    assert_eq!(nl, 203); // punctual lights first (spots 0, 1; point 2), then 200 triangles

    // Exact direct lighting at p (normal +y), f64.
    let analytic = |p: Vec3| -> f64 {
        let mut e: f64 = emitters.iter().map(|(le, v)| polygon_irradiance(*le as f64, p, Vec3::Y, v)).sum();
        for l in &lights {
            let (pos, i, att) = match *l {
                Light::Point { position, intensity, .. } => (position, intensity.x, 1.0),
                Light::Spot { position, direction, intensity, inner_cone_rad, outer_cone_rad, .. } => {
                    let cd = direction.as_dvec3().normalize().dot((p - position).as_dvec3().normalize());
                    let (ci, co) = ((inner_cone_rad as f64).cos(), (outer_cone_rad as f64).cos());
                    let att = if inner_cone_rad >= outer_cone_rad {
                        if cd > co {
                            1.0
                        } else {
                            0.0
                        }
                    } else {
                        ((cd - co) / (ci - co)).clamp(0.0, 1.0).powi(2)
                    };
                    (position, intensity.x, att)
                }
                Light::Directional { .. } => unreachable!(),
            };
            let d = (pos - p).as_dvec3();
            e += i as f64 * att * d.normalize().y / d.length_squared();
        }
        albedo as f64 / std::f64::consts::PI * e
    };

    // Angles from each spot's axis: around its outer edge (and the soft one's inner edge).
    let offsets = [-4e-3f32, -2e-3, -1e-3, -5e-4, -2e-4, -5e-5, 5e-5, 5e-4, 2e-3];
    let mut points = vec![];
    for (k, &(position, aim, inner, outer, _)) in spots.iter().enumerate() {
        let axis = (aim - position).normalize();
        let mut angles: Vec<f32> = offsets.iter().map(|d| outer + d).collect();
        if inner < outer {
            angles.extend([inner - 1e-3, inner + 1e-3, 0.5 * (inner + outer)]);
        }
        for theta in angles {
            for p in spot_ray_points(position, axis, theta) {
                points.push((k, theta - outer, p));
            }
        }
    }
    assert!(points.len() > 40, "{} points", points.len());

    let tracer = PathTracer { max_depth: 1, ..PathTracer::default() };
    let (mut worst_z, mut worst_pick) = (0.0f64, 0.0f32);
    let mut failures = vec![];
    for (j, &(spot, delta, p)) in points.iter().enumerate() {
        // Selection: returned pmf = light_pmf, frequencies = pmf (stratified u: within a few).
        let pmfs: Vec<f32> = (0..nl).map(|i| rs.light_pmf(p, Vec3::Y, i)).collect();
        let sum: f32 = pmfs.iter().sum();
        assert!((sum - 1.0).abs() < 1e-4, "pmfs sum to {sum} at {p}");
        let m = 20000;
        let mut counts = vec![0u32; nl];
        for s in 0..m {
            let u = (s as f32 + 0.5) / m as f32;
            let (i, pmf) = rs.pick_light(p, Vec3::Y, u).expect("a light is picked");
            worst_pick = worst_pick.max((pmf - pmfs[i]).abs() / pmfs[i]);
            assert!((pmf - pmfs[i]).abs() <= 1e-5 * pmfs[i], "pick pmf {pmf} vs light_pmf {} at {p}", pmfs[i]);
            counts[i] += 1;
        }
        for i in 0..nl {
            let expected = pmfs[i] as f64 * m as f64;
            assert!(
                (counts[i] as f64 - expected).abs() <= 2.0 + 1e-3 * expected,
                "light {i} at {p}: {} picks, expected {expected:.1}",
                counts[i]
            );
        }
        // The spot itself is a candidate wherever it lights p.
        let spot_light = spot;
        let inside = delta < 0.0;
        assert!(!inside || pmfs[spot_light] > 0.0, "spot {spot} has pmf 0 inside its cone at {p}");

        // Direct lighting: tree, power selection, analytic.
        let expected = analytic(p);
        let eye = p + Vec3::new(0.25, 0.3, 0.15);
        let mut est = vec![];
        for (selection, spp) in [(LightSelection::Tree, 16384), (LightSelection::Power, 16384)] {
            rs.set_light_selection(selection);
            est.push(plane_estimate_iid(&tracer, &rs, eye, p, j as u32, spp));
        }
        rs.set_light_selection(LightSelection::Tree);
        let ((mt, st), (mp, sp)) = (est[0], est[1]);
        let z_tree = (mt - expected) / st;
        let z_power = (mp - expected) / sp;
        let z_tp = (mt - mp) / (st * st + sp * sp).sqrt();
        worst_z = worst_z.max(z_tree.abs()).max(z_power.abs()).max(z_tp.abs());
        let what = format!(
            "spot {spot}, {:+.0} µrad from the outer edge, p {p}: analytic {expected:.5}, tree {mt:.5} ± {st:.5} \
             (z {z_tree:+.1}), power {mp:.5} ± {sp:.5} (z {z_power:+.1}), tree − power z {z_tp:+.1}",
            delta * 1e6
        );
        if !(z_tree.abs() <= 4.5 && z_power.abs() <= 4.5 && z_tp.abs() <= 4.5) {
            failures.push(what);
        }
    }
    for f in &failures {
        eprintln!("{f}");
    }
    eprintln!(
        "spot cone edges: {} points, worst |z| {worst_z:.2}, worst |pick pmf − light_pmf|/pmf {worst_pick:.1e}",
        points.len()
    );
    assert!(failures.is_empty(), "{} of {} points differ beyond 4.5 standard errors", failures.len(), points.len());
}
