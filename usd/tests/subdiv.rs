//! Catmull-Clark subdivision surfaces against Blender 5.0's Subdivision modifier (OpenSubdiv):
//! `data/subdiv/subd.usda` is Blender's USD export ("Best Match": the cage with its scheme,
//! boundary rule and creases) of the objects `tests/usd/make_subdiv_fixture.py` builds, and
//! `blender.json` their evaluated meshes (render level 2, limit surface): every face corner's
//! world position and UV.

use glam::{DVec2, DVec3};
use petzval_usd::{load, load_with, LoadOptions};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/subdiv").join(name)
}

/// Our vertices (stage-world position, UV with USD's origin) per Blender object name.
fn ours(level: Option<u32>) -> HashMap<String, Vec<(DVec3, DVec2)>> {
    let shot = match level {
        None => load(&data("subd.usda"), None).unwrap(),
        Some(l) => load_with(&data("subd.usda"), &LoadOptions { subdivision_level: l, ..Default::default() }).unwrap(),
    };
    let mut out = HashMap::new();
    let placed = shot.scene.instances.iter().zip(&shot.info.instance_paths).zip(&shot.info.instance_stage_xf);
    for ((inst, path), xf) in placed {
        let object = path.split('/').nth(2).unwrap().to_string();
        let mesh = &shot.scene.meshes[inst.mesh as usize];
        let v = mesh
            .positions
            .iter()
            .zip(&mesh.uv0)
            .map(|(p, uv)| (xf.transform_point3(p.as_dvec3()), DVec2::new(uv.x as f64, 1.0 - uv.y as f64)))
            .collect();
        out.insert(object, v);
    }
    out
}

/// Blender's face corners per object.
fn blender() -> HashMap<String, Vec<(DVec3, DVec2)>> {
    #[derive(serde::Deserialize)]
    struct Object {
        corners: Vec<[f64; 5]>,
    }
    let v: HashMap<String, Object> =
        serde_json::from_str(&std::fs::read_to_string(data("blender.json")).unwrap()).unwrap();
    v.into_iter()
        .map(|(k, o)| {
            let c = o.corners.into_iter().map(|c| (DVec3::new(c[0], c[1], c[2]), DVec2::new(c[3], c[4])));
            (k, c.collect())
        })
        .collect()
}

/// The largest distance from a point of `a` to the nearest point of `b`.
fn farthest(a: &[(DVec3, DVec2)], b: &[(DVec3, DVec2)]) -> f64 {
    let nearest = |p: DVec3| b.iter().map(|q| p.distance(q.0)).fold(f64::INFINITY, f64::min);
    a.iter().map(|p| nearest(p.0)).fold(0.0, f64::max)
}

/// Level 2 puts the same vertices where Blender's modifier puts them: smooth and extraordinary
/// vertices, triangles and n-gons, infinitely sharp and semi-sharp creases (including one that
/// ends between the last level and the limit), boundaries with and without pinned corners.
/// Two kinds of vertex differ, by up to 0.11 % and 0.4 % of the object's size: a smooth
/// boundary corner (`edgeOnly`) and the end of an infinitely sharp crease (a dart). Ours are
/// the exact limits (a smooth corner's is the boundary B-spline's, `(e₀ + 4v + e₁)/6`); Blender
/// puts these irregular vertices where its third refinement level has them (its Quality 3):
/// a corner moves 21/128 of the way to its neighbours instead of 1/6, and stays there at
/// levels 1, 2 and 3.
#[test]
fn vertices_are_where_blenders_subdivision_modifier_puts_them() {
    let (o, b) = (ours(None), blender());
    assert_eq!(o.len(), b.len());
    for (name, bv) in &b {
        let ov = &o[name.as_str()];
        let d = farthest(ov, bv).max(farthest(bv, ov));
        println!("{name}: vertices within {d:.2e} of Blender's");
        let tol = match name.as_str() {
            "GridEdge" => 2.5e-3,
            "Dart" => 8.1e-3,
            _ => 1e-6,
        };
        assert!(d < tol, "{name}: {d:.3e} from Blender's vertices (tolerance {tol:.0e})");
    }
}

/// Every Blender face corner has a vertex of ours at its position with its UV: the UVs are
/// refined by their own topology with the mesh's `faceVaryingLinearInterpolation` (boundaries,
/// none, all).
#[test]
fn uvs_are_refined_as_blenders() {
    let (o, b) = (ours(None), blender());
    for (name, bv) in &b {
        let ov = &o[name.as_str()];
        let pos_tol = if matches!(name.as_str(), "GridEdge" | "Dart") { 8.1e-3 } else { 1e-6 };
        let mut worst = 0.0f64;
        for (p, uv) in bv {
            let near = ov.iter().filter(|q| q.0.distance(*p) < pos_tol);
            let d = near.map(|q| q.1.distance(*uv)).fold(f64::INFINITY, f64::min);
            worst = worst.max(d);
        }
        println!("{name}: UVs within {worst:.2e} of Blender's");
        // Crease2's UVs are smoothed up to their boundary (`none`), whose corners differ as
        // the vertices of an `edgeOnly` boundary do (see above)
        let tol = if name == "Crease2" { 1e-3 } else { 1e-6 };
        assert!(worst < tol, "{name}: a corner's UV is {worst:.3e} from Blender's (tolerance {tol:.0e})");
    }
}

/// Level 0 renders the cage; each level multiplies a quad mesh's triangles by four.
#[test]
fn the_level_is_an_option() {
    let count = |l: u32| {
        let shot = load_with(&data("subd.usda"), &LoadOptions { subdivision_level: l, ..Default::default() }).unwrap();
        let m = shot.info.meshes.iter().find(|m| m.prim.ends_with("/Cube/Cube")).unwrap().clone();
        (m.triangles, m.subdivision_level)
    };
    assert_eq!(count(0), (12, Some(0)));
    assert_eq!(count(1), (48, Some(1)));
    assert_eq!(count(2), (192, Some(2)));
    assert_eq!(count(3), (768, Some(3)));
}
