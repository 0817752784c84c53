//! The USD stage on small usda files written here (the pxr comparisons are in tests/usd).

use glam::{DMat4, DVec3};
use petzval_usd::{load, Error};
use std::path::PathBuf;

fn write(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("petzval-usd-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const TRI: &str = "point3f[] points = [(0,0,0),(1,0,0),(0,1,0)]
    int[] faceVertexCounts = [3]
    int[] faceVertexIndices = [0, 1, 2]";

#[test]
fn rotate_xyz_applies_x_first() {
    let p = write(
        "rot.usda",
        &format!(
            "#usda 1.0\n(\n metersPerUnit = 1\n upAxis = \"Y\"\n)\ndef Mesh \"M\"\n{{\n {TRI}\n float3 xformOp:rotateXYZ = (90, 0, 90)\n uniform token[] xformOpOrder = [\"xformOp:rotateXYZ\"]\n}}\n"
        ),
    );
    let shot = load(&p, None).unwrap();
    let m = shot.info.instance_stage_xf[0];
    let expect = DMat4::from_rotation_z(90f64.to_radians()) * DMat4::from_rotation_x(90f64.to_radians());
    assert!(m.abs_diff_eq(expect, 1e-9), "{m:?}");
    // +y → (x first) +z → (z) +z
    assert!(m.transform_vector3(DVec3::Y).abs_diff_eq(DVec3::Z, 1e-9));
}

#[test]
fn reset_xform_stack_drops_the_parent() {
    let p = write(
        "reset.usda",
        &format!(
            "#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Xform \"P\"\n{{\n double3 xformOp:translate = (10, 0, 0)\n uniform token[] xformOpOrder = [\"xformOp:translate\"]\n def Mesh \"M\"\n {{\n {TRI}\n double3 xformOp:translate = (0, 1, 0)\n uniform token[] xformOpOrder = [\"!resetXformStack!\", \"xformOp:translate\"]\n }}\n}}\n"
        ),
    );
    let shot = load(&p, None).unwrap();
    let t = shot.info.instance_stage_xf[0].transform_point3(DVec3::ZERO);
    assert!(t.abs_diff_eq(DVec3::new(0.0, 1.0, 0.0), 1e-12), "{t}");
}

#[test]
fn an_op_without_a_value_names_layer_prim_and_attribute() {
    let p = write(
        "noval.usda",
        &format!(
            "#usda 1.0\ndef Mesh \"M\"\n{{\n {TRI}\n uniform token[] xformOpOrder = [\"xformOp:translate\"]\n}}\n"
        ),
    );
    let e = load(&p, None).err().expect("an error");
    let msg = e.to_string();
    assert!(matches!(e, Error::Attribute { .. }), "{msg}");
    assert!(msg.contains("noval.usda") && msg.contains("/M.xformOp:translate"), "{msg}");
}

#[test]
fn camera_fallbacks_in_tenths_of_a_scene_unit() {
    let p = write("cam.usda", "#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Camera \"C\"\n{\n}\n");
    let shot = load(&p, None).unwrap();
    let c = shot.camera(Some("/C")).unwrap();
    // fallbacks 50 and 20.955 tenths of a metre
    assert!((c.focal_length_mm - 5000.0).abs() < 1e-9);
    assert!((c.horizontal_aperture_mm - 2095.5).abs() < 1e-9);
    assert_eq!(c.f_stop, 0.0);
    assert_eq!(c.focus_distance_m, None);
    assert_eq!(c.clipping_range_m, (1.0, 1_000_000.0));
    let h = c.host_camera().unwrap();
    assert_eq!(h.lens, "thin");
    assert_eq!(h.f_number, None, "fStop 0 = no depth of field");
    let e = shot.camera(Some("/Nope")).err().unwrap().to_string();
    assert!(e.contains("/Nope") && e.contains("/C"), "{e}");
}

#[test]
fn left_handed_flips_the_winding() {
    let p = write(
        "lh.usda",
        &format!("#usda 1.0\ndef Mesh \"R\"\n{{\n {TRI}\n}}\ndef Mesh \"L\"\n{{\n {TRI}\n uniform token orientation = \"leftHanded\"\n}}\n"),
    );
    let shot = load(&p, None).unwrap();
    let r = &shot.scene.meshes[0];
    let l = &shot.scene.meshes[1];
    assert_eq!(r.indices[0], [0, 1, 2]);
    assert_eq!(l.indices[0], [0, 2, 1]);
    // smooth normals follow the winding
    assert!(r.normals[0].z > 0.99 && l.normals[0].z < -0.99);
}

#[test]
fn shapes_wind_outwards_with_outward_normals() {
    let p = write(
        "shapes.usda",
        "#usda 1.0\ndef Cube \"A\"\n{\n}\ndef Sphere \"B\"\n{\n}\ndef Cylinder \"C\"\n{\n uniform token axis = \"X\"\n}\ndef Cone \"D\"\n{\n uniform token axis = \"Y\"\n}\ndef Capsule \"E\"\n{\n}\n",
    );
    let shot = load(&p, None).unwrap();
    assert_eq!(shot.scene.meshes.len(), 5);
    for (k, m) in shot.scene.meshes.iter().enumerate() {
        for t in &m.indices {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a);
            if n.length() < 1e-9 {
                continue; // the poles' collapsed quads
            }
            let centroid = (a + b + c) / 3.0;
            assert!(n.dot(centroid) > 0.0, "mesh {k}: triangle {t:?} winds inwards");
            let vn = m.normals[t[0] as usize] + m.normals[t[1] as usize] + m.normals[t[2] as usize];
            assert!(vn.dot(n) > 0.0, "mesh {k}: normals disagree with the winding");
        }
    }
}

/// A bool authored in time samples with integer literals (Blender's USD export of an animated
/// light writes `bool inputs:normalize.timeSamples = { 1: 1 }`) reads as the bool, as pxr reads
/// it: the light is normalised as with `bool inputs:normalize = true`.
#[test]
fn bool_time_samples_written_as_integers_read_as_bools() {
    let stage = |name: &str, normalize: &str| {
        write(
            name,
            &format!(
                "#usda 1.0\n(\n metersPerUnit = 1\n startTimeCode = 1\n endTimeCode = 2\n)\ndef SphereLight \"Lamp\"\n{{\n float inputs:intensity = 100\n {normalize}\n}}\ndef Mesh \"M\"\n{{\n {TRI}\n}}\n"
            ),
        )
    };
    let intensity = |p: &PathBuf| match load(p, Some(1.0)).unwrap().scene.lights.as_slice() {
        [petzval_renderer::scene::Light::Point { intensity, .. }] => *intensity,
        other => panic!("expected one point light, got {other:?}"),
    };
    let sampled = intensity(&stage("bool_samples.usda", "bool inputs:normalize.timeSamples = {\n 1: 1,\n }"));
    let on = intensity(&stage("bool_on.usda", "bool inputs:normalize = true"));
    let off = intensity(&stage("bool_off.usda", "bool inputs:normalize = false"));
    assert_eq!(sampled, on);
    assert_ne!(on, off);
}

/// A sphere light's radius and a distant light's angle are read (soft shadows, as Cycles renders
/// Blender's exports): `inputs:radius` in stage units (metersPerUnit applied), 0 with
/// `treatAsPoint`; `inputs:angle` in degrees, 0.53 (UsdLux's fallback) when not authored; in a
/// stage Blender wrote (`doc = "Blender v…"`) the angle is doubled and the sphere is Blender's
/// default Soft Falloff disc; a negative radius is an error naming the prim and the attribute.
#[test]
fn sphere_light_radius_and_distant_light_angle_are_read() {
    use petzval_renderer::scene::Light;
    let stage = |name: &str, lights: &str| {
        write(name, &format!("#usda 1.0\n(\n metersPerUnit = 0.01\n)\n{lights}\ndef Mesh \"M\"\n{{\n {TRI}\n}}\n"))
    };
    let p = stage(
        "soft_lights.usda",
        "def SphereLight \"Soft\"\n{\n float inputs:radius = 25\n}\n\
         def SphereLight \"Hard\"\n{\n float inputs:radius = 25\n bool treatAsPoint = true\n}\n\
         def DistantLight \"Sun\"\n{\n float inputs:angle = 12\n}\n\
         def DistantLight \"Default\"\n{\n}\n",
    );
    let shot = load(&p, None).unwrap();
    let radii: Vec<f32> = shot
        .scene
        .lights
        .iter()
        .filter_map(|l| match l {
            Light::Point { radius_m, .. } => Some(*radius_m),
            _ => None,
        })
        .collect();
    let angles: Vec<f32> = shot
        .scene
        .lights
        .iter()
        .filter_map(|l| match l {
            Light::Directional { angle_rad, .. } => Some(angle_rad.to_degrees()),
            _ => None,
        })
        .collect();
    assert_eq!(radii.len(), 2);
    assert!((radii[0] - 0.25).abs() < 1e-6 && radii[1] == 0.0, "{radii:?}");
    assert!((angles[0] - 12.0).abs() < 1e-4 && (angles[1] - 0.53).abs() < 1e-4, "{angles:?}");
    // UsdLux's sphere light is a sphere; Blender writes its point lights as spheres but renders
    // them with Soft Falloff by default (a disc), and writes half its sun's angle
    assert!(shot.scene.lights.iter().all(|l| !matches!(l, Light::Point { sphere: false, .. })));
    let blender = write(
        "soft_lights_blender.usda",
        &format!(
            "#usda 1.0\n(\n doc = \"Blender v5.0.1\"\n metersPerUnit = 1\n)\n\
             def SphereLight \"Soft\"\n{{\n float inputs:radius = 0.1\n}}\n\
             def DistantLight \"Sun\"\n{{\n float inputs:angle = 5\n}}\n\
             def Mesh \"M\"\n{{\n {TRI}\n}}\n"
        ),
    );
    let shot = load(&blender, None).unwrap();
    for l in &shot.scene.lights {
        match *l {
            Light::Point { radius_m, sphere, .. } => assert!((radius_m - 0.1).abs() < 1e-6 && !sphere, "{l:?}"),
            Light::Directional { angle_rad, .. } => assert!((angle_rad.to_degrees() - 10.0).abs() < 1e-4, "{l:?}"),
            _ => panic!("{l:?}"),
        }
    }
    let bad = stage("bad_radius.usda", "def SphereLight \"Neg\"\n{\n float inputs:radius = -1\n}\n");
    let Err(e) = load(&bad, None) else { panic!("a negative radius was accepted") };
    let e = e.to_string();
    assert!(e.contains("/Neg") && e.contains("inputs:radius"), "{e}");
}

/// A rect light's emitter is seen by camera rays on a UsdLux stage, and hidden from them on a
/// stage Blender wrote (Blender 5 hides lights from the camera; its exporter does not record
/// the setting); either way it is a light's emitter (no shadow).
#[test]
fn rect_lights_are_hidden_from_the_camera_on_blender_stages() {
    let stage = |name: &str, doc: &str| {
        write(
            name,
            &format!(
                "#usda 1.0\n(\n{doc} metersPerUnit = 1\n)\n\
                 def RectLight \"Panel\"\n{{\n float inputs:width = 2\n}}\n\
                 def Mesh \"M\"\n{{\n {TRI}\n}}\n"
            ),
        )
    };
    for (doc, seen) in [("", true), (" doc = \"Blender v5.0.1\"\n", false)] {
        let shot = load(&stage(if seen { "rect_usdlux.usda" } else { "rect_blender.usda" }, doc), None).unwrap();
        let panel: Vec<_> = shot.scene.materials.iter().filter(|m| m.name == "/Panel").collect();
        assert_eq!(panel.len(), 1, "{:?}", shot.scene.materials.iter().map(|m| &m.name).collect::<Vec<_>>());
        assert!(panel[0].light_emitter && panel[0].visible_to_camera == seen, "doc {doc:?}: {:?}", panel[0]);
    }
}

/// A `catmullClark` mesh (Blender's "Best Match" export of a Subdivision modifier) is
/// subdivided, two levels by default, without a warning; `loop` is named in a warning and
/// rendered as its cage; "none" (what Blender writes for every other mesh), `bilinear` and an
/// unauthored scheme render the mesh as authored.
#[test]
fn subdivision_schemes() {
    const QUAD: &str = "point3f[] points = [(0,0,0),(1,0,0),(1,1,0),(0,1,0)]
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]";
    let stage = |name: &str, scheme: &str| {
        let p = write(
            name,
            &format!("#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Mesh \"Blob\"\n{{\n {QUAD}\n {scheme}\n}}\n"),
        );
        let shot = load(&p, None).unwrap();
        (shot.scene.warnings, shot.info.meshes[0].triangles, shot.info.meshes[0].subdivision_level)
    };
    let (w, tris, level) = stage("subdiv_cc.usda", "uniform token subdivisionScheme = \"catmullClark\"");
    assert!(w.is_empty(), "{w:?}");
    assert_eq!((tris, level), (32, Some(2)));
    let (w, tris, level) = stage("subdiv_loop.usda", "uniform token subdivisionScheme = \"loop\"");
    assert!(w.iter().any(|w| w.contains("/Blob") && w.contains("loop")), "{w:?}");
    assert_eq!((tris, level), (2, None));
    for (name, scheme) in [
        ("subdiv_none.usda", "uniform token subdivisionScheme = \"none\""),
        ("subdiv_bilinear.usda", "uniform token subdivisionScheme = \"bilinear\""),
        ("subdiv_unset.usda", ""),
    ] {
        let (w, tris, level) = stage(name, scheme);
        assert!(w.is_empty(), "{name}: {w:?}");
        assert_eq!((tris, level), (2, None), "{name}");
    }
}

/// Malformed crease data is an error naming the prim and attribute.
#[test]
fn bad_creases_name_the_attribute() {
    let cases = [
        ("int[] creaseIndices = [0, 9]\n int[] creaseLengths = [2]\n float[] creaseSharpnesses = [1]", "creaseIndices"),
        ("int[] creaseIndices = [0, 1]\n int[] creaseLengths = [3]\n float[] creaseSharpnesses = [1]", "creaseIndices"),
        (
            "int[] creaseIndices = [0, 1]\n int[] creaseLengths = [2]\n float[] creaseSharpnesses = [1, 2, 3]",
            "creaseSharpnesses",
        ),
        ("int[] cornerIndices = [0]\n float[] cornerSharpnesses = []", "cornerSharpnesses"),
        ("token interpolateBoundary = \"sideways\"", "interpolateBoundary"),
    ];
    for (k, (attrs, attr)) in cases.iter().enumerate() {
        let p = write(
            &format!("bad_crease_{k}.usda"),
            &format!("#usda 1.0\ndef Mesh \"Blob\"\n{{\n {TRI}\n uniform token subdivisionScheme = \"catmullClark\"\n {attrs}\n}}\n"),
        );
        let e = load(&p, None).err().unwrap_or_else(|| panic!("{attrs}: loaded")).to_string();
        assert!(e.contains("/Blob") && e.contains(attr), "{attrs}: {e}");
    }
}

/// A disk light's emitting polygon has the disc's area, so it emits the disc's power (the
/// 32-gon inscribed in the circle lacked 0.64 % of it: Cycles' renders were that much brighter).
#[test]
fn a_disk_light_emits_the_discs_power() {
    let p = write(
        "disk_light.usda",
        &format!(
            "#usda 1.0\n(\n metersPerUnit = 1\n)\ndef DiskLight \"Disc\"\n{{\n float inputs:radius = 0.4\n}}\ndef Mesh \"M\"\n{{\n {TRI}\n}}\n"
        ),
    );
    let shot = load(&p, None).unwrap();
    let emitter = shot.scene.materials.iter().position(|m| m.emissive != glam::Vec3::ZERO).expect("an emitter");
    let mesh = shot.scene.meshes.iter().find(|m| m.material_ids.first() == Some(&(emitter as u32))).expect("its mesh");
    let area: f64 = mesh
        .indices
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_dvec3());
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    let disc = std::f64::consts::PI * 0.16;
    assert!((area / disc - 1.0).abs() < 1e-5, "polygon area {area} against the disc's {disc}");
}

/// `inputs:opacity` connected to the alpha of the texture that gives the diffuse colour (Blender's
/// USD export of an image's alpha wired into the Principled BSDF) cuts the surface out where the
/// texture is transparent, as the GLB export's base colour alpha does; opacity from any other
/// texture output is named in a warning (it was ignored in silence).
#[test]
fn opacity_from_the_diffuse_textures_alpha_cuts_out() {
    let dir = write("alpha.png", "").parent().unwrap().to_path_buf();
    let mut png = image::RgbaImage::new(4, 4);
    for (x, _, p) in png.enumerate_pixels_mut() {
        *p = image::Rgba([200, 100, 50, if x < 2 { 0 } else { 255 }]);
    }
    png.save(dir.join("alpha.png")).unwrap();
    let stage = |name: &str, output: &str| {
        write(
            name,
            &format!(
                "#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Mesh \"Card\"\n{{\n point3f[] points = [(-1,-1,0),(1,-1,0),(1,1,0),(-1,1,0)]\n int[] faceVertexCounts = [4]\n int[] faceVertexIndices = [0,1,2,3]\n texCoord2f[] primvars:st = [(0,0),(1,0),(1,1),(0,1)] (interpolation = \"vertex\")\n rel material:binding = </M>\n}}\ndef Material \"M\"\n{{\n token outputs:surface.connect = </M/S.outputs:surface>\n def Shader \"S\"\n {{\n  uniform token info:id = \"UsdPreviewSurface\"\n  color3f inputs:diffuseColor.connect = </M/T.outputs:rgb>\n  float inputs:opacity.connect = </M/T.{output}>\n  token outputs:surface\n }}\n def Shader \"T\"\n {{\n  uniform token info:id = \"UsdUVTexture\"\n  asset inputs:file = @./alpha.png@\n  float outputs:a\n  float outputs:r\n  float3 outputs:rgb\n }}\n}}\n"
            ),
        )
    };
    let shot = load(&stage("cutout.usda", "outputs:a"), None).unwrap();
    let m = &shot.scene.materials[0];
    assert!(m.base_color_texture.is_some());
    assert_eq!(m.alpha_mode, petzval_renderer::scene::AlphaMode::Blend);
    assert!(!shot.scene.warnings.iter().any(|w| w.contains("opacity")), "{:?}", shot.scene.warnings);
    let shot = load(&stage("cutout_r.usda", "outputs:r"), None).unwrap();
    assert_eq!(shot.scene.materials[0].alpha_mode, petzval_renderer::scene::AlphaMode::Opaque);
    assert!(
        shot.scene
            .warnings
            .iter()
            .any(|w| w.contains("/M/S") && w.contains("inputs:opacity") && w.contains("outputs:r")),
        "{:?}",
        shot.scene.warnings
    );
}

/// `--camera NAME` on a USD shot: a name (no '/') finds the camera whose prim or parent prim has
/// it (Blender writes the camera object `Camera` as `/root/Camera/Camera`); several matches or
/// none are errors that list the cameras.
#[test]
fn cameras_are_found_by_name() {
    let p = write(
        "names.usda",
        "#usda 1.0\ndef Xform \"root\"\n{\n def Xform \"Camera\"\n {\n  def Camera \"Camera\"\n  {\n  }\n }\n def Xform \"Rig\"\n {\n  def Camera \"Tele\"\n  {\n  }\n }\n def Xform \"A\"\n {\n  def Camera \"Cam\"\n  {\n  }\n }\n def Xform \"B\"\n {\n  def Camera \"Cam\"\n  {\n  }\n }\n}\n",
    );
    let shot = load(&p, None).unwrap();
    assert_eq!(shot.camera(Some("Camera")).unwrap().path, "/root/Camera/Camera");
    assert_eq!(shot.camera(Some("Tele")).unwrap().path, "/root/Rig/Tele");
    assert_eq!(shot.camera(Some("Rig")).unwrap().path, "/root/Rig/Tele");
    let e = shot.camera(Some("Cam")).err().unwrap().to_string();
    assert!(e.contains("several") && e.contains("/root/A/Cam") && e.contains("/root/B/Cam"), "{e}");
    let e = shot.camera(Some("Nope")).err().unwrap().to_string();
    assert!(e.contains("Nope") && e.contains("/root/Camera/Camera"), "{e}");
}

/// UsdPreviewSurface's clear coat (Blender's USD export writes Coat Weight and Coat Roughness
/// there): read as the material's coat of IOR 1.5, untinted; without it the coat weight is 0 and
/// the roughness the spec's fallback, 0.01.
#[test]
fn preview_surface_clearcoat_is_read() {
    let stage = |name: &str, inputs: &str| {
        write(
            name,
            &format!(
                "#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Mesh \"Card\"\n{{\n point3f[] points = [(-1,-1,0),(1,-1,0),(1,1,0),(-1,1,0)]\n int[] faceVertexCounts = [4]\n int[] faceVertexIndices = [0,1,2,3]\n rel material:binding = </M>\n}}\ndef Material \"M\"\n{{\n token outputs:surface.connect = </M/S.outputs:surface>\n def Shader \"S\"\n {{\n  uniform token info:id = \"UsdPreviewSurface\"\n{inputs}  token outputs:surface\n }}\n}}\n"
            ),
        )
    };
    let shot =
        load(&stage("coat.usda", "  float inputs:clearcoat = 0.6\n  float inputs:clearcoatRoughness = 0.25\n"), None)
            .unwrap();
    let m = &shot.scene.materials[0];
    assert_eq!((m.coat, m.coat_roughness, m.coat_ior, m.coat_tint), (0.6, 0.25, 1.5, glam::Vec3::ONE));
    assert!(shot.scene.warnings.is_empty(), "{:?}", shot.scene.warnings);
    let m = &load(&stage("nocoat.usda", ""), None).unwrap().scene.materials[0];
    assert_eq!((m.coat, m.coat_roughness), (0.0, 0.01));
}

const QUAD_2: &str = "point3f[] points = [(0,0,0),(1,0,0),(2,0,0),(0,1,0),(1,1,0),(2,1,0)]
    int[] faceVertexCounts = [4, 4]
    int[] faceVertexIndices = [0, 1, 4, 3, 1, 2, 5, 4]";

/// A UsdPreviewSurface whose diffuseColor is a `UsdPrimvarReader_float3` takes the gprim's
/// primvar as vertex colours (base colour white; faceVarying values per corner); a gprim
/// without the primvar gets the reader's fallback; an unbound mesh with a displayColor per face
/// is coloured per face; `usd info` names the primvar.
#[test]
fn colour_primvars_become_vertex_colours() {
    let material = "def Material \"M\"\n{\n token outputs:surface.connect = </M/S.outputs:surface>\n def Shader \"S\"\n {\n  uniform token info:id = \"UsdPreviewSurface\"\n  color3f inputs:diffuseColor.connect = </M/R.outputs:result>\n  token outputs:surface\n }\n def Shader \"R\"\n {\n  uniform token info:id = \"UsdPrimvarReader_float3\"\n  string inputs:varname = \"Cd\"\n  float3 inputs:fallback = (0.1, 0.2, 0.3)\n  float3 outputs:result\n }\n}\n";
    let text = format!(
        "#usda 1.0\n{material}def Mesh \"Painted\" (prepend apiSchemas = [\"MaterialBindingAPI\"])\n{{\n {QUAD_2}\n rel material:binding = </M>\n color3f[] primvars:Cd = [(1,0,0),(0,1,0),(0,0,1),(1,1,1),(1,0,0),(1,0,0),(1,0,0),(1,0,0)] (interpolation = \"faceVarying\")\n}}\ndef Mesh \"Bare\" (prepend apiSchemas = [\"MaterialBindingAPI\"])\n{{\n {QUAD_2}\n rel material:binding = </M>\n}}\ndef Mesh \"PerFace\"\n{{\n {QUAD_2}\n color3f[] primvars:displayColor = [(0.5, 0, 0), (0, 0.25, 0)] (interpolation = \"uniform\")\n}}\n"
    );
    let p = write("colour_primvars.usda", &text);
    let shot = load(&p, None).unwrap();
    assert!(shot.scene.warnings.is_empty(), "{:?}", shot.scene.warnings);
    let mesh_of = |name: &str| {
        let k = shot.info.meshes.iter().position(|m| m.prim.ends_with(name)).unwrap();
        (&shot.scene.meshes[k], &shot.info.meshes[k])
    };
    let colour_at = |m: &petzval_renderer::scene::Mesh, p: glam::Vec3| -> Vec<glam::Vec4> {
        m.positions.iter().zip(&m.colors).filter(|(q, _)| q.distance(p) < 1e-6).map(|(_, c)| *c).collect()
    };
    use glam::{Vec3, Vec4};
    let (painted, info) = mesh_of("/Painted");
    assert_eq!(info.color_primvar.as_deref(), Some("primvars:Cd"));
    assert_eq!(painted.colors.len(), painted.positions.len());
    assert_eq!(shot.scene.materials[painted.material_ids[0] as usize].base_color, Vec4::ONE);
    // point 1 (1, 0, 0) is corner 1 of face 0 (green) and corner 0 of face 1 (red)
    let mut c = colour_at(painted, Vec3::new(1.0, 0.0, 0.0));
    c.sort_by(|a, b| a.x.total_cmp(&b.x));
    assert_eq!(c, vec![Vec4::new(0.0, 1.0, 0.0, 1.0), Vec4::new(1.0, 0.0, 0.0, 1.0)]);
    let (bare, _) = mesh_of("/Bare");
    assert!(bare.colors.iter().all(|c| c.distance(Vec4::new(0.1, 0.2, 0.3, 1.0)) < 1e-6), "{:?}", bare.colors);
    let (per_face, info) = mesh_of("/PerFace");
    assert_eq!(info.color_primvar.as_deref(), Some("primvars:displayColor"));
    assert_eq!(shot.scene.materials[per_face.material_ids[0] as usize].base_color, Vec4::ONE);
    for (t, &m) in per_face.indices.iter().zip(&per_face.material_ids) {
        let _ = m;
        let cs: Vec<Vec4> = t.iter().map(|&i| per_face.colors[i as usize]).collect();
        let centre = t.iter().map(|&i| per_face.positions[i as usize]).sum::<Vec3>() / 3.0;
        let want = if centre.x < 1.0 { Vec4::new(0.5, 0.0, 0.0, 1.0) } else { Vec4::new(0.0, 0.25, 0.0, 1.0) };
        assert!(cs.iter().all(|c| *c == want), "triangle at {centre}: {cs:?}");
    }
}

/// A subdivided mesh's vertex colours are refined with it: a per-point displayColor that is
/// the same everywhere stays that colour at every refined vertex, and one per face keeps each
/// child face its parent's colour.
#[test]
fn colour_primvars_are_refined_with_a_subdivision_surface() {
    let text = format!(
        "#usda 1.0\ndef Mesh \"Flat\"\n{{\n {QUAD_2}\n uniform token subdivisionScheme = \"catmullClark\"\n color3f[] primvars:displayColor = [(0.2,0.4,0.6),(0.2,0.4,0.6),(0.2,0.4,0.6),(0.2,0.4,0.6),(0.2,0.4,0.6),(0.2,0.4,0.6)] (interpolation = \"vertex\")\n}}\ndef Mesh \"Faces\"\n{{\n {QUAD_2}\n uniform token subdivisionScheme = \"catmullClark\"\n color3f[] primvars:displayColor = [(1,0,0),(0,0,1)] (interpolation = \"uniform\")\n}}\n"
    );
    let p = write("colour_subdiv.usda", &text);
    let shot = load(&p, None).unwrap();
    let flat = &shot.scene.meshes[0];
    assert_eq!(shot.info.meshes[0].subdivision_level, Some(2));
    assert_eq!(flat.colors.len(), flat.positions.len());
    assert!(flat.colors.iter().all(|c| c.distance(glam::Vec4::new(0.2, 0.4, 0.6, 1.0)) < 1e-6));
    let faces = &shot.scene.meshes[1];
    assert_eq!(faces.indices.len(), 2 * 16 * 2);
    for t in &faces.indices {
        let cs: Vec<glam::Vec4> = t.iter().map(|&i| faces.colors[i as usize]).collect();
        assert!(cs.iter().all(|c| *c == cs[0]), "a triangle mixes colours: {cs:?}");
        assert!(cs[0] == glam::Vec4::new(1.0, 0.0, 0.0, 1.0) || cs[0] == glam::Vec4::new(0.0, 0.0, 1.0, 1.0));
    }
}

/// Stage-space world vertices and normals of a loaded shot's meshes, per instance prim path.
fn world_vertices(shot: &petzval_usd::UsdShot) -> Vec<(String, Vec<(DVec3, DVec3)>)> {
    let s = &shot.scene;
    s.instances
        .iter()
        .enumerate()
        .map(|(i, inst)| {
            let xf = shot.info.instance_stage_xf[i];
            let m = &s.meshes[inst.mesh as usize];
            let normal = glam::DMat3::from_mat4(xf).inverse().transpose();
            let v = m
                .positions
                .iter()
                .zip(&m.normals)
                .map(|(p, n)| (xf.transform_point3(p.as_dvec3()), (normal * n.as_dvec3()).normalize()))
                .collect();
            (shot.info.instance_paths[i].clone(), v)
        })
        .collect()
}

/// The larger one-sided distance between point sets, brute force.
fn hausdorff(a: &[DVec3], b: &[DVec3]) -> f64 {
    let one = |x: &[DVec3], y: &[DVec3]| {
        x.iter().map(|p| y.iter().map(|q| p.distance(*q)).fold(f64::INFINITY, f64::min)).fold(0.0, f64::max)
    };
    one(a, b).max(one(b, a))
}

/// UsdSkel: Blender's USD export of an animated two-bone armature bending a smooth tube and an
/// icosphere with two shape keys (BlendShapes weighted by a SkelAnimation), read at time codes
/// 1, 7, 13 and 24 (`tests/scene/make_usd_skin_fixtures.py`), has every mesh's world-space
/// points where Pixar's UsdSkel (usd-core's `BakeSkinning`) puts them, within 10⁻⁵ stage units
/// both ways (measured: ≤ 1.1·10⁻⁶, the references' rounding), and where Blender's own
/// evaluated meshes are. Normals: Blender's recomputed ones, ≤ 0.1° off on average and ≤ 0.5°
/// at most (measured: 0.006–0.017° and 0.054–0.070°). Frames 1 and 13 are far apart, so the
/// comparison tells poses apart.
#[test]
fn usd_skel_poses_meshes_as_pixar_and_blender_do() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/skel");
    let points = |v: &serde_json::Value| -> Vec<DVec3> {
        v.as_array().unwrap().iter().map(|p| DVec3::from_array([0, 1, 2].map(|k| p[k].as_f64().unwrap()))).collect()
    };
    for f in [1u32, 7, 13, 24] {
        let text = std::fs::read_to_string(dir.join(format!("frame_{f}.json"))).unwrap();
        let want: serde_json::Value = serde_json::from_str(&text).unwrap();
        let shot = load(&dir.join("skinned.usdc"), Some(f as f64)).unwrap();
        assert!(shot.scene.warnings.is_empty(), "{:?}", shot.scene.warnings);
        let got = world_vertices(&shot);
        let all: Vec<(DVec3, DVec3)> = got.iter().flat_map(|(_, v)| v.iter().copied()).collect();
        let all_points: Vec<DVec3> = all.iter().map(|v| v.0).collect();
        // 1. Pixar's UsdSkel, mesh by mesh.
        for (prim, pts) in want["pxr_points"].as_object().unwrap() {
            let mine: Vec<DVec3> =
                got.iter().filter(|(p, _)| p == prim).flat_map(|(_, v)| v.iter().map(|x| x.0)).collect();
            assert!(!mine.is_empty(), "frame {f}: {prim} not loaded");
            let d = hausdorff(&mine, &points(pts));
            assert!(d <= 1e-5, "frame {f}: {prim} is {d} from Pixar's UsdSkel");
        }
        if f == 13 {
            let first: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(dir.join("frame_1.json")).unwrap()).unwrap();
            let tube = |v: &serde_json::Value| points(&v["pxr_points"]["/root/Rig/Tube/Cylinder"]);
            let apart = hausdorff(&tube(&first), &tube(&want));
            assert!(apart > 0.3, "frames 1 and 13 are only {apart} apart");
        }
        // 2. Blender's evaluated meshes: points and normals.
        let blender: Vec<(DVec3, DVec3)> = want["blender"]
            .as_object()
            .unwrap()
            .values()
            .flat_map(|o| o.as_array().unwrap().iter())
            .map(|r| {
                let x = |k: usize| r[k].as_f64().unwrap();
                (DVec3::new(x(0), x(1), x(2)), DVec3::new(x(3), x(4), x(5)))
            })
            .collect();
        let d = hausdorff(&all_points, &blender.iter().map(|b| b.0).collect::<Vec<_>>());
        assert!(d <= 1e-5, "frame {f}: {d} from Blender's evaluated meshes");
        let angles: Vec<f64> = all
            .iter()
            .map(|(p, n)| {
                let b = blender.iter().min_by(|a, b| a.0.distance(*p).total_cmp(&b.0.distance(*p))).unwrap();
                n.dot(b.1).clamp(-1.0, 1.0).acos().to_degrees()
            })
            .collect();
        let mean = angles.iter().sum::<f64>() / angles.len() as f64;
        let worst = angles.iter().copied().fold(0.0, f64::max);
        assert!(mean <= 0.1 && worst <= 0.5, "frame {f}: normals {mean}° off on average, {worst}° at most");
    }
}

/// A hand-written UsdSkel rig against positions worked out by hand: a triangle bound to a
/// two-joint skeleton whose second joint the animation moves 2 along z, one point weighted half
/// and half, a blend shape moving a point 1 along y at weight 0.5; the skeleton's SkelRoot is
/// translated 10 along x (the mesh's own translation of 100 is ignored, as UsdSkel places
/// skinned points by the skeleton). Malformed influences and shapes are errors naming the prim
/// and attribute; a binding outside any SkelRoot is a warning and the mesh is left as authored.
#[test]
fn usd_skel_by_hand() {
    let rig = |root: &str, indices: &str, shape_indices: &str| {
        format!(
            "#usda 1.0\n(\n metersPerUnit = 1\n upAxis = \"Y\"\n startTimeCode = 1\n endTimeCode = 1\n)\n\
def {root} \"Root\"\n{{\n double3 xformOp:translate = (10, 0, 0)\n uniform token[] xformOpOrder = [\"xformOp:translate\"]\n\
 def Skeleton \"Skel\" (\n  prepend apiSchemas = [\"SkelBindingAPI\"]\n )\n {{\n\
  uniform token[] joints = [\"Hip\", \"Hip/Knee\"]\n\
  uniform matrix4d[] bindTransforms = [((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1)), ((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1))]\n\
  uniform matrix4d[] restTransforms = [((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1)), ((1,0,0,0),(0,1,0,0),(0,0,1,0),(0,0,0,1))]\n\
  rel skel:animationSource = </Root/Skel/Anim>\n\
  def SkelAnimation \"Anim\"\n  {{\n   uniform token[] joints = [\"Hip/Knee\"]\n   float3[] translations = [(0, 0, 2)]\n\
   quatf[] rotations = [(1, 0, 0, 0)]\n   half3[] scales = [(1, 1, 1)]\n\
   uniform token[] blendShapes = [\"Up\"]\n   float[] blendShapeWeights = [0.5]\n  }}\n }}\n\
 def Mesh \"Leg\" (\n  prepend apiSchemas = [\"SkelBindingAPI\"]\n )\n {{\n  {TRI}\n\
  double3 xformOp:translate = (100, 0, 0)\n  uniform token[] xformOpOrder = [\"xformOp:translate\"]\n\
  int[] primvars:skel:jointIndices = [{indices}] (\n   elementSize = 2\n   interpolation = \"vertex\"\n  )\n\
  float[] primvars:skel:jointWeights = [1, 0, 0.5, 0.5, 1, 0] (\n   elementSize = 2\n   interpolation = \"vertex\"\n  )\n\
  uniform token[] skel:blendShapes = [\"Up\"]\n  rel skel:blendShapeTargets = </Root/Leg/Up>\n  rel skel:skeleton = </Root/Skel>\n\
  def BlendShape \"Up\"\n  {{\n   uniform vector3f[] offsets = [(0, 1, 0)]\n   uniform int[] pointIndices = [{shape_indices}]\n  }}\n }}\n}}\n"
        )
    };
    let shot = load(&write("rig.usda", &rig("SkelRoot", "0, 0, 1, 0, 1, 0", "2")), None).unwrap();
    assert!(shot.scene.warnings.is_empty(), "{:?}", shot.scene.warnings);
    let v: Vec<DVec3> = world_vertices(&shot).into_iter().flat_map(|(_, v)| v.into_iter().map(|x| x.0)).collect();
    let want = [DVec3::new(10.0, 0.0, 0.0), DVec3::new(11.0, 0.0, 1.0), DVec3::new(10.0, 1.5, 2.0)];
    assert_eq!(v.len(), 3);
    for (a, b) in v.iter().zip(want) {
        assert!(a.abs_diff_eq(b, 1e-6), "{v:?}");
    }
    // a Skeleton that authors skel:animationSource without applying SkelBindingAPI (older
    // files): still posed by its animation
    let text = rig("SkelRoot", "0, 0, 1, 0, 1, 0", "2").replacen(
        "def Skeleton \"Skel\" (\n  prepend apiSchemas = [\"SkelBindingAPI\"]\n )",
        "def Skeleton \"Skel\"",
        1,
    );
    assert!(!text.contains("def Skeleton \"Skel\" ("));
    let shot = load(&write("rig_noapi.usda", &text), None).unwrap();
    let v: Vec<DVec3> = world_vertices(&shot).into_iter().flat_map(|(_, v)| v.into_iter().map(|x| x.0)).collect();
    assert!(v[2].abs_diff_eq(want[2], 1e-6), "{v:?}");
    // outside a SkelRoot: a warning, the mesh as authored (its own translation)
    let shot = load(&write("rig_xform.usda", &rig("Xform", "0, 0, 1, 0, 1, 0", "2")), None).unwrap();
    assert!(shot.scene.warnings.iter().any(|w| w.contains("outside any SkelRoot")), "{:?}", shot.scene.warnings);
    let v: Vec<DVec3> = world_vertices(&shot).into_iter().flat_map(|(_, v)| v.into_iter().map(|x| x.0)).collect();
    assert!(v[2].abs_diff_eq(DVec3::new(110.0, 1.0, 0.0), 1e-6), "{v:?}");
    // malformed
    let error = |name: &str, text: String| match load(&write(name, &text), None) {
        Ok(_) => panic!("{name} loaded"),
        Err(e) => e.to_string(),
    };
    let e = error("rig_joint.usda", rig("SkelRoot", "0, 0, 7, 0, 1, 0", "2"));
    assert!(e.contains("/Root/Leg") && e.contains("primvars:skel:jointIndices") && e.contains("joint 7"), "{e}");
    let e = error("rig_count.usda", rig("SkelRoot", "0, 0, 1, 0", "2"));
    assert!(e.contains("primvars:skel:jointIndices") && e.contains("6 needed"), "{e}");
    let text = rig("SkelRoot", "0, 0, 1, 0, 1, 0", "2").replace("offsets = [(0, 1, 0)]", "offsets = [(0, inf, 0)]");
    let e = error("rig_inf.usda", text);
    assert!(e.contains("/Root/Leg") && e.contains("skel:blendShapes") && e.contains("not finite"), "{e}");
    let e = error("rig_shape.usda", rig("SkelRoot", "0, 0, 1, 0, 1, 0", "5"));
    assert!(e.contains("/Root/Leg/Up") && e.contains("pointIndices") && e.contains("index 5"), "{e}");
}

/// RenderSettingsBase over settings and product: the product's pixel aspect, conform policy and
/// data window win over the settings'; includedPurposes is the settings'; malformed values are
/// errors naming the layer, prim and attribute.
#[test]
fn render_settings_base_attributes_and_their_errors() {
    use petzval_usd::render_settings::read;
    let stage = |settings_extra: &str, product_extra: &str| {
        format!(
            "#usda 1.0\n(\n renderSettingsPrimPath = \"/R/S\"\n)\ndef Camera \"C\"\n{{\n}}\ndef Scope \"R\"\n{{\n def RenderSettings \"S\"\n {{\n  rel camera = </C>\n  rel products = </R/P>\n  float pixelAspectRatio = 2\n  uniform token aspectRatioConformPolicy = \"cropAperture\"\n  float4 dataWindowNDC = (0, 0, 0.5, 0.5)\n{settings_extra}\n }}\n def RenderProduct \"P\"\n {{\n{product_extra}\n }}\n}}\n"
        )
    };
    // 1. The settings' values where the product authors none.
    let p = write("rs_base.usda", &stage("", ""));
    let rs = read(&p, None, None).unwrap().unwrap();
    assert_eq!((rs.pixel_aspect, rs.aspect_conform.as_str()), (2.0, "cropAperture"));
    assert_eq!(rs.data_window_ndc, Some([0.0, 0.0, 0.5, 0.5]));
    assert_eq!(rs.included_purposes, ["default", "render"]);
    // 2. The product's over them; includedPurposes from the settings.
    let p = write(
        "rs_product.usda",
        &stage(
            "  uniform token[] includedPurposes = [\"default\", \"proxy\"]",
            "  float pixelAspectRatio = 1.5\n  uniform token aspectRatioConformPolicy = \"adjustApertureWidth\"\n  float4 dataWindowNDC = (-0.1, -0.1, 1.1, 1.1)",
        ),
    );
    let rs = read(&p, None, None).unwrap().unwrap();
    assert_eq!((rs.pixel_aspect, rs.aspect_conform.as_str()), (1.5, "adjustApertureWidth"));
    let w = rs.data_window_ndc.unwrap();
    assert!((w[0] + 0.1).abs() < 1e-6 && (w[3] - 1.1).abs() < 1e-6, "{w:?}");
    assert_eq!(rs.included_purposes, ["default", "proxy"]);
    // 3. Errors name the layer, the prim and the attribute.
    for (name, settings_extra, product_extra, attr) in [
        ("rs_bad1.usda", "", "  float4 dataWindowNDC = (0.5, 0, 0.5, 1)", "/R/P.dataWindowNDC"),
        ("rs_bad2.usda", "", "  uniform token aspectRatioConformPolicy = \"fit\"", "/R/P.aspectRatioConformPolicy"),
        ("rs_bad3.usda", "  uniform token[] includedPurposes = [\"final\"]", "", "/R/S.includedPurposes"),
        ("rs_bad4.usda", "", "  float pixelAspectRatio = -1", "/R/P.pixelAspectRatio"),
        ("rs_bad5.usda", "", "  float2 dataWindowNDC = (0, 1)", "/R/P.dataWindowNDC"),
    ] {
        let p = write(name, &stage(settings_extra, product_extra));
        let e = read(&p, None, None).err().unwrap_or_else(|| panic!("{name}: an error")).to_string();
        assert!(e.contains(name) && e.contains(attr), "{name}: {e}");
    }
}

/// `colorTemperature`'s tint is UsdLux's blackbody colour: pxr's
/// `UsdLux.BlackbodyTemperatureAsRgb` (usd-core 0.26.11) at these temperatures, to 10⁻⁵,
/// clamped outside 1000–10 000 K. (Before: Tanner Helland's fit divided by its 6500 K colour,
/// (1.839, 0.817, 0.299) at 3000 K, up to 10 % off per channel.)
#[test]
fn colour_temperature_is_usdlux_blackbody() {
    let pxr: [(f64, [f32; 3]); 12] = [
        (800.0, [4.305504, 0.118358, 0.0]),
        (1000.0, [4.305504, 0.118358, 0.0]),
        (1300.0, [3.555754, 0.341438, 0.0]),
        (2700.0, [1.935324, 0.803566, 0.191690]),
        (3000.0, [1.771028, 0.844294, 0.272032]),
        (4000.0, [1.414028, 0.924039, 0.533308]),
        (5250.0, [1.177022, 0.966231, 0.813248]),
        (6500.0, [1.043333, 0.983624, 1.034613]),
        (7777.0, [0.958579, 0.991070, 1.210425]),
        (9000.0, [0.904302, 0.993889, 1.342326]),
        (10000.0, [0.871841, 0.994688, 1.429996]),
        (12000.0, [0.871841, 0.994688, 1.429996]),
    ];
    for (kelvin, want) in pxr {
        let got = petzval_usd::lights::blackbody_rgb(kelvin).to_array();
        for c in 0..3 {
            assert!((got[c] - want[c]).abs() < 1e-5, "{kelvin} K: {got:?} against pxr's {want:?}");
        }
    }
}

/// A `DistantLight` without `normalize` (UsdLux's fallback) gives its intensity as the disc's
/// radiance: the irradiance is that over the disc, π tan²(angle/2) of the normalized light's, as
/// Cycles renders Blender's import of it (measured: unnormalized / normalized 0.00383 for
/// Blender's 4° sun, π tan²(2°) = 0.00383). A sun without an angle stays normalized. (Before,
/// every distant light was taken as normalized: 261× too bright against Cycles at 2°.)
#[test]
fn unnormalized_distant_lights_give_the_radiance_of_their_disc() {
    use petzval_renderer::scene::Light;
    let p = write(
        "distant_normalize.usda",
        &format!(
            "#usda 1.0\n\
             def DistantLight \"Off\"\n{{\n float inputs:angle = 2\n float inputs:exposure = 1\n}}\n\
             def DistantLight \"On\"\n{{\n float inputs:angle = 2\n float inputs:exposure = 1\n bool inputs:normalize = 1\n}}\n\
             def DistantLight \"Point\"\n{{\n float inputs:angle = 0\n}}\n\
             def Mesh \"M\"\n{{\n {TRI}\n}}\n"
        ),
    );
    let shot = load(&p, None).unwrap();
    let e: Vec<f32> = shot
        .scene
        .lights
        .iter()
        .filter_map(|l| match l {
            Light::Directional { irradiance, .. } => Some(irradiance.x),
            _ => None,
        })
        .collect();
    let disc = std::f32::consts::PI * 1f32.to_radians().tan().powi(2);
    assert_eq!(e.len(), 3);
    assert!((e[0] - 8.0 * disc).abs() < 1e-6 * 8.0, "{e:?}");
    assert!((e[1] - 8.0).abs() < 1e-5, "{e:?}");
    assert!((e[2] - 4.0).abs() < 1e-5, "{e:?}");
}

/// Blender 5.0's exporter writes `enableColorTemperature = 1` on every light, and
/// `colorTemperature` only away from 6500 K: on a stage Blender wrote, an enabled light without
/// an authored temperature keeps its colour (Blender's default light, Temperature off), one with
/// a temperature takes its blackbody colour; on other stages UsdLux's fallback 6500 K applies.
#[test]
fn blender_stages_enable_colour_temperature_on_every_light() {
    use petzval_renderer::scene::Light;
    let stage = |name: &str, doc: &str| {
        write(
            name,
            &format!(
                "#usda 1.0\n(\n doc = \"{doc}\"\n)\n\
                 def SphereLight \"Default\"\n{{\n bool inputs:enableColorTemperature = 1\n bool inputs:normalize = 1\n float inputs:radius = 0\n}}\n\
                 def SphereLight \"Warm\"\n{{\n bool inputs:enableColorTemperature = 1\n float inputs:colorTemperature = 3000\n bool inputs:normalize = 1\n float inputs:radius = 0\n}}\n\
                 def Mesh \"M\"\n{{\n {TRI}\n}}\n"
            ),
        )
    };
    let tints = |p: &PathBuf| -> Vec<[f32; 3]> {
        load(p, None)
            .unwrap()
            .scene
            .lights
            .iter()
            .filter_map(|l| match l {
                Light::Point { intensity, .. } => Some((*intensity * 4.0).to_array()),
                _ => None,
            })
            .collect()
    };
    let warm = petzval_usd::lights::blackbody_rgb(3000.0).to_array();
    let d65 = petzval_usd::lights::blackbody_rgb(6500.0).to_array();
    let close = |a: [f32; 3], b: [f32; 3]| (0..3).all(|c| (a[c] - b[c]).abs() < 1e-5);
    let blender = tints(&stage("temperature_blender.usda", "Blender v5.0.1"));
    assert!(close(blender[0], [1.0; 3]) && close(blender[1], warm), "{blender:?}");
    let other = tints(&stage("temperature_other.usda", "made by hand"));
    assert!(close(other[0], d65) && close(other[1], warm), "{other:?}");
    // a non-finite temperature is an error naming the prim and the attribute
    let bad = write(
        "temperature_nan.usda",
        &format!(
            "#usda 1.0\ndef SphereLight \"Hot\"\n{{\n bool inputs:enableColorTemperature = 1\n float inputs:colorTemperature = nan\n}}\ndef Mesh \"M\"\n{{\n {TRI}\n}}\n"
        ),
    );
    let e = load(&bad, None).err().expect("a NaN temperature was accepted").to_string();
    assert!(e.contains("/Hot") && e.contains("inputs:colorTemperature"), "{e}");
}
