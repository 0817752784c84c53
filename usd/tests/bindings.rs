//! Material binding resolution against pxr: `tests/data/bindings/bindings.usda` covers
//! purpose order, `strongerThanDescendants`, collection bindings (includes/excludes,
//! `explicitOnly`, `includeRoot`, nested collections, dictionary order), malformed bindings,
//! GeomSubsets and native instances (nested too). Each expected material is what usd-core
//! 26.11's `UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial("full")` returns for the
//! prim (instance proxies through `Usd.TraverseInstanceProxies`); `tests/usd/test_bindings.py`
//! computes them again with pxr.

use petzval_usd::load;
use std::path::PathBuf;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/bindings/bindings.usda")
}

/// pxr's bound material per gprim (None: unbound).
const PXR: &[(&str, Option<&str>)] = &[
    ("/PurposeOrder/AllPurposeOnPrim", Some("M1")),
    ("/PurposeOrder/FullOnPrim", Some("M3")),
    ("/PurposeOrder/PreviewOnPrim", Some("M1")),
    ("/PurposeOrder/TwoTargets", Some("M1")),
    ("/PreviewOnly/Geo", None),
    ("/PreviewOnly/PreviewAndAll", Some("M5")),
    ("/Strength/FullBeatsStrongerAll", Some("M2")),
    ("/Strength/StrongerAllBeatsAll", Some("M1")),
    ("/Strength/FullStrong/Inner/OutermostStrongerWins", Some("M4")),
    ("/Coll/In", Some("M2")),
    ("/Coll/Grp/Member", Some("M2")),
    ("/Coll/Grp/Out/Excluded", Some("M1")),
    ("/Coll/Ex", Some("M3")),
    ("/Coll/ExGrp/NotExplicit", Some("M1")),
    ("/Coll/Nested", Some("M4")),
    ("/Coll/Other", Some("M1")),
    ("/Coll/OwnBinding", Some("M5")),
    ("/Root/Yes", Some("M5")),
    ("/Root/No", None),
    ("/Malformed/Geo", None),
    ("/FullColl/Geo", Some("M2")),
    ("/Same/In", Some("M2")),
    ("/Same/Out", Some("M1")),
    ("/Same/Bound", Some("M3")),
    ("/StrongDirect/Geo", Some("M2")),
    ("/StrongColl/Geo", Some("M2")),
    ("/Order/Geo", Some("M1")),
    ("/Subsets/Quads", Some("M1")),
    ("/Subsets/Other", Some("M4")),
    ("/Instances/Picked/Plain", Some("M3")),
    ("/Instances/Picked/Bound", Some("M2")),
    ("/Instances/Picked/Collected", Some("M6")),
    ("/Instances/NotPicked/Plain", Some("M1")),
    ("/Instances/NotPicked/Bound", Some("M2")),
    ("/Instances/NotPicked/Collected", Some("M6")),
    ("/Instances/Whole/Plain", Some("M4")),
    ("/Instances/Whole/Bound", Some("M4")),
    ("/Instances/Whole/Collected", Some("M4")),
    ("/Instances/OwnFull/Plain", Some("M5")),
    ("/Instances/OwnFull/Bound", Some("M5")),
    ("/Instances/OwnFull/Collected", Some("M5")),
    ("/Nested/N1/Holder/Inner/Plain", Some("M3")),
    ("/Nested/N1/Holder/Inner/Bound", Some("M2")),
    ("/Nested/N1/Holder/Inner/Collected", Some("M6")),
    ("/Nested/N2/Holder/Inner/Plain", Some("M5")),
    ("/Nested/N2/Holder/Inner/Bound", Some("M2")),
    ("/Nested/N2/Holder/Inner/Collected", Some("M6")),
    ("/PassOver/Grp/Geo", Some("M2")),
    ("/SubsetInstances/A/Geo", Some("M1")),
    ("/SubsetInstances/B/Geo", Some("M1")),
];

/// The material of every placed gprim is pxr's; an unbound one gets its display colour.
#[test]
fn bound_materials_are_pxrs() {
    let shot = load(&fixture(), None).unwrap();
    let mut seen = Vec::new();
    for (k, path) in shot.info.instance_paths.iter().enumerate() {
        let mesh = &shot.info.meshes[shot.scene.instances[k].mesh as usize];
        let got = mesh.material.as_deref().unwrap();
        let want = PXR.iter().find(|(p, _)| p == path).unwrap_or_else(|| panic!("{path} is not in the table")).1;
        match want {
            Some(m) => assert_eq!(got, format!("/Looks/{m}"), "{path}"),
            None => assert!(got.starts_with("displayColor:"), "{path}: {got}, pxr binds none"),
        }
        seen.push(path.clone());
    }
    assert_eq!(seen.len(), PXR.len(), "every gprim placed once");
}

/// GeomSubsets resolve as prims (their chain runs through the mesh): pxr's `first` M5 (its
/// own binding), `second` M6 (a stronger collection on an ancestor includes it), `third` M1
/// (the mesh's), `Other/sub` M2 (its full binding over the collection binding of the mesh);
/// on the proxies of `SubsetInstances`, `A/Geo/s0` and `B/Geo/s1` M3, the others M1.
#[test]
fn subsets_resolve_as_pxr() {
    let shot = load(&fixture(), None).unwrap();
    let subsets = |prim: &str| shot.info.meshes.iter().find(|m| m.prim == prim).unwrap().subset_materials.clone();
    let pairs = |v: &[(&str, &str)]| v.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect::<Vec<_>>();
    assert_eq!(
        subsets("/Subsets/Quads"),
        pairs(&[("/Subsets/Quads/first", "/Looks/M5"), ("/Subsets/Quads/second", "/Looks/M6")])
    );
    assert_eq!(subsets("/Subsets/Other"), pairs(&[("/Subsets/Other/sub", "/Looks/M2")]));
    // instance proxies: A's s0 and B's s1 are M3 (collections outside name them), so A and B
    // need two meshes though their materials are the same
    let placed = |path: &str| {
        let k = shot.info.instance_paths.iter().position(|p| p == path).unwrap();
        &shot.info.meshes[shot.scene.instances[k].mesh as usize]
    };
    let (a, b) = (placed("/SubsetInstances/A/Geo"), placed("/SubsetInstances/B/Geo"));
    let names = |m: &petzval_usd::MeshInfo| {
        m.subset_materials
            .iter()
            .map(|(s, m)| (s.rsplit('/').next().unwrap().to_string(), m.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(names(a), [("s0".to_string(), "/Looks/M3".to_string())]);
    assert_eq!(names(b), [("s1".to_string(), "/Looks/M3".to_string())]);
    // the faces carry them: 2 triangles per quad, in face order
    let k = shot.info.meshes.iter().position(|m| m.prim == "/Subsets/Quads").unwrap();
    let names: Vec<&str> =
        shot.scene.meshes[k].material_ids.iter().map(|&id| shot.scene.materials[id as usize].name.as_str()).collect();
    assert_eq!(names, ["/Looks/M5", "/Looks/M5", "/Looks/M6", "/Looks/M6", "/Looks/M1", "/Looks/M1"]);
}

/// Malformed bindings are skipped with a warning naming the relationship, as pxr skips them:
/// a direct binding with two targets, a collection binding with one or three targets or two
/// prim targets, and one naming a collection that is not applied.
#[test]
fn malformed_bindings_are_warned_and_ignored() {
    let shot = load(&fixture(), None).unwrap();
    let warned = |needle: &str| shot.scene.warnings.iter().any(|w| w.starts_with(needle) && w.contains("ignored"));
    for rel in [
        "/PurposeOrder/TwoTargets.material:binding:full",
        "/Malformed.material:binding:collection:a",
        "/Malformed.material:binding:collection:b",
        "/Malformed.material:binding:collection:c",
        "/Malformed.material:binding:collection:d",
    ] {
        assert!(warned(rel), "no warning for {rel}: {:?}", shot.scene.warnings);
    }
}

/// Instances whose chains decide the same for their prototype's prims share its meshes; the
/// meshes are built once per (prim, materials): 10 meshes for the 18 proxies of `Src/Asset`.
#[test]
fn instances_share_meshes_by_material() {
    let shot = load(&fixture(), None).unwrap();
    let asset = |p: &str| ["/Plain", "/Bound", "/Collected"].iter().any(|leaf| p.ends_with(leaf));
    let proto: Vec<_> =
        shot.info.meshes.iter().filter(|m| m.prim.starts_with("/__Prototype") && asset(&m.prim)).collect();
    assert_eq!(proto.len(), 10);
    let placed = shot.info.instance_paths.iter().filter(|p| p.starts_with("/Instances") || p.starts_with("/Nested"));
    assert_eq!(placed.count(), 18);
}
