//! Meshes and instances: the two-level BVH against the flattened scene, mirrored, rotated and
//! non-uniformly scaled instances against analytic hits, shadow rays, and glTF shared meshes.

use crate::common::{base64, icosphere};
use glam::{Affine3A, Mat3, Quat, Vec2, Vec3, Vec4};
use petzval_renderer::integrator::{PathTracer, RenderScene};
use petzval_renderer::sampler::PixelSampler;
use petzval_renderer::scene::gltf::load_gltf_slice;
use petzval_renderer::scene::{AlphaMode, Environment, Material, Mesh, Scene};

fn diffuse(c: Vec3) -> Material {
    Material { base_color: c.extend(1.0), metallic: 0.0, roughness: 0.6, ..Material::default() }
}

/// Unit quad in the xy plane (z = 0, front +z), vertex normals `n`.
fn quad(n: Vec3, material: u32) -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(-0.5, -0.5, 0.0),
            Vec3::new(0.5, -0.5, 0.0),
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(-0.5, 0.5, 0.0),
        ],
        normals: vec![n; 4],
        tangents: vec![Vec4::ZERO; 4],
        uv0: vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y],
        uv1: vec![],
        colors: vec![],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material_ids: vec![material; 2],
    }
}

/// A sphere placed four times (plain, rotated + non-uniformly scaled, mirrored, sheared), a
/// ground quad placed once and an emissive quad placed twice (once mirrored).
fn instanced_scene() -> Scene {
    let mut s = Scene {
        materials: vec![
            diffuse(Vec3::new(0.8, 0.3, 0.2)),
            diffuse(Vec3::splat(0.5)),
            Material { emissive: Vec3::splat(4.0), ..diffuse(Vec3::ZERO) },
        ],
        environment: Environment::Constant(Vec3::splat(0.2)),
        ..Scene::default()
    };
    let sphere = s.add_mesh(icosphere(Vec3::ZERO, 0.5, 2, 0));
    let ground = s.add_mesh(quad(Vec3::Z, 1));
    let lamp = s.add_mesh(quad(Vec3::Z, 2));
    s.add_instance(sphere, Affine3A::from_translation(Vec3::new(-1.5, 0.5, 0.0)));
    s.add_instance(
        sphere,
        Affine3A::from_scale_rotation_translation(
            Vec3::new(1.6, 0.7, 1.1),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, 0.9, -0.4),
            Vec3::new(0.0, 0.45, 0.2),
        ),
    );
    s.add_instance(
        sphere,
        Affine3A::from_scale_rotation_translation(Vec3::new(-1.0, 1.0, 1.0), Quat::IDENTITY, Vec3::new(1.5, 0.5, 0.0)),
    );
    let shear = Mat3::from_cols(Vec3::X, Vec3::new(0.4, 1.0, 0.0), Vec3::new(0.0, 0.2, 0.8));
    s.add_instance(sphere, Affine3A::from_mat3_translation(shear, Vec3::new(0.0, 0.5, -1.5)));
    s.add_instance(
        ground,
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(8.0),
            Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
            Vec3::ZERO,
        ),
    );
    let down = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
    s.add_instance(
        lamp,
        Affine3A::from_scale_rotation_translation(Vec3::new(1.0, 0.5, 1.0), down, Vec3::new(-0.8, 2.5, 0.0)),
    );
    s.add_instance(
        lamp,
        Affine3A::from_scale_rotation_translation(Vec3::new(-1.0, 0.5, 1.0), down, Vec3::new(0.8, 2.5, 0.0)),
    );
    s
}

fn flattened(s: &Scene) -> Scene {
    let mut f = s.clone();
    f.flatten();
    f
}

/// Camera rays over the scene from the front, 64 × 48.
fn camera_rays() -> Vec<(Vec3, Vec3)> {
    let eye = Vec3::new(0.3, 2.2, 5.0);
    let mut rays = Vec::new();
    for j in 0..48 {
        for i in 0..64 {
            let x = (i as f32 + 0.5) / 64.0 * 2.0 - 1.0;
            let y = (j as f32 + 0.5) / 48.0 * 2.0 - 1.0;
            let target = Vec3::new(x * 3.0, 0.6 - y * 1.8, 0.0);
            rays.push((eye, (target - eye).normalize()));
        }
    }
    rays
}

#[test]
fn instances_use_the_top_level_and_single_placements_are_baked() {
    let rs = RenderScene::new(instanced_scene()).unwrap();
    // 4 spheres + 2 lamps through the TLAS; the ground (placed once) is baked.
    assert_eq!(rs.tlas_instance_count(), 6);
    let m = rs.memory();
    assert!(m.blas_bytes > 0 && m.tlas_bytes > 0 && m.world_bvh_bytes > 0, "{m:?}");
    let flat = RenderScene::new(flattened(&instanced_scene())).unwrap();
    assert_eq!(flat.tlas_instance_count(), 0);
    assert_eq!(rs.triangle_count(), flat.triangle_count());
    assert_eq!(rs.light_count(), flat.light_count());
}

#[test]
fn instanced_hits_match_the_flattened_scene() {
    let inst = RenderScene::new(instanced_scene()).unwrap();
    let flat = RenderScene::new(flattened(&instanced_scene())).unwrap();
    let (mut both, mut differ) = (0, 0);
    for (o, d) in camera_rays() {
        match (inst.intersect(o, d, f32::INFINITY), flat.intersect(o, d, f32::INFINITY)) {
            (Some(a), Some(b)) => {
                both += 1;
                if (a.t - b.t).abs() > 1e-4 * a.t.max(1.0) {
                    differ += 1; // a silhouette ray grazing an edge
                    continue;
                }
                assert!((a.position - b.position).length() < 1e-4, "{} vs {}", a.position, b.position);
                assert!(a.geometric_normal.dot(b.geometric_normal) > 0.9999, "{a:?}\n{b:?}");
                assert!(a.shading_normal.dot(b.shading_normal) > 0.999, "{a:?}\n{b:?}");
                assert_eq!((a.material_id, a.front_face), (b.material_id, b.front_face));
                assert!((a.uv0 - b.uv0).length() < 1e-4);
                assert_eq!(inst.emission(&a, d), flat.emission(&b, d));
            }
            (None, None) => {}
            _ => differ += 1,
        }
    }
    assert!(both > 1500, "{both} hits");
    assert!(differ <= 6, "{differ} rays disagree");
}

#[test]
fn instanced_render_matches_the_flattened_scene() {
    let inst = RenderScene::new(instanced_scene()).unwrap();
    let flat = RenderScene::new(flattened(&instanced_scene())).unwrap();
    let tracer = PathTracer::default();
    let (mut a, mut b) = (Vec3::ZERO, Vec3::ZERO);
    for (k, (o, d)) in camera_rays().into_iter().enumerate().step_by(7) {
        for s in 0..16 {
            let sampler = || {
                let mut sp = PixelSampler::new(k as u32, 7, s, 1);
                sp.next_2d();
                sp.next_2d();
                sp.next_1d();
                sp
            };
            a += tracer.trace(&inst, o, d, &mut sampler()).radiance;
            b += tracer.trace(&flat, o, d, &mut sampler()).radiance;
        }
    }
    let rel = (a - b).abs().max_element() / b.max_element();
    assert!(rel < 0.01, "instanced {a} vs flattened {b}");
}

/// A scene with `quad(n)` placed by `xf`, plus (when `tlas`) a far copy so the mesh is instanced.
fn one_quad(n: Vec3, xf: Affine3A, tlas: bool) -> RenderScene {
    let mut s = Scene { materials: vec![diffuse(Vec3::ONE)], ..Scene::default() };
    let q = s.add_mesh(quad(n, 0));
    s.add_instance(q, xf);
    if tlas {
        s.add_instance(q, Affine3A::from_translation(Vec3::new(100.0, 0.0, 0.0)));
    }
    let rs = RenderScene::new(s).unwrap();
    assert_eq!(rs.tlas_instance_count(), if tlas { 2 } else { 0 });
    rs
}

#[test]
fn rotated_non_uniformly_scaled_instance_hits_and_normals_are_analytic() {
    let rot = Quat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 0.25);
    let scale = Vec3::new(3.0, 0.5, 2.0);
    let t = Vec3::new(0.2, -0.1, -4.0);
    let xf = Affine3A::from_scale_rotation_translation(scale, rot, t);
    // Vertex normals tilted off the face: only the inverse transpose gets them right.
    let n_obj = Vec3::new(0.6, 0.0, 0.8);
    let lin = Mat3::from(xf.matrix3);
    let n_geo = (lin.inverse().transpose() * Vec3::Z).normalize();
    let n_shade = (lin.inverse().transpose() * n_obj).normalize();
    for tlas in [false, true] {
        let rs = one_quad(n_obj, xf, tlas);
        for (u, v) in [(0.1, 0.2), (-0.3, 0.35), (0.4, -0.4)] {
            let target = xf.transform_point3(Vec3::new(u, v, 0.0));
            let o = Vec3::new(0.5, 1.0, 3.0);
            let d = (target - o).normalize();
            let hit = rs.intersect(o, d, f32::INFINITY).expect("hits the quad");
            assert!((hit.t - (target - o).length()).abs() < 1e-4, "t {} vs {}", hit.t, (target - o).length());
            assert!((hit.position - target).length() < 1e-4);
            let ng = if hit.geometric_normal.dot(n_geo) > 0.0 { n_geo } else { -n_geo };
            assert!(hit.geometric_normal.dot(ng) > 0.99999, "{} vs {ng}", hit.geometric_normal);
            assert!(hit.geometric_normal.dot(n_geo) > 0.0, "front side follows the transformed normal");
            assert!(hit.shading_normal.dot(n_shade) > 0.99999, "{} vs {n_shade}", hit.shading_normal);
            assert_eq!(hit.front_face, d.dot(n_geo) < 0.0);
        }
    }
}

#[test]
fn negative_scale_instance_keeps_its_front_side_outward() {
    let xf =
        Affine3A::from_scale_rotation_translation(Vec3::new(-2.0, 1.0, 1.0), Quat::IDENTITY, Vec3::new(0.0, 0.0, -3.0));
    for tlas in [false, true] {
        let rs = one_quad(Vec3::Z, xf, tlas);
        // Mirroring x keeps the +z face normal: a ray from +z sees the front.
        let hit = rs.intersect(Vec3::new(0.3, 0.1, 0.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
        assert!((hit.t - 3.0).abs() < 1e-5);
        assert!(hit.front_face, "tlas {tlas}: {hit:?}");
        assert!(hit.geometric_normal.dot(Vec3::Z) > 0.9999);
        assert!(hit.shading_normal.dot(Vec3::Z) > 0.9999);
    }
    // A mirrored sphere: normals point away from the centre, rays from outside hit the front.
    let mut s = Scene { materials: vec![diffuse(Vec3::ONE)], ..Scene::default() };
    let sphere = s.add_mesh(icosphere(Vec3::ZERO, 1.0, 3, 0));
    let c = [Vec3::new(0.0, 0.0, -5.0), Vec3::new(3.0, 0.0, -5.0)];
    for p in c {
        s.add_instance(sphere, Affine3A::from_scale_rotation_translation(Vec3::new(1.0, -1.0, 1.0), Quat::IDENTITY, p));
    }
    let rs = RenderScene::new(s).unwrap();
    for p in c {
        for d in [Vec3::new(0.05, 0.1, -1.0), Vec3::new(-0.08, -0.05, -1.0)] {
            let h = rs.intersect(Vec3::new(p.x, 0.0, 0.0), d, f32::INFINITY).unwrap();
            let out = (h.position - p).normalize();
            assert!(h.front_face, "{h:?}");
            assert!(h.geometric_normal.dot(out) > 0.99, "{h:?}");
            assert!(h.shading_normal.dot(out) > 0.99, "{h:?}");
        }
    }
}

#[test]
fn shadow_rays_through_instances() {
    // Two opaque quads (instanced) facing up at y = 1 and a cut-out one (alpha 0, masked).
    let mut s = Scene {
        materials: vec![
            diffuse(Vec3::ONE),
            Material {
                base_color: Vec4::new(1.0, 1.0, 1.0, 0.0),
                alpha_mode: AlphaMode::Mask(0.5),
                ..diffuse(Vec3::ONE)
            },
        ],
        ..Scene::default()
    };
    let opaque = s.add_mesh(quad(Vec3::Z, 0));
    let cut = s.add_mesh(quad(Vec3::Z, 1));
    let up = Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2);
    for x in [-2.0, 0.0] {
        s.add_instance(opaque, Affine3A::from_rotation_translation(up, Vec3::new(x, 1.0, 0.0)));
    }
    for x in [2.0, 4.0] {
        s.add_instance(cut, Affine3A::from_rotation_translation(up, Vec3::new(x, 1.0, 0.0)));
    }
    let rs = RenderScene::new(s).unwrap();
    assert_eq!(rs.tlas_instance_count(), 4);
    let from = |x: f32| Vec3::new(x, 0.0, 0.1);
    // Toward a light at y = 2 straight above: blocked by the opaque quads only.
    assert!(rs.occluded(from(-2.0), Vec3::Y * 2.0, 1.0));
    assert!(rs.occluded(from(0.1), Vec3::Y * 2.0, 1.0));
    assert!(!rs.occluded(from(1.0), Vec3::Y * 2.0, 1.0), "between the quads");
    assert!(!rs.occluded(from(2.0), Vec3::Y * 2.0, 1.0), "through the cut-out");
    assert!(!rs.occluded(from(4.1), Vec3::Y * 2.0, 1.0), "through the cut-out");
    // Shorter than the distance to the quad: not blocked.
    assert!(!rs.occluded(from(0.0), Vec3::Y * 0.9, 1.0));
    // Consistent with closest hits.
    for x in [-2.0, -1.0, 0.0, 1.0, 2.0, 4.0] {
        assert_eq!(rs.occluded(from(x), Vec3::Y, 10.0), rs.intersect(from(x), Vec3::Y, 10.0).is_some(), "x {x}");
    }
    // Emissive instanced quads are lights; a degenerate (zero-scale) instance is skipped.
    let mut s = instanced_scene();
    let lamp = s.instances[5].mesh;
    s.add_instance(lamp, Affine3A::from_scale(Vec3::ZERO));
    let rs = RenderScene::new(s).unwrap();
    assert!(rs.scene().warnings.iter().any(|w| w.contains("singular")), "{:?}", rs.scene().warnings);
    let area_sample =
        |k: u32| rs.sample_light_at(Vec3::new(-0.8, 0.5, 0.0), Vec3::Y, (k as f32 + 0.5) / 32.0, Vec2::new(0.4, 0.6));
    assert!((0..32)
        .any(|k| area_sample(k).is_some_and(|l| l.target.is_some() && l.pdf > 0.0 && l.radiance.max_element() > 0.0)));
}

#[test]
fn gltf_shared_mesh_is_one_mesh_and_several_instances() {
    let p: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = p.iter().flat_map(|v| v.to_le_bytes()).collect();
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1,3]}}],
        "nodes":[{{"mesh":0,"translation":[1,0,0]}},{{"mesh":0,"scale":[-1,1,1],"children":[2]}},
                 {{"mesh":0,"translation":[0,0,-2]}},{{"mesh":1}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}},{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3"}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{}"}}]}}"#,
        base64(&bytes)
    );
    let s = load_gltf_slice(json.as_bytes(), None, "shared.gltf").unwrap();
    assert_eq!(s.meshes.len(), 2, "glTF mesh 0 read once");
    assert_eq!(s.instances.len(), 4);
    assert_eq!(s.instances.iter().filter(|i| i.mesh == s.instances[0].mesh).count(), 3);
    assert_eq!(s.meshes[s.instances[0].mesh as usize].triangle_count(), 1);
    // Node 2 inherits node 1's mirror: its vertex (1, 0, 0) lands at (−1, 0, −2).
    let flat = s.flattened_mesh();
    assert_eq!(flat.triangle_count(), 4);
    assert!(flat.positions.iter().any(|q| (*q - Vec3::new(-1.0, 0.0, -2.0)).length() < 1e-6));
    let rs = RenderScene::new(s).unwrap();
    assert_eq!(rs.tlas_instance_count(), 3);
    let hit = rs.intersect(Vec3::new(-0.2, 0.2, 1.0), Vec3::NEG_Z, f32::INFINITY).unwrap();
    assert!((hit.t - 1.0).abs() < 1e-5);
    assert!(hit.front_face, "the mirrored node keeps its front side (+z)");
}

/// A mesh placed once by a transform is shaded from world-space positions and normals computed
/// once: every hit record is the one computed at the hit, as for the same mesh placed twice
/// (which is not baked), bit for bit, for translated, rotated and scaled, mirrored and sheared
/// placements; the scene counts those attributes' bytes.
#[test]
fn baked_world_attributes_give_the_same_hit_records() {
    let placements = [
        Affine3A::from_translation(Vec3::new(0.3, -1.2, 4.0)),
        Affine3A::from_scale_rotation_translation(
            Vec3::new(1.6, 0.7, 1.1),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, 0.9, -0.4),
            Vec3::new(0.0, 0.45, 0.2),
        ),
        Affine3A::from_scale_rotation_translation(Vec3::new(-1.0, 1.0, 1.0), Quat::IDENTITY, Vec3::new(1.5, 0.5, 0.0)),
        Affine3A::from_mat3_translation(
            Mat3::from_cols(Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.6, 1.0, 0.0), Vec3::new(0.0, -0.3, 0.8)),
            Vec3::new(-2.0, 0.1, 0.7),
        ),
    ];
    for (p, &xf) in placements.iter().enumerate() {
        let scene_with = |copies: usize| {
            let mut s = Scene { materials: vec![diffuse(Vec3::splat(0.5))], ..Scene::default() };
            let sphere = s.add_mesh(icosphere(Vec3::ZERO, 0.5, 2, 0));
            for c in 0..copies {
                s.add_instance(sphere, Affine3A::from_translation(Vec3::X * 10.0 * c as f32) * xf);
            }
            RenderScene::new(s).unwrap()
        };
        let (once, twice) = (scene_with(1), scene_with(2));
        let (m1, m2) = (once.memory(), twice.memory());
        let vertices = once.scene().meshes[0].positions.len();
        assert_eq!(m1.world_attribute_bytes, vertices * 2 * std::mem::size_of::<Vec3>(), "placement {p}");
        assert_eq!(m2.world_attribute_bytes, 0, "placement {p}");
        let dir = Vec3::new(0.3, -0.5, -0.8).normalize();
        for tri in 0..once.scene().meshes[0].indices.len() as u32 {
            for (b1, b2) in [(0.2, 0.3), (0.0, 0.0), (1.0 / 3.0, 1.0 / 3.0), (0.7, 0.29), (0.0, 1.0)] {
                let (a, b) = (once.surface_hit(0, tri, b1, b2, 1.5, dir), twice.surface_hit(0, tri, b1, b2, 1.5, dir));
                assert_eq!(format!("{a:?}"), format!("{b:?}"), "placement {p}, triangle {tri} at ({b1}, {b2})");
            }
        }
    }
}
