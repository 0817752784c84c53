//! UsdGeomBasisCurves: `data/curves/curves.usda` (one prim per type, basis and wrap) and
//! `blender_hair.usda` (Blender 5.0's export of a Curves object: catmullRom, pinned, vertex
//! widths = 2 × Blender's radius), with `expected.json` written by
//! `tests/usd/make_curves_fixture.py`: every centre line evaluated by numpy with pxr's basis
//! matrices (the pinned ends expanded as Hydra does), and Blender's own evaluated strands.

use glam::{DVec3, Vec3};
use openusd::sdf;
use petzval_usd::curves::{centre_lines, spans, Basis, Wrap, FALLBACK_WIDTH, MAX_CURVE_TRIANGLES, MITRE_LIMIT, SIDES};
use petzval_usd::value::Reader;
use petzval_usd::{load, open_stage};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/curves").join(name)
}

#[derive(serde::Deserialize)]
struct Prim {
    curves: Vec<Vec<[f64; 3]>>,
    extent: [[f64; 3]; 2],
}

#[derive(serde::Deserialize)]
struct Blender {
    resolution: usize,
    curves: Vec<Vec<[f64; 3]>>,
}

#[derive(serde::Deserialize)]
struct Expected {
    rings: usize,
    prims: HashMap<String, Prim>,
    blender: Blender,
}

fn expected() -> Expected {
    serde_json::from_str(&std::fs::read_to_string(data("expected.json")).unwrap()).unwrap()
}

/// The largest distance between our centre lines of `prim` and `want` (same point count).
fn worst(file: &str, prim: &str, rings: usize, want: &[Vec<[f64; 3]>]) -> f64 {
    let stage = open_stage(&data(file)).unwrap();
    let reader = Reader { stage: &stage, time: None };
    let p = stage.prim(sdf::path(prim).unwrap());
    let ours = centre_lines(&reader, &p, rings).unwrap();
    assert_eq!(ours.len(), want.len(), "{prim}: curve count");
    let mut worst = 0.0f64;
    for (k, (o, w)) in ours.iter().zip(want).enumerate() {
        assert_eq!(o.len(), w.len(), "{prim} curve {k}: sample count");
        for (a, b) in o.iter().zip(w) {
            worst = worst.max(a.distance(DVec3::from_array(*b)));
        }
    }
    worst
}

#[test]
fn centre_lines_match_pxr_matrices_for_every_basis_and_wrap() {
    let e = expected();
    assert_eq!(e.prims.len(), 12);
    for (prim, want) in &e.prims {
        let d = worst("curves.usda", prim, e.rings, &want.curves);
        assert!(d < 1e-6, "{prim}: centre line {d} from the reference");
    }
    // the bad counts are skipped, not guessed at
    assert!(e.prims["/C/bad_counts"].curves[0].is_empty());
}

#[test]
fn blender_hair_centre_lines_match_blenders_own_evaluation() {
    let e = expected();
    let d = worst("blender_hair.usda", "/root/Hair/Hair", e.blender.resolution, &e.blender.curves);
    // measured 1.9e-7 (Blender's single-precision evaluation); the schema text's phantom point
    // 2·P0 − P1 would put them 0.0185 apart
    assert!(d < 1e-6, "{d}");
}

#[test]
fn span_counts_follow_the_schema() {
    let n = |n, b, w| spans(n, b, w).map(|s| s.controls.len());
    assert_eq!(n(7, Basis::Bezier, Wrap::Nonperiodic), Some(2));
    assert_eq!(n(5, Basis::Bezier, Wrap::Nonperiodic), None);
    assert_eq!(n(6, Basis::Bezier, Wrap::Periodic), Some(2));
    assert_eq!(n(6, Basis::Bspline, Wrap::Nonperiodic), Some(3));
    assert_eq!(n(5, Basis::Bspline, Wrap::Periodic), Some(5));
    assert_eq!(n(6, Basis::CatmullRom, Wrap::Pinned), Some(5));
    assert_eq!(n(5, Basis::Bspline, Wrap::Pinned), Some(6));
    assert_eq!(n(3, Basis::Linear, Wrap::Nonperiodic), Some(2));
    assert_eq!(n(3, Basis::Linear, Wrap::Periodic), Some(3));
    assert_eq!(n(1, Basis::Linear, Wrap::Nonperiodic), None);
    // a varying primvar has one value per authored span end: pinned catmullRom n, bspline n
    assert_eq!(spans(6, Basis::CatmullRom, Wrap::Pinned).unwrap().varying_count, 6);
    let b = spans(5, Basis::Bspline, Wrap::Pinned).unwrap();
    assert_eq!((b.varying_count, b.varying[0], b.varying[1], b.varying[5]), (5, [0, 0], [0, 1], [4, 4]));
}

#[test]
fn tubes_have_the_authored_width_and_lie_in_pxr_extent() {
    let e = expected();
    let shot = load(&data("curves.usda"), None).unwrap();
    for (prim, want) in &e.prims {
        let k = shot.info.meshes.iter().position(|m| &m.prim == prim).unwrap_or_else(|| panic!("{prim} not loaded"));
        let info = &shot.info.meshes[k];
        let c = info.curves.as_ref().unwrap();
        let mesh = &shot.scene.meshes[k];
        if prim == "/C/bad_counts" {
            assert_eq!((c.curves, c.tessellated, c.bad_counts), (2, 1, 1));
            continue;
        }
        assert_eq!(c.tessellated, want.curves.len());
        // every ring vertex is 0.025 (half the width) from the chords to its neighbours' centres
        // (a mitred ring: the tube keeps its radius through bends)
        let centres: Vec<DVec3> = want.curves.iter().flatten().map(|p| DVec3::from_array(*p)).collect();
        assert_eq!(mesh.positions.len(), centres.len() * SIDES, "{prim}");
        let closed = prim.contains("closed");
        let (mut ring, mut sharp) = (0, 0);
        // the turn (cosine) at every ring, and each link's two rings
        let (mut turns, mut links) = (Vec::new(), Vec::new());
        for curve in &want.curves {
            let n = curve.len();
            links.extend((0..if closed { n } else { n - 1 }).map(|i| (ring + i, ring + (i + 1) % n)));
            for i in 0..n {
                let c = DVec3::from_array(curve[i]);
                let next = if i + 1 < n {
                    Some(curve[i + 1])
                } else if closed {
                    Some(curve[0])
                } else {
                    None
                };
                let prev = if i > 0 {
                    Some(curve[i - 1])
                } else if closed {
                    Some(curve[n - 1])
                } else {
                    None
                };
                // a turn sharper than the mitre limit (151°) is not stretched in full
                let turn = match (prev, next) {
                    (Some(a), Some(b)) => {
                        (c - DVec3::from_array(a)).normalize().dot((DVec3::from_array(b) - c).normalize())
                    }
                    _ => 1.0,
                };
                turns.push(turn);
                if turn < -0.87 {
                    sharp += 1;
                    continue;
                }
                for other in [next, prev].into_iter().flatten() {
                    let d = (DVec3::from_array(other) - c).normalize();
                    for p in &mesh.positions[(ring + i) * SIDES..(ring + i + 1) * SIDES] {
                        let o = p.as_dvec3() - c;
                        let r = (o - d * o.dot(d)).length();
                        assert!((r - 0.025).abs() < 1e-5, "{prim}: radius {r} from a chord");
                    }
                }
            }
            ring += n;
        }
        assert!(sharp <= 1, "{prim}: {sharp} rings at turns over 150°");
        // normals point out; the rings' centres (bezier and bspline: inside the control points'
        // hull) inside pxr's extent, every vertex within it grown by the mitre's stretch
        for ((p, n), ring) in mesh.positions.iter().zip(&mesh.normals).zip(centres.iter().flat_map(|c| [c; SIDES])) {
            assert!((p.as_dvec3() - *ring).dot(n.as_dvec3()) > 0.0249, "{prim}: normal not outward");
        }
        if !prim.contains("catmullRom") {
            let lo = Vec3::from_array(want.extent[0].map(|v| v as f32));
            let hi = Vec3::from_array(want.extent[1].map(|v| v as f32));
            let inside = |p: Vec3, grow: f32| p.cmpge(lo - grow).all() && p.cmple(hi + grow).all();
            for ring in mesh.positions.chunks(SIDES) {
                let centre = ring.iter().sum::<Vec3>() / SIDES as f32;
                assert!(inside(centre, 1e-5), "{prim}: a ring's centre {centre} leaves pxr's extent");
            }
            let grow = 0.025 * (MITRE_LIMIT as f32 - 1.0) + 1e-5;
            assert!(mesh.positions.iter().all(|&p| inside(p, grow)), "{prim} leaves pxr's extent");
        }
        // triangles wound outward: each face normal agrees with its first vertex's normal,
        // except beside rings where the sampled centre line turns by more than 90° (cusps of
        // the random control points)
        for (k, t) in mesh.indices.iter().enumerate() {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            if (b - a).cross(c - a).dot(mesh.normals[t[0] as usize]) <= 0.0 {
                let (r0, r1) = links[k / (2 * SIDES)];
                assert!(turns[r0].min(turns[r1]) < 0.0, "{prim}: inward triangle {k} on a gentle bend");
            }
        }
    }
    let warned = shot.scene.warnings.iter().any(|w| w.contains("/C/bad_counts") && w.contains("1 of 2 curves"));
    assert!(warned, "{:?}", shot.scene.warnings);
    assert!(!shot.scene.warnings.iter().any(|w| w.contains("BasisCurves")), "{:?}", shot.scene.warnings);
}

/// A scratch directory removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new() -> TempDir {
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let k = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!("petzval_curves_{}_{k}", std::process::id()));
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn widths_interpolations_fallback_and_colours() {
    let dir = TempDir::new();
    let head = "#usda 1.0\n(\n metersPerUnit = 1\n upAxis = \"Y\"\n)\n";
    let curve = |extra: &str| {
        format!(
            "def BasisCurves \"C\"\n{{\n uniform token type = \"linear\"\n int[] curveVertexCounts = [2, 3]\n \
             point3f[] points = [(0,0,0),(0,1,0),(2,0,0),(2,1,0),(2,2,0)]\n{extra}}}\n"
        )
    };
    let radii = |text: &str| -> Vec<f64> {
        let shot = load(&write(&dir.0, "w.usda", &format!("{head}{}", curve(text))), None).unwrap();
        let m = &shot.scene.meshes[0];
        m.positions.chunks(SIDES).map(|r| (r[0] - r[SIDES / 2]).length() as f64 / 2.0).collect()
    };
    let close = |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
    // no widths: 1 unit wide everywhere
    assert!(close(&radii(""), &[FALLBACK_WIDTH / 2.0; 5]));
    assert!(close(&radii(" float[] widths = [0.2] (interpolation = \"constant\")\n"), &[0.1; 5]));
    assert!(close(&radii(" float[] widths = [0.2, 0.4] (interpolation = \"uniform\")\n"), &[0.1, 0.1, 0.2, 0.2, 0.2]));
    let v = " float[] widths = [0.1, 0.2, 0.3, 0.4, 0.5]\n";
    assert!(close(&radii(v), &[0.05, 0.1, 0.15, 0.2, 0.25]));
    let v = " float[] primvars:widths = [0.1, 0.2, 0.3, 0.4, 0.5] (interpolation = \"varying\")\n";
    assert!(close(&radii(v), &[0.05, 0.1, 0.15, 0.2, 0.25]));
    // too few widths: an error naming the prim and attribute
    let bad = load(&write(&dir.0, "b.usda", &format!("{head}{}", curve(" float[] widths = [0.1, 0.2]\n"))), None);
    let msg = bad.err().unwrap().to_string();
    assert!(msg.contains("/C") && msg.contains("widths") && msg.contains("needs 5"), "{msg}");
    // a width too large for single precision
    let huge = " float[] widths = [1e39] (interpolation = \"constant\")\n";
    let msg = load(&write(&dir.0, "h.usda", &format!("{head}{}", curve(huge))), None).err().unwrap().to_string();
    assert!(msg.contains("/C.widths") && msg.contains("not finite"), "{msg}");
    // points and counts that disagree
    let bad = "def BasisCurves \"C\"\n{\n int[] curveVertexCounts = [4]\n point3f[] points = [(0,0,0)]\n}\n";
    let msg = load(&write(&dir.0, "c.usda", &format!("{head}{bad}")), None).err().unwrap().to_string();
    assert!(msg.contains("/C.curveVertexCounts"), "{msg}");
    // displayColor per curve: vertex colours; one value: the material's colour
    let dc = " color3f[] primvars:displayColor = [(1,0,0),(0,0,1)] (interpolation = \"uniform\")\n";
    let shot = load(&write(&dir.0, "d.usda", &format!("{head}{}", curve(dc))), None).unwrap();
    let m = &shot.scene.meshes[0];
    assert_eq!(m.colors.len(), m.positions.len());
    assert_eq!((m.colors[0].x, m.colors[0].z, m.colors[m.colors.len() - 1].z), (1.0, 0.0, 1.0));
    let dc = " color3f[] primvars:displayColor = [(0.2,0.5,0.1)]\n";
    let shot = load(&write(&dir.0, "e.usda", &format!("{head}{}", curve(dc))), None).unwrap();
    let mat = &shot.scene.materials[shot.scene.meshes[0].material_ids[0] as usize];
    assert!(shot.scene.meshes[0].colors.is_empty());
    assert!((mat.base_color.y - 0.5).abs() < 1e-6 && mat.double_sided);
}

#[test]
fn visibility_purpose_time_samples_and_the_old_warning() {
    let dir = TempDir::new();
    let text = "#usda 1.0\n(\n metersPerUnit = 1\n upAxis = \"Y\"\n)\n\
        def BasisCurves \"Seen\"\n{\n uniform token type = \"linear\"\n int[] curveVertexCounts = [2]\n\
         point3f[] points.timeSamples = {1: [(0,0,0),(0,1,0)], 3: [(0,0,0),(0,3,0)]}\n float[] widths = [0.1] (interpolation = \"constant\")\n}\n\
        def BasisCurves \"Hidden\"\n{\n token visibility = \"invisible\"\n int[] curveVertexCounts = [2]\n point3f[] points = [(0,0,0),(0,1,0)]\n uniform token type = \"linear\"\n}\n\
        def BasisCurves \"Guide\"\n{\n uniform token purpose = \"guide\"\n int[] curveVertexCounts = [2]\n point3f[] points = [(0,0,0),(0,1,0)]\n uniform token type = \"linear\"\n}\n\
        def Points \"P\"\n{\n point3f[] points = [(0,0,0)]\n}\n";
    let p = write(&dir.0, "t.usda", text);
    let shot = load(&p, Some(2.0)).unwrap();
    assert_eq!(shot.info.meshes.iter().map(|m| m.prim.as_str()).collect::<Vec<_>>(), ["/Seen"]);
    let top = shot.scene.meshes[0].positions.iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((top - 2.0).abs() < 1e-5, "points at time 2: top {top}");
    assert!(shot.scene.warnings.iter().any(|w| w.contains("Points are not supported")), "{:?}", shot.scene.warnings);
    assert!(!shot.scene.warnings.iter().any(|w| w.contains("BasisCurves")), "{:?}", shot.scene.warnings);
}

#[test]
fn a_huge_hair_system_is_tessellated_coarser_with_a_warning() {
    // 200 000 catmullRom strands of 6 points: 5 spans × 4 rings × 8 sides × 2 = 320 triangles
    // each (64 M) at the default; the limit needs the coarsest levels
    let n = 200_000usize;
    let mut pts = String::with_capacity(n * 6 * 20);
    for i in 0..n {
        for j in 0..6 {
            pts.push_str(&format!("({},{},0),", i % 1000, j));
        }
    }
    let text = format!(
        "#usda 1.0\ndef BasisCurves \"Fur\"\n{{\n uniform token basis = \"catmullRom\"\n uniform token wrap = \"pinned\"\n\
         int[] curveVertexCounts = [{}]\n point3f[] points = [{}]\n float[] widths = [0.01] (interpolation = \"constant\")\n}}\n",
        vec!["6"; n].join(","),
        pts.trim_end_matches(',')
    );
    let dir = TempDir::new();
    let shot = load(&write(&dir.0, "fur.usda", &text), None).unwrap();
    let c = shot.info.meshes[0].curves.clone().unwrap();
    let tris = shot.scene.meshes[0].triangle_count();
    assert!(tris <= MAX_CURVE_TRIANGLES, "{tris}");
    // 1 ring per span and 4 sides: 40 triangles a strand, 8 M in all
    assert_eq!((c.rings_per_span, c.sides, c.tessellated, c.over_limit, tris), (1, 4, n, 0, 8_000_000));
    assert!(shot.scene.warnings.iter().any(|w| w.contains("/Fur") && w.contains("1 rings per span and 4 sides")));
}

#[test]
fn blender_hair_tubes_are_wound_outward_and_as_wide_as_blenders_radius() {
    let shot = load(&data("blender_hair.usda"), None).unwrap();
    let m = &shot.scene.meshes[0];
    let c = shot.info.meshes[0].curves.clone().unwrap();
    assert_eq!(
        (c.basis.as_str(), c.wrap.as_str(), c.tessellated, c.widths_authored),
        ("catmullRom", "pinned", 3, true)
    );
    for t in &m.indices {
        let [a, b, cc] = t.map(|i| m.positions[i as usize]);
        assert!((b - a).cross(cc - a).dot(m.normals[t[0] as usize]) > 0.0);
    }
    // the first ring of each strand: Blender's radius 0.01 at the root (widths 0.02)
    let r = (m.positions[0] - m.positions[SIDES / 2]).length() / 2.0;
    assert!((r - 0.01).abs() < 1e-6, "{r}");
}
