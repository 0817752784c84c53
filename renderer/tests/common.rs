//! Helpers shared by the test modules (scene building).

use glam::{Vec2, Vec3, Vec4};
use petzval_renderer::scene::Mesh;
use std::collections::HashMap;

/// Icosphere (outward counter-clockwise winding, smooth normals).
pub fn icosphere(center: Vec3, radius: f32, level: u32, material: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut v: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        let mut m = |a: u32, b: u32, v: &mut Vec<Vec3>| -> u32 {
            let k = (a.min(b), a.max(b));
            *mid.entry(k).or_insert_with(|| {
                v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                (v.len() - 1) as u32
            })
        };
        for &[a, b, c] in &f {
            let ab = m(a, b, &mut v);
            let bc = m(b, c, &mut v);
            let ca = m(c, a, &mut v);
            nf.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    let n = v.len();
    Mesh {
        positions: v.iter().map(|&p| center + p * radius).collect(),
        normals: v.clone(),
        tangents: vec![Vec4::ZERO; n],
        uv0: vec![Vec2::ZERO; n],
        uv1: vec![],
        colors: vec![],
        material_ids: vec![material; f.len()],
        indices: f,
    }
}

/// Axis-aligned box from `lo` to `hi` (flat faces, outward counter-clockwise winding and
/// normals, four vertices per face).
pub fn box_mesh(lo: Vec3, hi: Vec3, material: u32) -> Mesh {
    let mut m = Mesh::default();
    // each face: an outward normal and two in-face axes (a × b = normal)
    let faces = [(Vec3::X, Vec3::Y, Vec3::Z), (Vec3::Y, Vec3::Z, Vec3::X), (Vec3::Z, Vec3::X, Vec3::Y)];
    let c = 0.5 * (lo + hi);
    let h = 0.5 * (hi - lo);
    for (n, a, b) in faces {
        for s in [1.0f32, -1.0] {
            let n = n * s;
            let (a, b) = if s > 0.0 { (a, b) } else { (b, a) };
            let (ha, hb, hn) = (a * h, b * h, n * h);
            let base = m.positions.len() as u32;
            for (u, v) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                m.positions.push(c + hn + ha * u + hb * v);
                m.normals.push(n);
                m.tangents.push(Vec4::ZERO);
                m.uv0.push(Vec2::new((u + 1.0) * 0.5, (v + 1.0) * 0.5));
            }
            m.indices.push([base, base + 1, base + 2]);
            m.indices.push([base, base + 2, base + 3]);
            m.material_ids.extend([material, material]);
        }
    }
    m
}

/// Standard base64 (with padding), for data URIs in hand-written glTF files.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}
