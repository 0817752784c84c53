//! The built-in demo: a miniature street on a table top at dusk, with rows of small lamps
//! receding into the distance, seen through `double-gauss-50mm` wide open with a tilted sensor.
//! Out-of-focus lamps show the aperture's blades (and cat's eyes towards the corners), the
//! tilted plane of focus cuts a sharp band through the street (the "miniature" look), and the
//! corners show the lens's vignetting. Built in code: no files needed.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | lens | library name | — | `double-gauss-50mm` |
//! | f-number | f64 | — | 2.1 (wide open is f/2.03) |
//! | focus distance | f64 | m | 0.55 |
//! | sensor tilt x | f64 | degrees | −6 |
//! | aperture | blades | — | 7 blades, 10° |

use super::{Environment, Light, Material, Mesh, Scene, SceneCamera, Texture, TextureRef};
use crate::scene::texture::Wrap;
use glam::{Affine3A, Vec2, Vec3, Vec4};
use std::sync::Arc;

/// How the demo wants to be photographed.
#[derive(Debug, Clone)]
pub struct DemoShot {
    /// Library lens.
    pub lens: &'static str,
    /// f-number.
    pub f_number: f64,
    /// Focus distance from the entrance pupil (m).
    pub focus_distance_m: f64,
    /// Sensor tilt about x (degrees).
    pub tilt_x_deg: f64,
    /// Aperture blades.
    pub blades: u32,
    /// Blade rotation (degrees).
    pub blade_rotation_deg: f64,
}

/// Adds a box (axis-aligned before `xf`).
fn add_box(mesh: &mut Mesh, xf: Affine3A, size: Vec3, material: u32) {
    let h = size * 0.5;
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    for (n, u, v) in faces {
        let c = n * h;
        let (du, dv) = (u * (u.abs().dot(h)), v * (v.abs().dot(h)));
        let corners = [c - du - dv, c + du - dv, c + du + dv, c - du + dv];
        add_quad(
            mesh,
            xf,
            corners,
            [Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)],
            material,
        );
    }
}

/// Adds a quad (counter-clockwise seen from the front).
fn add_quad(mesh: &mut Mesh, xf: Affine3A, corners: [Vec3; 4], uvs: [Vec2; 4], material: u32) {
    let base = mesh.positions.len() as u32;
    let p: Vec<Vec3> = corners.iter().map(|c| xf.transform_point3(*c)).collect();
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
    let t = (p[1] - p[0]).normalize();
    for k in 0..4 {
        mesh.positions.push(p[k]);
        mesh.normals.push(n);
        mesh.tangents.push(t.extend(1.0));
        mesh.uv0.push(uvs[k]);
    }
    mesh.indices.push([base, base + 1, base + 2]);
    mesh.indices.push([base, base + 2, base + 3]);
    mesh.material_ids.extend([material, material]);
}

/// Adds a UV sphere.
fn add_sphere(mesh: &mut Mesh, centre: Vec3, radius: f32, material: u32, rings: u32, segments: u32) {
    let base = mesh.positions.len() as u32;
    for i in 0..=rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let phi = std::f32::consts::TAU * j as f32 / segments as f32;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            mesh.positions.push(centre + n * radius);
            mesh.normals.push(n);
            mesh.tangents.push(Vec4::new(-phi.sin(), 0.0, phi.cos(), 1.0));
            mesh.uv0.push(Vec2::new(j as f32 / segments as f32, i as f32 / rings as f32));
        }
    }
    let row = segments + 1;
    for i in 0..rings {
        for j in 0..segments {
            let a = base + i * row + j;
            let b = a + row;
            if i > 0 {
                mesh.indices.push([a, a + 1, b]);
                mesh.material_ids.push(material);
            }
            if i + 1 < rings {
                mesh.indices.push([a + 1, b + 1, b]);
                mesh.material_ids.push(material);
            }
        }
    }
}

fn diffuse(name: &str, rgb: Vec3, roughness: f32) -> Material {
    Material { name: name.into(), base_color: rgb.extend(1.0), metallic: 0.0, roughness, ..Material::default() }
}

/// A small deterministic hash for the demo's variety.
fn rand01(i: u32) -> f32 {
    (crate::sampler::hash_u32(i.wrapping_mul(0x27d4_eb2d)) >> 8) as f32 / (1u32 << 24) as f32
}

/// Builds the demo scene and the shot it is meant for.
pub fn demo_scene() -> (Scene, DemoShot) {
    let mut scene = Scene::default();
    // 1. Materials: wooden table (checker texture), street, houses, lamps.
    let checker = {
        let n = 256u32;
        let mut texels = Vec::with_capacity((n * n) as usize);
        for y in 0..n {
            for x in 0..n {
                let board = ((x / 32) + (y / 32)) % 2 == 0;
                let grain = 0.85 + 0.15 * (((x as f32) * 0.31 + (y as f32 * 0.05).sin() * 4.0).sin() * 0.5 + 0.5);
                let c = if board { Vec3::new(0.42, 0.25, 0.12) } else { Vec3::new(0.30, 0.17, 0.08) } * grain;
                texels.push(c.extend(1.0));
            }
        }
        Texture {
            name: "table".into(),
            width: n,
            height: n,
            texels,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            bilinear: true,
            srgb_encoded: false,
        }
    };
    scene.textures.push(Arc::new(checker));
    let mut table = diffuse("table", Vec3::ONE, 0.6);
    table.base_color_texture = Some(TextureRef { index: 0, uv_set: 0, transform: None });
    scene.materials.push(table); // 0
    scene.materials.push(diffuse("street", Vec3::new(0.08, 0.08, 0.09), 0.9)); // 1
    let house_colours = [
        Vec3::new(0.7, 0.62, 0.5),
        Vec3::new(0.55, 0.2, 0.15),
        Vec3::new(0.8, 0.78, 0.7),
        Vec3::new(0.3, 0.4, 0.55),
        Vec3::new(0.6, 0.5, 0.25),
    ];
    for (i, c) in house_colours.iter().enumerate() {
        scene.materials.push(diffuse(&format!("house{i}"), *c, 0.8)); // 2..=6
    }
    let warm = Material {
        name: "lamp-warm".into(),
        emissive: Vec3::new(60.0, 38.0, 16.0),
        base_color: Vec4::new(1.0, 0.9, 0.7, 1.0),
        metallic: 0.0,
        ..Material::default()
    };
    let cool = Material {
        name: "lamp-cool".into(),
        emissive: Vec3::new(25.0, 35.0, 60.0),
        base_color: Vec4::new(0.8, 0.9, 1.0, 1.0),
        metallic: 0.0,
        ..Material::default()
    };
    scene.materials.push(warm); // 7
    scene.materials.push(cool); // 8
    scene.materials.push(diffuse("post", Vec3::new(0.05, 0.05, 0.05), 0.4)); // 9
    let window = Material {
        name: "window".into(),
        emissive: Vec3::new(4.0, 2.6, 1.0),
        base_color: Vec4::new(0.9, 0.8, 0.6, 1.0),
        metallic: 0.0,
        ..Material::default()
    };
    scene.materials.push(window); // 10
    let mut world = Mesh::default();
    let mesh = &mut world;
    // 2. Table top (y = 0) and the street running away from the camera along −z.
    add_quad(
        mesh,
        Affine3A::IDENTITY,
        [Vec3::new(-2.0, 0.0, 1.0), Vec3::new(2.0, 0.0, 1.0), Vec3::new(2.0, 0.0, -4.0), Vec3::new(-2.0, 0.0, -4.0)],
        [Vec2::new(0.0, 10.0), Vec2::new(8.0, 10.0), Vec2::new(8.0, 0.0), Vec2::new(0.0, 0.0)],
        0,
    );
    add_quad(
        mesh,
        Affine3A::IDENTITY,
        [
            Vec3::new(-0.06, 0.001, 0.4),
            Vec3::new(0.06, 0.001, 0.4),
            Vec3::new(0.06, 0.001, -3.0),
            Vec3::new(-0.06, 0.001, -3.0),
        ],
        [Vec2::ZERO; 4],
        1,
    );
    // 3. Houses on both sides.
    let mut k = 0u32;
    for side in [-1.0f32, 1.0] {
        let mut z = 0.25f32;
        while z > -3.0 {
            k += 1;
            let w = 0.05 + 0.05 * rand01(k);
            let d = 0.05 + 0.04 * rand01(k + 100);
            let h = 0.04 + 0.10 * rand01(k + 200);
            let x = side * (0.11 + d * 0.5 + 0.02 * rand01(k + 300));
            let m = 2 + (k % 5);
            add_box(mesh, Affine3A::from_translation(Vec3::new(x, h * 0.5, z - w * 0.5)), Vec3::new(d, h, w), m);
            // a lit window facing the street
            if rand01(k + 400) > 0.35 {
                let wx = x - side * (d * 0.5 + 0.0005);
                let wy = h * 0.55;
                let s = 0.008;
                let zc = z - w * 0.5;
                let corners = if side < 0.0 {
                    [
                        Vec3::new(wx, wy - s, zc + s),
                        Vec3::new(wx, wy - s, zc - s),
                        Vec3::new(wx, wy + s, zc - s),
                        Vec3::new(wx, wy + s, zc + s),
                    ]
                } else {
                    [
                        Vec3::new(wx, wy - s, zc - s),
                        Vec3::new(wx, wy - s, zc + s),
                        Vec3::new(wx, wy + s, zc + s),
                        Vec3::new(wx, wy + s, zc - s),
                    ]
                };
                add_quad(mesh, Affine3A::IDENTITY, corners, [Vec2::ZERO; 4], 10);
            }
            z -= w + 0.01 + 0.02 * rand01(k + 500);
        }
    }
    // 4. Rows of small lamps on posts along the street, and a string of lights across it.
    let mut i = 0;
    let mut z = 0.2f32;
    while z > -3.0 {
        for side in [-1.0f32, 1.0] {
            let x = side * 0.085;
            add_box(mesh, Affine3A::from_translation(Vec3::new(x, 0.025, z)), Vec3::new(0.003, 0.05, 0.003), 9);
            add_sphere(mesh, Vec3::new(x, 0.053, z), 0.0035, 7 + (i % 2), 8, 12);
        }
        i += 1;
        z -= 0.12;
    }
    for j in 0..24 {
        let x = -0.3 + 0.6 * j as f32 / 23.0;
        let y = 0.16 - 0.04 * (1.0 - (x / 0.3).powi(2));
        add_sphere(mesh, Vec3::new(x, y, -1.2), 0.003, 7 + (j % 2), 6, 10);
    }
    // 5. Dusk sky and a dim moon.
    scene.add_world_mesh(world);
    scene.environment = Environment::Constant(Vec3::new(0.035, 0.045, 0.08));
    scene.lights.push(Light::Directional {
        direction: Vec3::new(0.3, -1.0, -0.4).normalize(),
        irradiance: Vec3::new(0.25, 0.27, 0.35),
        angle_rad: 0.0,
    });
    // 6. The camera: low over the table, looking down the street.
    let eye = Vec3::new(0.0, 0.09, 0.55);
    let target = Vec3::new(0.0, 0.02, -0.4);
    let view = glam::camera::rh::view::look_at_affine3a(eye, target, Vec3::Y);
    scene.cameras.push(SceneCamera {
        name: "demo".into(),
        to_world: view.inverse(),
        yfov_rad: 0.45,
        aspect_ratio: Some(1.5),
        ortho_scale_m: None,
        znear: 0.01,
        zfar: None,
    });
    (scene, demo_shot())
}

/// How the demo wants to be photographed, without building it (the command line checks its
/// flags against these before loading anything).
pub fn demo_shot() -> DemoShot {
    DemoShot {
        lens: "double-gauss-50mm",
        f_number: 2.1,
        focus_distance_m: 0.55,
        tilt_x_deg: -6.0,
        blades: 7,
        blade_rotation_deg: 10.0,
    }
}
