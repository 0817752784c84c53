//! What pxr traverses and resolves, on small usda stages written here: prim specifiers,
//! material bindings on native instances, point-instancer orientations, typeless prims. Each
//! test's expected values are usd-core's (26.11) on the same text.

use glam::DVec3;
use petzval_usd::load;
use std::path::PathBuf;

fn write(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("petzval-usd-traversal-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn sorted(mut v: Vec<String>) -> Vec<String> {
    v.sort();
    v
}

/// `class` (abstract) and `over` (undefined) prims and everything beneath them are not scene
/// content, as `Usd.PrimDefaultPredicate` traverses, yet they stay composition sources:
/// inherits, internal references, native prototypes and point-instancer prototypes read
/// through them. An `over` in a stronger sublayer over a `def` stays defined. pxr's
/// `Usd.PrimRange(root, Usd.TraverseInstanceProxies())` on this stage: `/Sub/Geo`,
/// `/Inheriting/{Geo,Cam,Lamp}`, `/Referencing/{Geo,Proto}`, `/Instance/{Geo,Cam,Lamp}`,
/// `/Scatter`.
#[test]
fn class_and_over_prims_are_not_scene_content() {
    write("weak.usda", "#usda 1.0\ndef Xform \"Sub\"\n{\n def Cube \"Geo\"\n {\n }\n}\n");
    let p = write(
        "specifiers.usda",
        r#"#usda 1.0
(
    metersPerUnit = 1
    subLayers = [@weak.usda@]
)

class "Klass"
{
    def Cube "Geo"
    {
        double3 xformOp:translate = (1, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def Camera "Cam"
    {
    }
    def SphereLight "Lamp"
    {
    }
}

over "Undefined"
{
    def Cube "Geo"
    {
        double3 xformOp:translate = (0, 2, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def Cube "Proto"
    {
    }
}

over "Sub"
{
    double3 xformOp:translate = (0, 0, 3)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}

def Xform "Inheriting" (
    inherits = </Klass>
)
{
}

def Xform "Referencing" (
    references = </Undefined>
)
{
}

def Xform "Instance" (
    instanceable = true
    references = </Klass>
)
{
}

def PointInstancer "Scatter"
{
    rel prototypes = </Undefined/Proto>
    int[] protoIndices = [0, 0]
    point3f[] positions = [(0, 0, 5), (0, 0, 6)]
}
"#,
    );
    let shot = load(&p, None).unwrap();
    let paths = sorted(shot.info.instance_paths.clone());
    let expect: Vec<String> = [
        "/Inheriting/Geo",
        "/Instance/Geo",
        "/Referencing/Geo",
        "/Referencing/Proto",
        "/Scatter[0]",
        "/Scatter[1]",
        "/Sub/Geo",
    ]
    .map(String::from)
    .to_vec();
    assert_eq!(paths, expect);
    let at = |path: &str| {
        let k = shot.info.instance_paths.iter().position(|p| p == path).unwrap();
        shot.info.instance_stage_xf[k].transform_point3(DVec3::ZERO)
    };
    assert!(at("/Inheriting/Geo").abs_diff_eq(DVec3::new(1.0, 0.0, 0.0), 1e-12));
    assert!(at("/Referencing/Geo").abs_diff_eq(DVec3::new(0.0, 2.0, 0.0), 1e-12));
    assert!(at("/Sub/Geo").abs_diff_eq(DVec3::new(0.0, 0.0, 3.0), 1e-12));
    assert!(at("/Scatter[1]").abs_diff_eq(DVec3::new(0.0, 0.0, 6.0), 1e-12));
    let cams: Vec<&str> = shot.cameras.iter().map(|c| c.path.as_str()).collect();
    assert_eq!(cams, ["/Inheriting/Cam"]);
    let lights: Vec<&str> = shot.info.lights.iter().map(|l| l.prim.as_str()).collect();
    assert_eq!(lights, ["/Inheriting/Lamp"]);
    // the meshes built are the rendered ones: none for /Klass/Geo or /Undefined/Geo
    assert!(shot.info.meshes.iter().all(|m| !m.prim.starts_with("/Klass") && m.prim != "/Undefined/Geo"));
}

/// A material binding on a native instance prim, or on an ancestor of it, reaches the
/// instance proxies beneath, as UsdShade's `ComputeBoundMaterial` resolves them along the
/// proxy's path: a binding inside the prototype is nearer and wins, unless an ancestor's is
/// `strongerThanDescendants`. pxr on this stage: A Red, B Green, C Blue, D Blue, E none.
#[test]
fn instance_prim_bindings_reach_the_instance_proxies() {
    let p = write("instance_binding.usda", INSTANCE_BINDINGS);
    let shot = load(&p, None).unwrap();
    let colour = |path: &str| {
        let k = shot.info.instance_paths.iter().position(|p| p == path).unwrap_or_else(|| panic!("no {path}"));
        let mesh = &shot.scene.meshes[shot.scene.instances[k].mesh as usize];
        shot.scene.materials[mesh.material_ids[0] as usize].base_color.truncate()
    };
    use glam::Vec3;
    assert_eq!(colour("/World/A/Geo"), Vec3::new(1.0, 0.0, 0.0));
    assert_eq!(colour("/World/B/Geo"), Vec3::new(0.0, 1.0, 0.0));
    assert_eq!(colour("/World/Group/C/Geo"), Vec3::new(0.0, 0.0, 1.0));
    assert_eq!(colour("/World/Strong/D/Geo"), Vec3::new(0.0, 0.0, 1.0));
    let e = colour("/World/E/Geo");
    assert!(e.x == e.y && e.y == e.z, "unbound: the grey fallback, not {e}");
    // A, C and E share the prototype's cube and differ only by what their instances bind
    let mesh_of = |path: &str| {
        let k = shot.info.instance_paths.iter().position(|p| p == path).unwrap();
        shot.scene.instances[k].mesh
    };
    assert_ne!(mesh_of("/World/A/Geo"), mesh_of("/World/Group/C/Geo"));
}

const INSTANCE_BINDINGS: &str = r#"#usda 1.0
(
    metersPerUnit = 1
)

def Scope "Looks"
{
    def Material "Red"
    {
        token outputs:surface.connect = </Looks/Red/S.outputs:surface>
        def Shader "S"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (1, 0, 0)
            token outputs:surface
        }
    }
    def Material "Green"
    {
        token outputs:surface.connect = </Looks/Green/S.outputs:surface>
        def Shader "S"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0, 1, 0)
            token outputs:surface
        }
    }
    def Material "Blue"
    {
        token outputs:surface.connect = </Looks/Blue/S.outputs:surface>
        def Shader "S"
        {
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor = (0, 0, 1)
            token outputs:surface
        }
    }
}

class "Src"
{
    def Xform "Box"
    {
        def Cube "Geo"
        {
        }
    }
    def Xform "BoxBound"
    {
        def Cube "Geo" (
            prepend apiSchemas = ["MaterialBindingAPI"]
        )
        {
            rel material:binding = </Looks/Green>
        }
    }
}

def Xform "World"
{
    def Xform "A" (
        instanceable = true
        prepend apiSchemas = ["MaterialBindingAPI"]
        references = </Src/Box>
    )
    {
        rel material:binding = </Looks/Red>
    }
    def Xform "B" (
        instanceable = true
        prepend apiSchemas = ["MaterialBindingAPI"]
        references = </Src/BoxBound>
    )
    {
        rel material:binding = </Looks/Red>
    }
    def Xform "Group" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        rel material:binding = </Looks/Blue>
        def Xform "C" (
            instanceable = true
            references = </Src/Box>
        )
        {
        }
    }
    def Xform "Strong" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        rel material:binding = </Looks/Blue> (
            bindMaterialAs = "strongerThanDescendants"
        )
        def Xform "D" (
            instanceable = true
            references = </Src/BoxBound>
        )
        {
        }
    }
    def Xform "E" (
        instanceable = true
        references = </Src/Box>
    )
    {
    }
}
"#;

/// A typeless prim (`def "X"`) is neither Xformable nor Imageable, and a `Scope` is not
/// Xformable: pxr ignores the xform ops, visibility and purpose they author (an invisible
/// Xform above a typeless prim still hides what is beneath). `UsdGeom.XformCache`,
/// `ComputeVisibility` and `ComputePurpose` on this stage: `/UntypedXf/Geo`,
/// `/UntypedInvisible/Geo`, `/UntypedGuide/Geo` at the origin and rendered, `/Outer/Mid/Geo`
/// and `/ScopeXf/Geo` invisible, `/T/Mid/Geo` at (0, 1, 0) (reset), `/T/Mid/Geo2` at
/// (0, 0, 1) (the typeless `Mid`'s (0, 0, 7) ignored).
#[test]
fn typeless_prims_author_no_transform_visibility_or_purpose() {
    let p = write("typeless.usda", TYPELESS);
    let shot = load(&p, None).unwrap();
    let paths = sorted(shot.info.instance_paths.clone());
    assert_eq!(paths, ["/T/Mid/Geo", "/T/Mid/Geo2", "/UntypedGuide/Geo", "/UntypedInvisible/Geo", "/UntypedXf/Geo"]);
    let at = |path: &str| {
        let k = shot.info.instance_paths.iter().position(|p| p == path).unwrap();
        shot.info.instance_stage_xf[k].transform_point3(DVec3::ZERO)
    };
    for origin in ["/UntypedGuide/Geo", "/UntypedInvisible/Geo", "/UntypedXf/Geo"] {
        assert_eq!(at(origin), DVec3::ZERO, "{origin}");
    }
    assert_eq!(at("/T/Mid/Geo"), DVec3::new(0.0, 1.0, 0.0));
    assert_eq!(at("/T/Mid/Geo2"), DVec3::new(0.0, 0.0, 1.0));
    // a point-instancer prototype root that is typeless or a Scope: its ops are ignored too
    // (pxr's ComputeInstanceTransformsAtTime: translations (0, 0, 0) and (1, 0, 0))
    let p = write("typeless_prototypes.usda", TYPELESS_PROTOTYPES);
    let shot = load(&p, None).unwrap();
    let got: Vec<DVec3> = shot.info.instance_stage_xf.iter().map(|m| m.transform_point3(DVec3::ZERO)).collect();
    assert_eq!(got, [DVec3::ZERO, DVec3::X]);
}

const TYPELESS_PROTOTYPES: &str = r#"#usda 1.0
def PointInstancer "PI"
{
    rel prototypes = [</PI/Protos/P>, </PI/Protos/S>]
    int[] protoIndices = [0, 1]
    point3f[] positions = [(0, 0, 0), (1, 0, 0)]
    over "Protos"
    {
        def "P"
        {
            double3 xformOp:translate = (0, 0, 7)
            uniform token[] xformOpOrder = ["xformOp:translate"]
            def Cube "C"
            {
            }
        }
        def Scope "S"
        {
            double3 xformOp:translate = (0, 0, 7)
            uniform token[] xformOpOrder = ["xformOp:translate"]
            def Cube "C"
            {
            }
        }
    }
}
"#;

const TYPELESS: &str = r#"#usda 1.0
def "UntypedXf"
{
    double3 xformOp:translate = (5, 0, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def Cube "Geo"
    {
    }
}
def "UntypedInvisible"
{
    token visibility = "invisible"
    def Cube "Geo"
    {
    }
}
def "UntypedGuide"
{
    uniform token purpose = "guide"
    def Cube "Geo"
    {
    }
}
def Xform "Outer"
{
    token visibility = "invisible"
    def "Mid"
    {
        def Cube "Geo"
        {
        }
    }
}
def Scope "ScopeXf"
{
    double3 xformOp:translate = (0, 5, 0)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    token visibility = "invisible"
    def Cube "Geo"
    {
    }
}
def Xform "T"
{
    double3 xformOp:translate = (0, 0, 1)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def "Mid"
    {
        double3 xformOp:translate = (0, 0, 7)
        uniform token[] xformOpOrder = ["xformOp:translate"]
        def Cube "Geo"
        {
            double3 xformOp:translate = (0, 1, 0)
            uniform token[] xformOpOrder = ["!resetXformStack!", "xformOp:translate"]
        }
        def Cube "Geo2"
        {
        }
    }
}
"#;

/// PointInstancer `orientations` are used normalised (a zero quaternion as the identity), so
/// an instance is its prototype rotated and scaled by `scales` alone. This is where petzval
/// and pxr differ on purpose: usd-core's `ComputeInstanceTransformsAtTime` builds the matrix
/// from the quaternion as authored (`GfMatrix4d.SetRotate(GfQuatd)`), so the half-precision
/// (0.7071, 0, 0.7071, 0) below (length 0.99989) leaves 4.27·10⁻⁴ on the diagonal of its
/// scale-2 instance, and a quaternion of length 2 would scale by −7.
#[test]
fn point_instancer_orientations_are_normalised() {
    let p = write("orientations.usda", ORIENTATIONS);
    let shot = load(&p, None).unwrap();
    let xf = &shot.info.instance_stage_xf;
    assert_eq!(xf.len(), 3);
    // 90° about +y at scale 2: x → −z, z → +x
    let m = xf[0];
    assert!(m.transform_vector3(DVec3::X).abs_diff_eq(DVec3::new(0.0, 0.0, -2.0), 1e-12), "{m}");
    assert!(m.transform_vector3(DVec3::Z).abs_diff_eq(DVec3::new(2.0, 0.0, 0.0), 1e-12), "{m}");
    assert!(m.transform_vector3(DVec3::Y).abs_diff_eq(DVec3::new(0.0, 2.0, 0.0), 1e-12), "{m}");
    // zero → identity; (2, 0, 0, 0) → identity, not a scale
    for k in [1, 2] {
        let expect = glam::DMat4::from_translation(DVec3::new(k as f64, 0.0, 0.0));
        assert!(xf[k].abs_diff_eq(expect, 1e-12), "{k}: {}", xf[k]);
    }
}

const ORIENTATIONS: &str = r#"#usda 1.0
def PointInstancer "PI"
{
    rel prototypes = </PI/Protos/C>
    int[] protoIndices = [0, 0, 0]
    point3f[] positions = [(0, 0, 0), (1, 0, 0), (2, 0, 0)]
    quath[] orientations = [(0.7071, 0, 0.7071, 0), (0, 0, 0, 0), (2, 0, 0, 0)]
    float3[] scales = [(2, 2, 2), (1, 1, 1), (1,1,1)]
    def Scope "Protos"
    {
        def Cube "C"
        {
        }
    }
}
"#;
