"""Writes the USD fuzzing seeds (usd/tests/data/fuzz/seeds/) with Pixar's USD (usd-core, the
`pxr` module in the test venv): small stages that together touch every part of the loader —
stage metadata, xform ops, meshes with primvars and subsets, intrinsic shapes, native
instancing, a PointInstancer, a reference and a variant set, a camera with PetzvalLensAPI,
UsdLux lights, UsdPreviewSurface materials, RenderSettings and time samples — as .usda, and
one as .usdc. Run: .venv/bin/python usd/tests/data/fuzz/make_seeds.py
"""

from __future__ import annotations

from pathlib import Path

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade, Vt

OUT = Path(__file__).resolve().parent / "seeds"


def quad(stage: Usd.Stage, path: str) -> UsdGeom.Mesh:
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    return m


def camera(stage: Usd.Stage, path: str) -> UsdGeom.Camera:
    cam = UsdGeom.Camera.Define(stage, path)
    cam.CreateFocalLengthAttr(0.5)
    cam.CreateHorizontalApertureAttr(0.36)
    cam.CreateVerticalApertureAttr(0.24)
    cam.CreateFStopAttr(2.8)
    cam.CreateFocusDistanceAttr(3.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1000))
    cam.AddTranslateOp().Set((0, 0.5, 4))
    return cam


def new(name: str) -> Usd.Stage:
    stage = Usd.Stage.CreateNew(str(OUT / name))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    return stage


def shot(name: str) -> None:
    stage = new(name)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(3)
    g = quad(stage, "/World/Ground")
    g.AddTranslateOp().Set((-2, -1, -3))
    g.AddRotateXYZOp().Set((-90, 0, 0))
    g.AddScaleOp().Set((4, 4, 1))
    tri = UsdGeom.Mesh.Define(stage, "/World/Tri")
    tri.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (2, 0, 0)])
    tri.CreateFaceVertexCountsAttr([3, 4])
    tri.CreateFaceVertexIndicesAttr([0, 1, 2, 1, 4, 3, 2])
    tri.CreateNormalsAttr([(0, 0, 1)] * 7)
    tri.SetNormalsInterpolation(UsdGeom.Tokens.faceVarying)
    st = UsdGeom.PrimvarsAPI(tri).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([(0, 0), (1, 0), (0, 1), (1, 1), (1, 0)])
    UsdGeom.Subset.CreateGeomSubset(tri, "front", UsdGeom.Tokens.face, Vt.IntArray([0]))
    tri.AddTranslateOp().Set((0, 0, -2))
    UsdGeom.Sphere.Define(stage, "/World/Ball").CreateRadiusAttr(0.5)
    UsdGeom.Cube.Define(stage, "/World/Box").AddTranslateOp().Set((1.5, 0, -2.5))
    mat = UsdShade.Material.Define(stage, "/World/Looks/Red")
    sh = UsdShade.Shader.Define(stage, "/World/Looks/Red/PBR")
    sh.CreateIdAttr("UsdPreviewSurface")
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set((0.8, 0.1, 0.1))
    sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.4)
    sh.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(tri.GetPrim()).Bind(mat)
    UsdLux.DistantLight.Define(stage, "/World/Sun").CreateIntensityAttr(3.0)
    UsdLux.DomeLight.Define(stage, "/World/Env").CreateIntensityAttr(0.5)
    cam = camera(stage, "/World/Cam")
    prim = cam.GetPrim()
    prim.AddAppliedSchema("PetzvalLensAPI")
    prim.CreateAttribute("petzval:lens", Sdf.ValueTypeNames.Asset).Set("double-gauss-50mm")
    prim.CreateAttribute("petzval:lensModel", Sdf.ValueTypeNames.Token).Set("thick")
    prim.CreateAttribute("petzval:tiltX", Sdf.ValueTypeNames.Float).Set(2.0)
    prim.CreateAttribute("petzval:aperture:blades", Sdf.ValueTypeNames.Int).Set(6)
    prim.CreateAttribute("petzval:aperture:rotation", Sdf.ValueTypeNames.Float).Set(15.0)
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateCameraRel().SetTargets(["/World/Cam"])
    rs.CreateResolutionAttr(Gf.Vec2i(64, 48))
    rs.CreatePixelAspectRatioAttr(1.0)
    rs.CreateAspectRatioConformPolicyAttr("cropAperture")
    rs.CreateIncludedPurposesAttr(["default", "render", "proxy"])
    prod = UsdRender.Product.Define(stage, "/Render/Product")
    prod.CreateProductNameAttr("beauty.####.exr")
    prod.CreateDataWindowNDCAttr(Gf.Vec4f(-0.1, 0.0, 1.1, 0.75))
    prod.CreatePixelAspectRatioAttr(1.5)
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    stage.GetRootLayer().Save()


def instancing() -> None:
    asset = new("ref_asset.usda")
    a = UsdGeom.Xform.Define(asset, "/Asset")
    quad(asset, "/Asset/Leaf").AddScaleOp().Set((0.2, 0.2, 0.2))
    asset.SetDefaultPrim(a.GetPrim())
    asset.GetRootLayer().Save()
    stage = new("instancing.usda")
    for i in range(3):
        x = UsdGeom.Xform.Define(stage, f"/World/Copy{i}")
        x.GetPrim().GetReferences().AddReference("./ref_asset.usda")
        x.GetPrim().SetInstanceable(True)
        x.AddTranslateOp().Set((i * 0.5, 0, -2))
    v = UsdGeom.Xform.Define(stage, "/World/Variant")
    vs = v.GetPrim().GetVariantSets().AddVariantSet("size")
    for name, s in (("small", 0.5), ("big", 2.0)):
        vs.AddVariant(name)
        vs.SetVariantSelection(name)
        with vs.GetVariantEditContext():
            UsdGeom.Cube.Define(stage, "/World/Variant/Geo").CreateSizeAttr(s)
    vs.SetVariantSelection("small")
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Scatter")
    proto = quad(stage, "/World/Scatter/Protos/Q")
    proto.AddScaleOp().Set((0.1, 0.1, 0.1))
    pi.CreatePrototypesRel().SetTargets([proto.GetPath()])
    pi.CreateProtoIndicesAttr([0, 0, 0, 0])
    pi.CreatePositionsAttr([(0, 0, -1), (0.3, 0, -1), (0, 0.3, -1), (0.3, 0.3, -1)])
    pi.CreateScalesAttr([(1, 1, 1), (2, 2, 2), (1, 1, 1), (0.5, 0.5, 0.5)])
    pi.CreateOrientationsAttr([Gf.Quath(1, 0, 0, 0)] * 4)
    pi.CreateInvisibleIdsAttr([3])
    camera(stage, "/Cam")
    stage.GetRootLayer().Save()


def lights_materials() -> None:
    stage = new("lights_materials.usda")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    q = quad(stage, "/Q")
    q.AddTranslateOp().Set((-50, -50, -300))
    q.AddScaleOp().Set((100, 100, 1))
    mat = UsdShade.Material.Define(stage, "/Looks/Glow")
    sh = UsdShade.Shader.Define(stage, "/Looks/Glow/PBR")
    sh.CreateIdAttr("UsdPreviewSurface")
    sh.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set((1, 0.5, 0.2))
    sh.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(0.5)
    sh.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(1.45)
    sh.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
    tex = UsdShade.Shader.Define(stage, "/Looks/Glow/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("missing.png")
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(q.GetPrim()).Bind(mat)
    sp = UsdLux.SphereLight.Define(stage, "/Lamp")
    sp.CreateIntensityAttr(50.0)
    sp.CreateRadiusAttr(5.0)
    sp.CreateColorAttr((1, 0.9, 0.8))
    sp.CreateExposureAttr(1.0)
    sp.AddTranslateOp().Set((0, 100, -100))
    shaping = UsdLux.ShapingAPI.Apply(sp.GetPrim())
    shaping.CreateShapingConeAngleAttr(30.0)
    shaping.CreateShapingConeSoftnessAttr(0.2)
    rect = UsdLux.RectLight.Define(stage, "/Panel")
    rect.CreateWidthAttr(50.0)
    rect.CreateHeightAttr(20.0)
    rect.CreateIntensityAttr(10.0)
    UsdLux.DiskLight.Define(stage, "/Disk").CreateRadiusAttr(10.0)
    cam = camera(stage, "/Cam")
    cam.CreateFocalLengthAttr(50.0)
    cam.CreateHorizontalApertureAttr(36.0)
    cam.CreateVerticalApertureAttr(24.0)
    stage.GetRootLayer().Save()


def animated() -> None:
    stage = new("animated.usda")
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(10)
    stage.SetTimeCodesPerSecond(24)
    m = quad(stage, "/M")
    op = m.AddTranslateOp()
    op.Set((0, 0, -3), 1)
    op.Set((1, 0, -3), 10)
    vis = m.CreateVisibilityAttr()
    vis.Set(UsdGeom.Tokens.inherited, 1)
    vis.Set(UsdGeom.Tokens.invisible, 9)
    cam = camera(stage, "/Cam")
    cam.GetFocalLengthAttr().Set(0.35, 1)
    cam.GetFocalLengthAttr().Set(0.85, 10)
    cam.GetFocusDistanceAttr().Set(2.0, 1)
    cam.GetFocusDistanceAttr().Set(5.0, 10)
    stage.GetRootLayer().Save()


def skel() -> None:
    """A quad strip skinned to a two-joint Skeleton inside a SkelRoot, posed by a time-sampled
    SkelAnimation, with a sparse BlendShape weighted by it (usd/src/skel.rs)."""
    from pxr import UsdSkel

    stage = new("skel.usda")
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(10)
    root = UsdSkel.Root.Define(stage, "/Rig")
    skel = UsdSkel.Skeleton.Define(stage, "/Rig/Skel")
    skel.CreateJointsAttr(["Hip", "Hip/Knee"])
    skel.CreateBindTransformsAttr([Gf.Matrix4d(1), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 1, 0))])
    skel.CreateRestTransformsAttr([Gf.Matrix4d(1), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 1, 0))])
    anim = UsdSkel.Animation.Define(stage, "/Rig/Skel/Anim")
    anim.CreateJointsAttr(["Hip/Knee"])
    anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([(0, 1, 0)]))
    rotations = anim.CreateRotationsAttr()
    rotations.Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0)]), 1)
    rotations.Set(Vt.QuatfArray([Gf.Quatf(0.92387953, 0.38268343, 0, 0)]), 10)
    anim.CreateScalesAttr().Set(Vt.Vec3hArray([(1, 1, 1)]))
    anim.CreateBlendShapesAttr(["Lift"])
    weights = anim.CreateBlendShapeWeightsAttr()
    weights.Set(Vt.FloatArray([0.0]), 1)
    weights.Set(Vt.FloatArray([1.0]), 10)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    m = UsdGeom.Mesh.Define(stage, "/Rig/Strip")
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 2, 0), (1, 2, 0)])
    m.CreateFaceVertexCountsAttr([4, 4])
    m.CreateFaceVertexIndicesAttr([0, 1, 3, 2, 2, 3, 5, 4])
    binding = UsdSkel.BindingAPI.Apply(m.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(False, 2).Set([0, 0, 0, 0, 0, 1, 0, 1, 1, 0, 1, 0])
    binding.CreateJointWeightsPrimvar(False, 2).Set([1, 0, 1, 0, 0.5, 0.5, 0.5, 0.5, 1, 0, 1, 0])
    binding.CreateBlendShapesAttr(["Lift"])
    shape = UsdSkel.BlendShape.Define(stage, "/Rig/Strip/Lift")
    shape.CreateOffsetsAttr([(0, 0, 0.5), (0, 0, 0.5)])
    shape.CreatePointIndicesAttr([4, 5])
    binding.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    camera(stage, "/Cam")
    _ = root
    stage.GetRootLayer().Save()


def curves() -> None:
    """BasisCurves of every type, basis and wrap, with vertex, varying and uniform widths and a
    uniform displayColor, and time-sampled points (usd/src/curves.rs)."""
    stage = new("curves.usda")
    cases = [
        ("Lin", "linear", "bezier", "periodic", [3], "uniform"),
        ("Bez", "cubic", "bezier", "nonperiodic", [4, 7], "vertex"),
        ("Bsp", "cubic", "bspline", "pinned", [2, 5], "varying"),
        ("Cat", "cubic", "catmullRom", "periodic", [4], "vertex"),
    ]
    k = 0
    for name, ty, basis, wrap, counts, interp in cases:
        c = UsdGeom.BasisCurves.Define(stage, f"/Hair/{name}")
        n = sum(counts)
        pts = [(0.1 * (k + i), 0.2 * (i % 3), 0.05 * i) for i in range(n)]
        c.CreatePointsAttr().Set(pts, 1)
        c.GetPointsAttr().Set([(x, y + 0.1, z) for x, y, z in pts], 2)
        c.CreateCurveVertexCountsAttr(counts)
        c.CreateTypeAttr(ty)
        c.CreateBasisAttr(basis)
        c.CreateWrapAttr(wrap)
        widths = {"uniform": len(counts), "vertex": n, "varying": n}[interp]
        c.CreateWidthsAttr([0.02] * widths)
        c.SetWidthsInterpolation(interp)
        c.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set([(0.8, 0.3, 0.1)] * len(counts))
        k += n
    camera(stage, "/Cam")
    stage.GetRootLayer().Save()


def main() -> None:
    OUT.mkdir(exist_ok=True)
    shot("shot.usda")
    instancing()
    lights_materials()
    animated()
    skel()
    curves()
    # the binary crate format: the first stage exported as .usdc
    Sdf.Layer.FindOrOpen(str(OUT / "shot.usda")).Export(str(OUT / "shot.usdc"))


if __name__ == "__main__":
    main()
