"""The USD stage (`usd/`, openusd 0.6) against Pixar's USD (`usd-core`, the `pxr` module).

Stages are authored here with pxr (usda, usdc and usdz), then `petzval usd info --json
--instances` reports what our loader made of them and pxr computes the same quantities
independently:

* world transforms of every mesh placement: `UsdGeom.XformCache` (every xform op type,
  `!invert!`, `!resetXformStack!`), through references, payloads, variants, sublayers and
  native instancing (instance proxies);
* `UsdGeomPointInstancer.ComputeInstanceTransformsAtTime` for a 100 000-instance scatter
  (with `invisibleIds`), which must not copy meshes;
* triangle counts, visibility and purpose, `upAxis`/`metersPerUnit`;
* camera parameters with the schema's fallbacks (`UsdGeom.Camera` attribute fallbacks);
* time samples at several frames;
* `petzval usd set-lens` output composes in pxr and carries `PetzvalLensAPI`;
* bad input gives an error naming layer, prim and attribute, never a panic.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
DEFAULT = Usd.TimeCode.Default()


def run(petzval: Path, *args: str, ok: bool = True) -> subprocess.CompletedProcess:
    r = subprocess.run([str(petzval), *args], capture_output=True, text=True, timeout=120)
    assert "panicked" not in r.stderr, r.stderr
    if ok:
        assert r.returncode == 0, r.stderr
    return r


def info(petzval: Path, path: Path, frame: float | None = None) -> dict:
    args = ["usd", "info", str(path), "--json", "--instances"]
    if frame is not None:
        args += ["--frame", str(frame)]
    return json.loads(run(petzval, *args).stdout)


def quad(stage: Usd.Stage, path: str) -> UsdGeom.Mesh:
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    return m


def pxr_mesh_placements(stage: Usd.Stage, time: Usd.TimeCode = DEFAULT) -> dict[str, np.ndarray]:
    """Every renderable mesh prim (instance proxies included) → its world matrix (row-major)."""
    cache = UsdGeom.XformCache(time)
    out = {}
    it = iter(Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies()))
    for prim in it:
        img = UsdGeom.Imageable(prim)
        if prim.IsA(UsdGeom.PointInstancer):
            it.PruneChildren()
            continue
        if img and (
            img.ComputeVisibility(time) == UsdGeom.Tokens.invisible
            or img.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy)
        ):
            it.PruneChildren()
            continue
        if prim.IsA(UsdGeom.Mesh):
            out[str(prim.GetPath())] = np.array(cache.GetLocalToWorldTransform(prim), dtype=float)
    return out


def ours_placements(rep: dict) -> dict[str, np.ndarray]:
    return {i["path"]: np.array(i["stage_world"], dtype=float).reshape(4, 4) for i in rep["instances"]}


def assert_same_placements(stage: Usd.Stage, rep: dict, time: Usd.TimeCode = DEFAULT) -> None:
    ref = pxr_mesh_placements(stage, time)
    ours = ours_placements(rep)
    assert sorted(ours) == sorted(ref)
    for k, m in ref.items():
        np.testing.assert_allclose(ours[k], m, atol=1e-5, err_msg=k)


def xform_stage(path: Path) -> Usd.Stage:
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/World")
    root.AddTranslateOp().Set((1, 2, 3))
    root.AddRotateXYZOp().Set((10, 20, 30))
    root.AddScaleOp().Set((2, 2, 2))
    ops = [
        ("RotX", lambda x: x.AddRotateXOp().Set(33)),
        ("RotY", lambda x: x.AddRotateYOp().Set(-47)),
        ("RotZ", lambda x: x.AddRotateZOp().Set(91)),
        ("XZY", lambda x: x.AddRotateXZYOp().Set((10, 50, -20))),
        ("YXZ", lambda x: x.AddRotateYXZOp().Set((15, -35, 60))),
        ("YZX", lambda x: x.AddRotateYZXOp().Set((-5, 25, 45))),
        ("ZXY", lambda x: x.AddRotateZXYOp().Set((70, 10, -30))),
        ("ZYX", lambda x: x.AddRotateZYXOp().Set((12, 34, 56))),
        ("Orient", lambda x: x.AddOrientOp().Set(Gf.Quatf(0.9, 0.1, 0.3, -0.2).GetNormalized())),
        (
            "Matrix",
            lambda x: x.AddTransformOp().Set(Gf.Matrix4d(1, 0.2, 0, 0, 0, 1, 0.3, 0, 0.1, 0, 1, 0, 4, 5, 6, 1)),
        ),
        ("ScaleNonUniform", lambda x: x.AddScaleOp().Set((1, -2, 0.5))),
    ]
    for name, make in ops:
        x = UsdGeom.Xform.Define(stage, f"/World/{name}")
        x.AddTranslateOp().Set((0.5, 0, 0))
        make(x)
        quad(stage, f"/World/{name}/Quad")
    # pivot with !invert!
    piv = UsdGeom.Xform.Define(stage, "/World/Pivot")
    t = piv.AddTranslateOp(opSuffix="pivot")
    t.Set((1, 1, 0))
    piv.AddRotateZOp().Set(45)
    piv.AddTranslateOp(opSuffix="pivot", isInverseOp=True)
    quad(stage, "/World/Pivot/Quad")
    # !resetXformStack!
    r = UsdGeom.Xform.Define(stage, "/World/Reset")
    r.SetResetXformStack(True)
    r.AddTranslateOp().Set((7, 8, 9))
    quad(stage, "/World/Reset/Quad")
    # invisible and guide subtrees are not rendered
    inv = UsdGeom.Xform.Define(stage, "/World/Hidden")
    inv.CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    quad(stage, "/World/Hidden/Quad")
    g = quad(stage, "/World/Guide")
    g.CreatePurposeAttr(UsdGeom.Tokens.guide)
    p = quad(stage, "/World/Proxy")
    p.CreatePurposeAttr(UsdGeom.Tokens.proxy)
    rr = quad(stage, "/World/Render")
    rr.CreatePurposeAttr(UsdGeom.Tokens.render)
    stage.GetRootLayer().Save()
    return stage


@pytest.mark.parametrize("fmt", ["usda", "usdc", "usdz"])
def test_xform_ops_match_pxr_xform_cache(petzval: Path, tmp_path: Path, fmt: str) -> None:
    src = tmp_path / "xf.usda"
    stage = xform_stage(src)
    path = src
    if fmt == "usdc":
        path = tmp_path / "xf.usdc"
        stage.GetRootLayer().Export(str(path))
    elif fmt == "usdz":
        path = tmp_path / "xf.usdz"
        from pxr import UsdUtils

        assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(src)), str(path))
    rep = info(petzval, path)
    assert_same_placements(Usd.Stage.Open(str(path)), rep)
    assert rep["mesh_count"] == len(rep["instances"])  # one mesh per prim here
    assert all(m["triangles"] == 2 for m in rep["meshes"])


def test_up_axis_and_meters_per_unit(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "zup.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    x = UsdGeom.Xform.Define(stage, "/X")
    x.AddTranslateOp().Set((100, 200, 300))
    quad(stage, "/X/Q")
    stage.GetRootLayer().Save()
    rep = info(petzval, path)
    assert rep["up_axis"] == "Z" and rep["meters_per_unit"] == 0.01
    inst = rep["instances"][0]
    world = np.array(inst["world"]).reshape(4, 4).T  # column-vector form
    # stage (x, y, z) cm, z up → renderer (x, z, −y) m, y up
    np.testing.assert_allclose(world @ [0, 0, 0, 1], [1.0, 3.0, -2.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(world @ [1, 0, 0, 1], [1.01, 3.0, -2.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(world @ [0, 1, 0, 1], [1.0, 3.0, -2.01, 1.0], atol=1e-6)


def test_composition_references_payloads_variants_sublayers(petzval: Path, tmp_path: Path) -> None:
    asset = Usd.Stage.CreateNew(str(tmp_path / "asset.usda"))
    UsdGeom.Xform.Define(asset, "/Asset")
    asset.SetDefaultPrim(asset.GetPrimAtPath("/Asset"))
    m = quad(asset, "/Asset/Body")
    m.AddTranslateOp().Set((0, 1, 0))
    vs = asset.GetPrimAtPath("/Asset").GetVariantSets().AddVariantSet("size")
    for name, s in [("small", 0.5), ("big", 3.0)]:
        vs.AddVariant(name)
        vs.SetVariantSelection(name)
        with vs.GetVariantEditContext():
            x = UsdGeom.Xform.Define(asset, f"/Asset/{name}")
            x.AddScaleOp().Set((s, s, s))
            quad(asset, f"/Asset/{name}/Part")
    vs.SetVariantSelection("small")
    asset.GetRootLayer().Save()

    heavy = Usd.Stage.CreateNew(str(tmp_path / "heavy.usdc"))
    h = UsdGeom.Xform.Define(heavy, "/Heavy")
    heavy.SetDefaultPrim(h.GetPrim())
    quad(heavy, "/Heavy/Q")
    heavy.GetRootLayer().Save()

    sub = Usd.Stage.CreateNew(str(tmp_path / "sub.usda"))
    quad(sub, "/FromSub")
    sub.GetRootLayer().Save()

    shot = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    shot.GetRootLayer().subLayerPaths.append("./sub.usda")
    a = UsdGeom.Xform.Define(shot, "/A")
    a.AddTranslateOp().Set((5, 0, 0))
    a.GetPrim().GetReferences().AddReference("./asset.usda")
    b = UsdGeom.Xform.Define(shot, "/B")
    b.AddTranslateOp().Set((-5, 0, 0))
    b.GetPrim().GetReferences().AddReference("./asset.usda")
    b.GetPrim().GetVariantSets().GetVariantSet("size").SetVariantSelection("big")
    p = UsdGeom.Xform.Define(shot, "/P")
    p.GetPrim().GetPayloads().AddPayload("./heavy.usdc")
    shot.GetRootLayer().Save()

    stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    rep = info(petzval, tmp_path / "shot.usda")
    assert_same_placements(stage, rep)
    paths = sorted(ours_placements(rep))
    assert "/A/small/Part" in paths and "/B/big/Part" in paths and "/P/Q" in paths and "/FromSub" in paths


def test_native_instancing_shares_meshes(petzval: Path, tmp_path: Path) -> None:
    asset = Usd.Stage.CreateNew(str(tmp_path / "tree.usda"))
    t = UsdGeom.Xform.Define(asset, "/Tree")
    asset.SetDefaultPrim(t.GetPrim())
    trunk = quad(asset, "/Tree/Trunk")
    trunk.AddScaleOp().Set((1, 3, 1))
    quad(asset, "/Tree/Crown").AddTranslateOp().Set((0, 3, 0))
    asset.GetRootLayer().Save()
    shot = Usd.Stage.CreateNew(str(tmp_path / "forest.usda"))
    for i in range(5):
        x = UsdGeom.Xform.Define(shot, f"/Forest/T{i}")
        x.AddTranslateOp().Set((i * 2.0, 0, -i))
        x.AddRotateYOp().Set(i * 17.0)
        x.GetPrim().GetReferences().AddReference("./tree.usda")
        x.GetPrim().SetInstanceable(True)
    shot.GetRootLayer().Save()
    stage = Usd.Stage.Open(str(tmp_path / "forest.usda"))
    assert len(stage.GetPrototypes()) == 1
    rep = info(petzval, tmp_path / "forest.usda")
    assert rep["mesh_count"] == 2, "the prototype's two meshes are stored once"
    assert rep["instance_count"] == 10
    assert len(rep["native_instances"]) == 5
    assert_same_placements(stage, rep)


def test_point_instancer_100k_does_not_copy_meshes(petzval: Path, tmp_path: Path) -> None:
    n = 100_000
    rng = np.random.default_rng(7)
    path = tmp_path / "scatter.usdc"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    pi = UsdGeom.PointInstancer.Define(stage, "/Scatter")
    pi.AddTranslateOp().Set((0, 1, 0))
    protos = UsdGeom.Xform.Define(stage, "/Scatter/Protos")
    _ = protos
    a = quad(stage, "/Scatter/Protos/A")
    a.AddScaleOp().Set((0.1, 0.1, 0.1))
    b = UsdGeom.Xform.Define(stage, "/Scatter/Protos/B")
    b.AddRotateXOp().Set(90)
    quad(stage, "/Scatter/Protos/B/Q1")
    quad(stage, "/Scatter/Protos/B/Q2").AddTranslateOp().Set((0, 0, 1))
    pi.CreatePrototypesRel().SetTargets([a.GetPath(), b.GetPath()])
    pi.CreateProtoIndicesAttr(rng.integers(0, 2, n).astype(np.int32))
    pi.CreatePositionsAttr(rng.uniform(-100, 100, (n, 3)).astype(np.float32))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    pi.CreateOrientationsAttr([Gf.Quath(*map(float, v)) for v in q[:1000]] * (n // 1000))
    pi.CreateScalesAttr(rng.uniform(0.5, 2, (n, 3)).astype(np.float32))
    pi.CreateIdsAttr(np.arange(n, dtype=np.int64) + 10)
    pi.CreateInvisibleIdsAttr(np.array([10, 11, 500, 99_999 + 10], dtype=np.int64))
    stage.GetRootLayer().Save()

    rep = info(petzval, path)
    # the prototypes' three meshes, each stored once
    assert rep["mesh_count"] == 3
    assert rep["stored_triangles"] == 6
    stage = Usd.Stage.Open(str(path))
    pi = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Scatter"))
    xfs = pi.ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default())
    mask = pi.ComputeMaskAtTime(Usd.TimeCode.Default())
    visible = [i for i in range(n) if mask[i]]
    assert rep["point_instancers"] == [{"prim": "/Scatter", "instances": len(visible), "hidden": 4}]
    proto_idx = np.array(pi.GetProtoIndicesAttr().Get())
    expected = sum(1 if proto_idx[i] == 0 else 2 for i in visible)
    assert rep["instance_count"] == expected
    ours = ours_placements(rep)
    world = np.array(UsdGeom.XformCache().GetLocalToWorldTransform(pi.GetPrim()))
    # pxr applies invisibleIds (the mask) and includes each prototype root's own transform
    assert len(xfs) == len(visible)
    cache = UsdGeom.XformCache()
    b_world = np.array(cache.GetLocalToWorldTransform(stage.GetPrimAtPath("/Scatter/Protos/B")))
    below_root = {
        0: {"": np.eye(4)},
        1: {
            f"/{q}": np.array(cache.GetLocalToWorldTransform(stage.GetPrimAtPath(f"/Scatter/Protos/B/{q}")))
            @ np.linalg.inv(b_world)
            for q in ("Q1", "Q2")
        },
    }
    for k in range(0, len(visible), len(visible) // 300):
        i = visible[k]
        for sub, rel in below_root[int(proto_idx[i])].items():
            ref = rel @ np.array(xfs[k]) @ world
            np.testing.assert_allclose(ours[f"/Scatter[{i}]{sub}"], ref, atol=2e-3 * np.abs(ref).max(), err_msg=str(i))


def test_mesh_triangulation_primvars_subsets(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "mesh.usda"
    stage = Usd.Stage.CreateNew(str(path))
    m = UsdGeom.Mesh.Define(stage, "/M")
    pts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0), (3, 0.5, 0), (3, 2, 0)]
    m.CreatePointsAttr(pts)
    counts = [4, 5, 3, 2, 3]  # a quad, a pentagon, a triangle, a degenerate face, a hole
    idx = [0, 1, 2, 3, 1, 4, 6, 5, 2, 5, 6, 7, 0, 1, 2, 3, 4]
    m.CreateFaceVertexCountsAttr(counts)
    m.CreateFaceVertexIndicesAttr(idx)
    m.CreateHoleIndicesAttr([4])
    m.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    pv = UsdGeom.PrimvarsAPI(m)
    st = pv.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    st.SetIndices([i % 4 for i in range(len(idx))])
    nrm = pv.CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.uniform)
    nrm.Set([(0, 0, 1)] * 5)
    mat_a = UsdShade.Material.Define(stage, "/Looks/A")
    sh = UsdShade.Shader.Define(stage, "/Looks/A/S")
    sh.CreateIdAttr("UsdPreviewSurface")
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set((0.8, 0.1, 0.1))
    sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.3)
    mat_a.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    mat_b = UsdShade.Material.Define(stage, "/Looks/B")
    shb = UsdShade.Shader.Define(stage, "/Looks/B/S")
    shb.CreateIdAttr("UsdPreviewSurface")
    shb.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(1.0)
    mat_b.CreateSurfaceOutput().ConnectToSource(shb.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat_a)
    subset = UsdGeom.Subset.CreateGeomSubset(m, "pent", UsdGeom.Tokens.face, [1], "materialBind")
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(mat_b)
    stage.GetRootLayer().Save()
    rep = info(petzval, path)
    (mesh,) = rep["meshes"]
    valid = [c for i, c in enumerate(counts) if c >= 3 and i != 4]
    assert mesh["triangles"] == sum(c - 2 for c in valid) == 6
    assert mesh["degenerate_faces"] == 1 and mesh["hole_faces"] == 1
    assert mesh["vertices"] == sum(valid)  # uniform/faceVarying primvars: one vertex per corner
    assert any("fewer than 3 vertices" in w for w in rep["warnings"])
    names = {mat["name"]: mat for mat in rep["materials"]}
    assert names["/Looks/A"]["base_color"][:3] == pytest.approx([0.8, 0.1, 0.1])
    assert names["/Looks/A"]["roughness"] == pytest.approx(0.3)
    assert names["/Looks/B"]["metallic"] == 1.0


def test_camera_fallbacks_and_units(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "cam.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.Camera.Define(stage, "/Fallback")
    c = UsdGeom.Camera.Define(stage, "/Authored")
    c.AddTranslateOp().Set((0, 100, 500))
    c.CreateFocalLengthAttr(35.0)
    c.CreateHorizontalApertureAttr(36.0)
    c.CreateVerticalApertureAttr(24.0)
    c.CreateHorizontalApertureOffsetAttr(2.0)
    c.CreateFStopAttr(2.8)
    c.CreateFocusDistanceAttr(250.0)
    c.CreateClippingRangeAttr((10, 5000))
    stage.GetRootLayer().Save()
    rep = info(petzval, path)
    cams = {c["path"]: c for c in rep["cameras"]}
    stage = Usd.Stage.Open(str(path))
    for p, ours in cams.items():
        cam = UsdGeom.Camera(stage.GetPrimAtPath(p))
        gf = cam.GetCamera(Usd.TimeCode.Default())  # pxr applies the schema fallbacks
        mm = 100 * 0.01  # mm per tenth of a scene unit
        assert ours["focal_length_mm"] == pytest.approx(gf.focalLength * mm)
        assert ours["horizontal_aperture_mm"] == pytest.approx(gf.horizontalAperture * mm)
        assert ours["vertical_aperture_mm"] == pytest.approx(gf.verticalAperture * mm)
        assert ours["horizontal_aperture_offset_mm"] == pytest.approx(gf.horizontalApertureOffset * mm)
        assert ours["f_stop"] == pytest.approx(gf.fStop)
        fd = gf.focusDistance * 0.01
        assert (ours["focus_distance_m"] or 0.0) == pytest.approx(fd)
        cr = gf.clippingRange
        assert ours["clipping_range_m"] == pytest.approx([cr.min * 0.01, cr.max * 0.01])
        m = np.array(ours["to_world"]).reshape(4, 4).T
        ref = np.array(UsdGeom.XformCache().GetLocalToWorldTransform(cam.GetPrim())).T
        np.testing.assert_allclose(m[:3, 3], ref[:3, 3] * 0.01, atol=1e-6)


def test_time_samples(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "anim.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(10)
    x = UsdGeom.Xform.Define(stage, "/X")
    t = x.AddTranslateOp()
    t.Set((0, 0, 0), 1)
    t.Set((10, 0, 0), 10)
    r = x.AddRotateYOp()
    r.Set(0, 1)
    r.Set(90, 10)
    quad(stage, "/X/Q")
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.CreateFocusDistanceAttr().Set(100.0, 1)
    cam.CreateFocusDistanceAttr().Set(300.0, 10)
    stage.GetRootLayer().Save()
    stage = Usd.Stage.Open(str(path))
    for frame in [1, 4.5, 10]:
        rep = info(petzval, path, frame)
        assert rep["time"] == frame
        assert_same_placements(stage, rep, Usd.TimeCode(frame))
        fd = UsdGeom.Camera(stage.GetPrimAtPath("/Cam")).GetFocusDistanceAttr().Get(frame)
        assert rep["cameras"][0]["focus_distance_m"] == pytest.approx(fd * 0.01)
    # no --frame: the stage's startTimeCode
    assert info(petzval, path)["time"] == 1


def lights_of(rep: dict, prim: str) -> list[float]:
    return next(li["value"] for li in rep["lights"] if li["prim"] == prim)


def test_lights_in_blender_units(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "lights.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    s = UsdLux.SphereLight.Define(stage, "/Point")
    s.CreateIntensityAttr(1000 / np.pi)
    s.CreateRadiusAttr(0.1)
    s.CreateNormalizeAttr(True)
    s.CreateExposureAttr(1.0)
    d = UsdLux.DistantLight.Define(stage, "/Sun")
    d.CreateIntensityAttr(0.75)
    d.CreateNormalizeAttr(True)
    r = UsdLux.RectLight.Define(stage, "/Area")
    r.CreateIntensityAttr(100 / np.pi)
    r.CreateWidthAttr(2.0)
    r.CreateHeightAttr(1.0)
    r.CreateNormalizeAttr(True)
    r.CreateColorAttr((1, 0.5, 0.25))
    dome = UsdLux.DomeLight.Define(stage, "/Dome")
    dome.CreateIntensityAttr(2.0)
    dome.CreateColorAttr((0.2, 0.3, 0.4))
    cyl = UsdLux.CylinderLight.Define(stage, "/Tube")
    cyl.CreateIntensityAttr(10.0)
    cyl.CreateRadiusAttr(0.1)
    cyl.CreateLengthAttr(2.0)
    cyl.CreateNormalizeAttr(True)
    stage.GetRootLayer().Save()
    rep = info(petzval, path)
    assert lights_of(rep, "/Tube") == pytest.approx([10 / (2 * np.pi * 0.1 * 2)] * 3, rel=1e-5)
    tube = next(m for m in rep["meshes"] if m["prim"] == "/Tube")
    np.testing.assert_allclose(tube["bounds"], [[-1, -0.1, -0.1], [1, 0.1, 0.1]], atol=1e-6)
    lights = {li["prim"]: li for li in rep["lights"]}
    # a 1000 W Blender point light (exposure +1 doubles it): 2 · 1000 / 4π W/sr
    assert lights["/Point"]["value"] == pytest.approx([2000 / (4 * np.pi)] * 3, rel=1e-5)
    assert lights["/Sun"]["value"] == pytest.approx([3.0] * 3)
    # a 100 W 2 m² area light: radiance 100 / (π · 2)
    assert lights["/Area"]["value"] == pytest.approx([100 / (2 * np.pi) * c for c in (1, 0.5, 0.25)], rel=1e-5)
    assert rep["environment"]["constant"] == pytest.approx([0.4, 0.6, 0.8])


def test_set_lens_composes_in_pxr_and_is_read_back(petzval: Path, tmp_path: Path) -> None:
    shot = tmp_path / "shot.usda"
    stage = Usd.Stage.CreateNew(str(shot))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetStartTimeCode(1001)
    UsdGeom.Camera.Define(stage, "/Rig/Cam")
    stage.GetRootLayer().Save()
    lens = tmp_path / "fitted.toml"
    lens.write_text(run(petzval, "lens", "export", "double-gauss-50mm").stdout)
    out = tmp_path / "lens.usda"
    run(
        petzval,
        "usd",
        "set-lens",
        str(shot),
        "--camera",
        "/Rig/Cam",
        "--lens",
        str(lens),
        "-o",
        str(out),
        "--tilt-x",
        "3",
        "--blades",
        "6",
    )
    composed = Usd.Stage.Open(str(out))
    # stage metadata lives on the root layer: set-lens carries the shot's over
    assert UsdGeom.GetStageMetersPerUnit(composed) == 1.0
    assert UsdGeom.GetStageUpAxis(composed) == UsdGeom.Tokens.z
    assert composed.GetStartTimeCode() == 1001
    prim = composed.GetPrimAtPath("/Rig/Cam")
    assert prim.IsA(UsdGeom.Camera)
    assert "PetzvalLensAPI" in prim.GetPrimTypeInfo().GetAppliedAPISchemas() or "PetzvalLensAPI" in (
        prim.GetMetadata("apiSchemas").GetAddedOrExplicitItems()
    )
    asset = prim.GetAttribute("petzval:lens").Get()
    assert Path(asset.resolvedPath).resolve() == lens.resolve()
    rep = info(petzval, out)
    pz = rep["cameras"][0]["petzval"]
    assert Path(pz["lens"]).resolve() == lens.resolve()
    assert pz["tilt_x_deg"] == 3 and pz["blades"] == 6
    # a camera that does not exist
    r = run(
        petzval,
        "usd",
        "set-lens",
        str(shot),
        "--camera",
        "/Nope",
        "--lens",
        "thin",
        "-o",
        str(tmp_path / "x.usda"),
        ok=False,
    )
    assert r.returncode != 0 and "/Nope" in r.stderr


def test_bad_input_names_layer_prim_attribute(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "bad.usda"
    path.write_text(
        '#usda 1.0\n(\n metersPerUnit = 1\n)\ndef Mesh "M"\n{\n'
        "    point3f[] points = [(0,0,0),(1,0,0),(1,1,0)]\n"
        "    int[] faceVertexCounts = [3]\n"
        '    string faceVertexIndices = "oops"\n}\n'
    )
    r = run(petzval, "usd", "info", str(path), ok=False)
    assert r.returncode != 0
    assert "bad.usda" in r.stderr and "/M.faceVertexIndices" in r.stderr
    # out-of-range index
    path.write_text(
        '#usda 1.0\ndef Mesh "M"\n{\n    point3f[] points = [(0,0,0),(1,0,0),(1,1,0)]\n'
        "    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 7]\n}\n"
    )
    r = run(petzval, "usd", "info", str(path), ok=False)
    assert "/M.faceVertexIndices" in r.stderr and "outside" in r.stderr
    # `render` names the shot once, not once as given and again as the layer
    r = run(petzval, "render", str(path), "-o", str(tmp_path / "x.exr"), ok=False)
    assert "/M.faceVertexIndices" in r.stderr and r.stderr.count("bad.usda") == 1, r.stderr
    # a missing reference is a listed warning; the rest loads
    path.write_text(
        '#usda 1.0\ndef Xform "A" (references = @./missing.usda@)\n{\n}\n'
        'def Mesh "M"\n{\n    point3f[] points = [(0,0,0),(1,0,0),(1,1,0)]\n'
        "    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 2]\n}\n"
    )
    rep = info(petzval, path)
    assert rep["instance_count"] == 1
    assert any("missing.usda" in w for w in rep["warnings"]), rep["warnings"]
    # a file that is not USD, and one that does not exist
    (tmp_path / "junk.usda").write_text("#usda 1.0\ndef Mesh (((\n")
    r = run(petzval, "usd", "info", str(tmp_path / "junk.usda"), ok=False)
    assert r.returncode != 0 and "junk.usda" in r.stderr
    r = run(petzval, "usd", "info", str(tmp_path / "none.usdc"), ok=False)
    assert r.returncode != 0 and "none.usdc" in r.stderr
    # issue 12: a light beyond the brightest value the film can sum names its prim and attribute
    (tmp_path / "sun.usda").write_text(
        '#usda 1.0\ndef SphereLight "Lamp"\n{\n    float inputs:intensity = 1e30\n'
        "    float inputs:exposure = 40\n}\n"
    )
    r = run(petzval, "usd", "info", str(tmp_path / "sun.usda"), ok=False)
    assert r.returncode != 0 and "/Lamp" in r.stderr and "inputs:intensity" in r.stderr, r.stderr
    assert "panicked" not in r.stderr
    # nested point instancers that expand to 16 M placed meshes from a 100 kB file: refused up front
    n = 4000
    pos = ",".join(f"({i % 100},{i // 100},0)" for i in range(n))
    idx = ",".join("0" for _ in range(n))
    (tmp_path / "nest.usda").write_text(
        f'#usda 1.0\ndef PointInstancer "Outer"\n{{\n rel prototypes = </Outer/Protos/Inner>\n'
        f" int[] protoIndices = [{idx}]\n point3f[] positions = [{pos}]\n"
        f' def Scope "Protos"\n {{\n  def PointInstancer "Inner"\n  {{\n'
        f"   rel prototypes = </Outer/Protos/Inner/P/Cube>\n   int[] protoIndices = [{idx}]\n"
        f'   point3f[] positions = [{pos}]\n   def Scope "P"\n   {{\n    def Cube "Cube"\n    {{\n    }}\n'
        "   }\n  }\n }\n}\n"
    )
    r = run(petzval, "usd", "info", str(tmp_path / "nest.usda"), ok=False)
    assert r.returncode != 0 and "/Outer.protoIndices" in r.stderr and "10000000" in r.stderr, r.stderr


def test_render_usd_shot_through_petzval_lens_api(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "shot.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    g = quad(stage, "/Ground")
    g.AddTranslateOp().Set((-2, -2, -3))
    g.AddScaleOp().Set((4, 4, 1))
    dome = UsdLux.DomeLight.Define(stage, "/Env")
    dome.CreateIntensityAttr(1.0)
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.CreateFocalLengthAttr(0.5)  # 50 mm at metersPerUnit 1 (tenths of a metre)
    cam.CreateHorizontalApertureAttr(0.36)
    cam.CreateVerticalApertureAttr(0.24)
    cam.CreateFStopAttr(2.8)
    cam.CreateFocusDistanceAttr(3.0)
    prim = cam.GetPrim()
    prim.AddAppliedSchema("PetzvalLensAPI")
    prim.CreateAttribute("petzval:lens", Sdf.ValueTypeNames.Asset).Set("double-gauss-50mm")
    prim.CreateAttribute("petzval:lensModel", Sdf.ValueTypeNames.Token).Set("thick")
    prim.CreateAttribute("petzval:aperture:blades", Sdf.ValueTypeNames.Int).Set(6)
    stage.GetRootLayer().Save()
    out = tmp_path / "f.exr"
    r = run(
        petzval,
        "render",
        str(path),
        "--camera",
        "/Cam",
        "-o",
        str(out),
        "--resolution",
        "48x32",
        "--spp",
        "2",
        "--no-png",
    )
    assert out.is_file()
    head = out.read_bytes()[:8192]
    assert b"usdCamera" in head and b"/Cam" in head and b"double-gauss" in head
    assert "thick" in r.stderr or b"thick" in head
    r = run(petzval, "render", str(path), "--camera", "/Missing", "-o", str(tmp_path / "g.exr"), ok=False)
    assert r.returncode != 0 and "/Missing" in r.stderr and "/Cam" in r.stderr


def test_schema_and_docs_example(petzval: Path, tmp_path: Path) -> None:
    """usd/schema.usda parses in pxr and declares exactly the attributes (and fallbacks) the
    loader reads; the usda example in docs/usd.md opens in pxr and in petzval."""
    layer = Sdf.Layer.OpenAsAnonymous(str(REPO / "usd" / "schema.usda"))
    api = layer.GetPrimAtPath("/PetzvalLensAPI")
    declared = {p.name: p.default for p in api.properties}
    assert declared == {
        "petzval:lens": Sdf.AssetPath(""),
        "petzval:lensModel": "auto",
        "petzval:tolerancePx": 0.25,
        "petzval:tiltX": 0.0,
        "petzval:tiltY": 0.0,
        "petzval:aperture:blades": 0,
        "petzval:aperture:rotation": 0.0,
        "petzval:aperture:curvature": 0.0,
        "petzval:aperture:ratio": 1.0,
        "petzval:aperture:image": Sdf.AssetPath(""),
    }
    assert api.customData["apiSchemaType"] == "singleApply"
    doc = (REPO / "docs" / "usd.md").read_text()
    example = doc.split("```usda\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "example.usda"
    path.write_text(example)
    stage = Usd.Stage.Open(str(path))
    assert stage.GetPrimAtPath("/Cam").IsA(UsdGeom.Camera)
    rep = info(petzval, path)
    (cam,) = rep["cameras"]
    assert cam["focal_length_mm"] == pytest.approx(50.0)
    pz = cam["petzval"]
    assert pz["lens"] == "double-gauss-50mm" and pz["blades"] == 6 and pz["tilt_x_deg"] == 4
    assert pz["curvature"] == pytest.approx(0.3) and pz["rotation_deg"] == 15
    assert not rep["warnings"], rep["warnings"]
    out = tmp_path / "ex.exr"
    run(
        petzval,
        "render",
        str(path),
        "-o",
        str(out),
        "--resolution",
        "32x24",
        "--spp",
        "1",
        "--no-png",
        "--lens-model",
        "thick",
    )
    assert b"double-gauss" in out.read_bytes()[:8192]


def test_render_settings_camera_resolution_product(petzval: Path, tmp_path: Path) -> None:
    import OpenEXR
    from pxr import UsdRender

    path = tmp_path / "rs.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    q = quad(stage, "/Q")
    q.AddTranslateOp().Set((-0.5, -0.5, -3))
    UsdLux.DomeLight.Define(stage, "/Env")
    for name in ("A", "B"):
        c = UsdGeom.Camera.Define(stage, f"/{name}")
        c.CreateFocalLengthAttr(0.5)
        c.CreateHorizontalApertureAttr(0.36)
        c.CreateVerticalApertureAttr(0.24)
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateCameraRel().SetTargets(["/A"])
    rs.CreateResolutionAttr(Gf.Vec2i(64, 48))
    prod = UsdRender.Product.Define(stage, "/Render/Product")
    prod.CreateCameraRel().SetTargets(["/B"])  # the product's camera wins
    prod.CreateResolutionAttr(Gf.Vec2i(40, 30))
    prod.CreateProductNameAttr(str(tmp_path / "beauty.####.exr"))
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    stage.GetRootLayer().Save()
    r = run(petzval, "render", str(path), "--frame", "7", "--spp", "1", "--no-png")
    out = tmp_path / "beauty.0007.exr"
    assert out.is_file(), r.stderr
    with OpenEXR.File(str(out)) as f:
        h = f.header()
        assert h["petzval/usdCamera"] == "/B"
        dw = h["dataWindow"]
        assert (dw[1][0] - dw[0][0] + 1, dw[1][1] - dw[0][1] + 1) == (40, 30)
    # the command line overrides the settings; a settings path that is not a RenderSettings fails
    out2 = tmp_path / "cli.exr"
    run(
        petzval,
        "render",
        str(path),
        "--camera",
        "/A",
        "--resolution",
        "20x10",
        "--spp",
        "1",
        "--no-png",
        "-o",
        str(out2),
    )
    with OpenEXR.File(str(out2)) as f:
        assert f.header()["petzval/usdCamera"] == "/A"
    r = run(petzval, "render", str(path), "--settings", "/Q", "--spp", "1", "-o", str(tmp_path / "x.exr"), ok=False)
    assert r.returncode != 0 and "/Q" in r.stderr and "RenderSettings" in r.stderr


def test_every_render_product_renders(petzval: Path, tmp_path: Path) -> None:
    """Two RenderProducts with their own cameras, resolutions and productNames: two EXRs."""
    import OpenEXR
    from pxr import UsdRender

    path = tmp_path / "products.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    q = quad(stage, "/Q")
    q.AddTranslateOp().Set((-0.5, -0.5, -3))
    UsdLux.DomeLight.Define(stage, "/Env")
    for name in ("A", "B"):
        UsdGeom.Camera.Define(stage, f"/{name}")
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateCameraRel().SetTargets(["/A"])
    rs.CreateResolutionAttr(Gf.Vec2i(32, 24))
    products = []
    for name, cam, res in (("main", "/A", (32, 24)), ("witness", "/B", (20, 10))):
        prod = UsdRender.Product.Define(stage, f"/Render/{name}")
        prod.CreateCameraRel().SetTargets([cam])
        prod.CreateResolutionAttr(Gf.Vec2i(*res))
        prod.CreateProductNameAttr(str(tmp_path / f"{name}.exr"))
        products.append(prod.GetPath())
    rs.CreateProductsRel().SetTargets(products)
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    stage.GetRootLayer().Save()
    run(petzval, "render", str(path), "--spp", "1", "--no-png")
    for name, cam, res in (("main", "/A", (32, 24)), ("witness", "/B", (20, 10))):
        with OpenEXR.File(str(tmp_path / f"{name}.exr")) as f:
            h = f.header()
            assert h["petzval/usdCamera"] == cam, name
            dw = h["dataWindow"]
            assert (dw[1][0] - dw[0][0] + 1, dw[1][1] - dw[0][1] + 1) == res, name


def test_pixel_aspect_ratio_widens_the_frame_on_the_film(petzval: Path, tmp_path: Path) -> None:
    """RenderSettings pixelAspectRatio: a 40×30 frame of 2:1 pixels covers a 80:30 part of the
    film back (expandAperture: 36 × 24 mm grows to 64 × 24 mm), square pixels 36 × 27 mm."""
    import OpenEXR
    from pxr import UsdRender

    path, stage = _window_stage(tmp_path, "par")
    UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings")).CreatePixelAspectRatioAttr(2.0)
    stage.GetRootLayer().Save()

    def sensor(*extra: str) -> tuple[float, float]:
        out = tmp_path / f"par{len(extra)}.exr"
        run(petzval, "render", str(path), "--spp", "1", "--no-png", "-o", str(out), *extra)
        with OpenEXR.File(str(out)) as f:
            w, h = f.header()["petzval/sensorMM"].split("x")
        return float(w), float(h)

    assert sensor() == pytest.approx((64.0, 24.0), abs=1e-3)
    assert sensor("--pixel-aspect", "1") == pytest.approx((36.0, 27.0), abs=1e-3)


def _window_stage(tmp_path: Path, name: str) -> tuple[Path, Usd.Stage]:
    """A 50 mm camera (36 × 24 mm aperture, no depth of field) facing a grey quad at 3 m, a
    second quad right of the frame (x 1.3–1.6 m: film x 21.7–26.7 mm, beyond the frame's
    18 mm half-width) and a dome light; RenderSettings at 40 × 30 px."""
    from pxr import UsdRender

    path = tmp_path / f"{name}.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    q = quad(stage, "/Q")
    q.AddTranslateOp().Set((-0.5, -0.5, -3))
    side = quad(stage, "/Side")
    side.AddTranslateOp().Set((1.3, -0.5, -3))
    side.AddScaleOp().Set((0.3, 1, 1))
    UsdLux.DomeLight.Define(stage, "/Env")
    c = UsdGeom.Camera.Define(stage, "/Cam")
    c.CreateFocalLengthAttr(0.5)
    c.CreateHorizontalApertureAttr(0.36)
    c.CreateVerticalApertureAttr(0.24)
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateCameraRel().SetTargets(["/Cam"])
    rs.CreateResolutionAttr(Gf.Vec2i(40, 30))
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    return path, stage


def _exr(path: Path) -> tuple[dict, np.ndarray]:
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        h = dict(f.header())
        rgb = np.asarray(f.channels()["RGBA"].pixels)[..., :3]
    return h, rgb.astype(np.float64)


def test_data_window_crops_and_overscans(petzval: Path, tmp_path: Path) -> None:
    """UsdRender dataWindowNDC: a window inside the frame renders exactly those pixels of the
    full render (the EXR's data window inside its 40 × 30 display window, pixels whose centres
    lie in the window); a window beyond it renders overscan, continuing the pixel grid: the
    frame's pixels as before and the quad right of the frame where the pinhole puts it."""
    path, stage = _window_stage(tmp_path, "window")
    stage.GetRootLayer().Save()
    common = ["--spp", "4", "--no-png", "--seed", "3"]
    full = tmp_path / "full.exr"
    run(petzval, "render", str(path), "-o", str(full), *common)
    hf, img = _exr(full)
    assert (hf["displayWindow"][0].tolist(), hf["displayWindow"][1].tolist()) == ([0, 0], [39, 29])
    # 1. A crop, authored on the settings: columns with centres in [0.25, 0.75) → 10..29; rows
    #    with centres (y up) in (0.25, 0.75] → 7..21 (the top-left rule).
    from pxr import UsdRender

    rs = UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings"))
    rs.CreateDataWindowNDCAttr(Gf.Vec4f(0.25, 0.25, 0.75, 0.75))
    stage.GetRootLayer().Save()
    crop = tmp_path / "crop.exr"
    run(petzval, "render", str(path), "-o", str(crop), *common)
    hc, cimg = _exr(crop)
    assert (hc["dataWindow"][0].tolist(), hc["dataWindow"][1].tolist()) == ([10, 7], [29, 21])
    assert (hc["displayWindow"][0].tolist(), hc["displayWindow"][1].tolist()) == ([0, 0], [39, 29])
    assert np.array_equal(cimg, img[7:22, 10:30]), "a crop renders the full render's pixels"
    # 2. Overscan, authored on a product over the settings': a quarter frame on each side.
    prod = UsdRender.Product.Define(stage, "/Render/Product")
    prod.CreateProductNameAttr(str(tmp_path / "over.exr"))
    prod.CreateDataWindowNDCAttr(Gf.Vec4f(-0.25, 0.0, 1.25, 1.0))
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    stage.GetRootLayer().Save()
    run(petzval, "render", str(path), *common)
    ho, oimg = _exr(tmp_path / "over.exr")
    assert (ho["dataWindow"][0].tolist(), ho["dataWindow"][1].tolist()) == ([-10, 0], [49, 29])
    assert oimg.shape == (30, 60, 3)
    inner = oimg[:, 10:50]
    rel = np.abs(inner - img) / np.maximum(img, 1e-3)
    assert np.median(rel) < 1e-5 and np.mean(rel < 1e-3) > 0.97, (np.median(rel), np.mean(rel < 1e-3))
    # the side quad: film x 21.67–26.67 mm at 0.9 mm per pixel → 24.1–29.6 px right of the
    # centre → frame columns 44.1–49.6 (overscan), rows 15 ± 9.3: darker there than the dome
    # above it (rows 0–2) in the same column; columns 43 and 49 take part of it through the
    # 3-pixel filter and are not asserted
    dark = [oimg[10:20, 10 + c].mean() < 0.5 * oimg[0:3, 10 + c].mean() for c in range(40, 50)]
    assert dark[0:3] == [False] * 3 and dark[4:9] == [True] * 5, dark
    assert not any(img[10:20, c].mean() < 0.5 * img[0:3, c].mean() for c in range(30, 40)), "not in the frame"
    # the command line's window wins over the product's; an empty one is refused
    run(petzval, "render", str(path), "--data-window", "0,0,1,1", *common)
    assert np.array_equal(_exr(tmp_path / "over.exr")[1], img)
    bad = ["-o", str(tmp_path / "bad.exr"), "--data-window", "0.3,0,0.31,1"]
    r = run(petzval, "render", str(path), *bad, *common, ok=False)
    assert r.returncode != 0 and "data_window" in r.stderr and "no pixel centre" in r.stderr, r.stderr
    assert not (tmp_path / "bad.exr").exists()


def test_aspect_ratio_conform_policies(petzval: Path, tmp_path: Path) -> None:
    """UsdRender aspectRatioConformPolicy fits the camera's 36 × 24 mm aperture to the image's
    aspect as the schema says: expand or crop the aperture, adjust its width or its height
    (keeping the other), or adjust the pixel aspect (recorded in the EXR's pixelAspectRatio)."""
    from pxr import UsdRender

    path, stage = _window_stage(tmp_path, "conform")
    rs = UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings"))
    policy = rs.CreateAspectRatioConformPolicyAttr("expandAperture")
    expected = {
        # 60 × 20 px: aspect 3, wider than the aperture's 1.5
        (60, 20): {
            "expandAperture": (72.0, 24.0),
            "cropAperture": (36.0, 12.0),
            "adjustApertureWidth": (72.0, 24.0),
            "adjustApertureHeight": (36.0, 12.0),
            "adjustPixelAspectRatio": (36.0, 24.0),
        },
        # 20 × 30 px: aspect 2/3, narrower
        (20, 30): {
            "expandAperture": (36.0, 54.0),
            "cropAperture": (16.0, 24.0),
            "adjustApertureWidth": (16.0, 24.0),
            "adjustApertureHeight": (36.0, 54.0),
            "adjustPixelAspectRatio": (36.0, 24.0),
        },
    }
    for (w, h), table in expected.items():
        rs.GetResolutionAttr().Set(Gf.Vec2i(w, h))
        for name, sensor in table.items():
            policy.Set(name)
            stage.GetRootLayer().Save()
            out = tmp_path / f"{name}_{w}x{h}.exr"
            run(petzval, "render", str(path), "--spp", "1", "--no-png", "-o", str(out))
            hd, _ = _exr(out)
            got = tuple(float(v) for v in hd["petzval/sensorMM"].split("x"))
            assert got == pytest.approx(sensor, abs=1e-3), (name, w, h, got)
            par = (36 / 24) * h / w if name == "adjustPixelAspectRatio" else 1.0
            assert hd["pixelAspectRatio"] == pytest.approx(par, rel=1e-6), (name, hd["pixelAspectRatio"])
            assert hd["petzval/aspectConform"] == name
    # the command line wins; an unknown policy names the attribute and the prim
    out = tmp_path / "cli.exr"
    run(petzval, "render", str(path), "--spp", "1", "--no-png", "-o", str(out), "--aspect-conform", "cropAperture")
    assert _exr(out)[0]["petzval/sensorMM"] == "16.000x24.000"
    policy.Set("squeeze")
    stage.GetRootLayer().Save()
    r = run(petzval, "render", str(path), "--spp", "1", "--no-png", "-o", str(tmp_path / "x.exr"), ok=False)
    assert "aspectRatioConformPolicy" in r.stderr and "/Render/Settings" in r.stderr and "squeeze" in r.stderr, r.stderr


def test_included_purposes_choose_the_geometry(petzval: Path, tmp_path: Path) -> None:
    """RenderSettings includedPurposes: by default render- and default-purpose geometry; with
    proxy included and render left out, the proxy subtree renders, and a mesh authored
    `render` inside it inherits the proxy purpose (UsdGeomImageable), while the render quad
    does not. `--purposes` overrides the settings."""
    from pxr import UsdRender

    path, stage = _window_stage(tmp_path, "purposes")
    UsdGeom.Imageable(stage.GetPrimAtPath("/Side")).CreatePurposeAttr("render")
    proxy = UsdGeom.Xform.Define(stage, "/Proxy")
    proxy.CreatePurposeAttr("proxy")
    for k in range(3):
        m = quad(stage, f"/Proxy/P{k}")
        if k == 0:
            UsdGeom.Imageable(m).CreatePurposeAttr("render")
    stage.GetRootLayer().Save()

    def triangles(*extra: str) -> int:
        r = run(petzval, "render", str(path), "--spp", "1", "--no-png", "-o", str(tmp_path / "p.exr"), *extra)
        line = next(ln for ln in r.stderr.splitlines() if ln.startswith("scene: "))
        return int(line.split()[1])

    assert triangles() == 4  # /Q and /Side
    rs = UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings"))
    rs.CreateIncludedPurposesAttr(["default", "proxy"])
    stage.GetRootLayer().Save()
    assert triangles() == 2 + 6  # /Q and the three proxy quads
    assert triangles("--purposes", "render") == 2  # /Side only
    r = run(petzval, "render", str(path), "--purposes", "default,final", "-o", str(tmp_path / "q.exr"), ok=False)
    assert "purposes" in r.stderr and "final" in r.stderr, r.stderr


def test_disable_depth_of_field_renders_the_thin_lens_as_a_pinhole(petzval: Path, tmp_path: Path) -> None:
    """UsdRender disableDepthOfField: the USD camera's thin lens (fStop 2, focused at 3 m)
    renders as a pinhole (the EXR's fNumber is inf); a product's false overrides the settings'
    true; `--no-dof` asks for the same from the command line."""
    from pxr import UsdRender

    path, stage = _window_stage(tmp_path, "nodof")
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/Cam"))
    cam.CreateFStopAttr(2.0)
    cam.CreateFocusDistanceAttr(3.0)
    rs = UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings"))
    stage.GetRootLayer().Save()

    def f_number(*extra: str) -> str:
        out = tmp_path / f"nodof{len(extra)}.exr"
        run(petzval, "render", str(path), "--spp", "1", "--no-png", "-o", str(out), *extra)
        return _exr(out)[0]["petzval/fNumber"]

    assert f_number() == "2.0000"
    assert f_number("--no-dof") == "inf"
    rs.CreateDisableDepthOfFieldAttr(True)
    stage.GetRootLayer().Save()
    assert f_number() == "inf"
    prod = UsdRender.Product.Define(stage, "/Render/Product")
    prod.CreateProductNameAttr(str(tmp_path / "nodof_product.exr"))
    prod.CreateDisableDepthOfFieldAttr(False)
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    stage.GetRootLayer().Save()
    run(petzval, "render", str(path), "--spp", "1", "--no-png")
    assert _exr(tmp_path / "nodof_product.exr")[0]["petzval/fNumber"] == "2.0000"


def test_render_vars_choose_the_exr_channels(petzval: Path, tmp_path: Path) -> None:
    """RenderVars' sourceName picks the EXR's channels (colour always; normal, albedo; an unknown
    one is listed as skipped); --aovs overrides them."""
    import OpenEXR
    from pxr import UsdRender

    path = tmp_path / "vars.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    q = quad(stage, "/Q")
    q.AddTranslateOp().Set((-0.5, -0.5, -3))
    UsdLux.DomeLight.Define(stage, "/Env")
    UsdGeom.Camera.Define(stage, "/Cam")
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateCameraRel().SetTargets(["/Cam"])
    rs.CreateResolutionAttr(Gf.Vec2i(24, 16))
    prod = UsdRender.Product.Define(stage, "/Render/Product")
    prod.CreateProductNameAttr(str(tmp_path / "vars.exr"))
    names = []
    for name, source in (("beauty", "Ci"), ("n", "normal"), ("alb", "albedo"), ("crypto", "cryptomatte")):
        v = UsdRender.Var.Define(stage, f"/Render/Vars/{name}")
        v.CreateSourceNameAttr(source)
        names.append(v.GetPath())
    prod.CreateOrderedVarsRel().SetTargets(names)
    rs.CreateProductsRel().SetTargets([prod.GetPath()])
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    stage.GetRootLayer().Save()

    def channels(exr: Path) -> set[str]:
        with OpenEXR.File(str(exr)) as f:
            return (
                set(f.header()["channels"].keys())
                if isinstance(f.header()["channels"], dict)
                else {c.name for c in f.header()["channels"]}
            )

    r = run(petzval, "render", str(path), "--spp", "1", "--no-png")
    assert "cryptomatte" in r.stderr and "skipped" in r.stderr, r.stderr
    got = channels(tmp_path / "vars.exr")
    assert {"R", "G", "B"} <= got, got
    assert any("normal" in c.lower() or c.startswith("N.") for c in got), got
    assert any("albedo" in c.lower() for c in got), got
    assert not any("depth" in c.lower() or c == "Z" for c in got), got
    # --aovs overrides the RenderVars
    run(petzval, "render", str(path), "--spp", "1", "--no-png", "--aovs", "depth", "-o", str(tmp_path / "d.exr"))
    got = channels(tmp_path / "d.exr")
    assert not any("albedo" in c.lower() for c in got), got


def test_petzval_lens_api_changes_the_render(petzval: Path, tmp_path: Path) -> None:
    """Lens, tilt and blades authored on the camera (through set-lens layers) reach the render:
    the EXR metadata reports them and the images differ from the plain thin-lens shot."""
    import OpenEXR

    path = tmp_path / "shot.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    for i in range(5):  # small bright squares at several depths, out of focus
        q = quad(stage, f"/Q{i}")
        q.AddTranslateOp().Set((-1.0 + 0.5 * i, -0.2 + 0.1 * i, -1.5 - 1.5 * i))
        q.AddScaleOp().Set((0.08, 0.08, 1))
        mat = UsdShade.Material.Define(stage, f"/Looks/E{i}")
        sh = UsdShade.Shader.Define(stage, f"/Looks/E{i}/S")
        sh.CreateIdAttr("UsdPreviewSurface")
        sh.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set((20, 20, 20))
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        UsdShade.MaterialBindingAPI.Apply(q.GetPrim()).Bind(mat)
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.CreateFocalLengthAttr(0.5)
    cam.CreateHorizontalApertureAttr(0.36)
    cam.CreateVerticalApertureAttr(0.24)
    cam.CreateFStopAttr(2.8)
    cam.CreateFocusDistanceAttr(1.0)
    stage.GetRootLayer().Save()

    def render(shot: Path, name: str) -> tuple[np.ndarray, dict]:
        out = tmp_path / f"{name}.exr"
        run(petzval, "render", str(shot), "-o", str(out), "--resolution", "64x48", "--spp", "16", "--no-png")
        with OpenEXR.File(str(out), separate_channels=True) as f:
            h = dict(f.header())
            rgb = np.stack([np.asarray(f.channels()[c].pixels) for c in ("R", "G", "B")], axis=-1)
        return rgb.astype(float), h

    base, hb = render(path, "base")
    variants = {
        "lens": ["--lens", "double-gauss-50mm", "--lens-model", "thick"],
        "tilt": ["--lens", "thin", "--tilt-x", "8"],
        "blades": ["--lens", "thin", "--blades", "5"],
    }
    for name, extra in variants.items():
        layer = tmp_path / f"{name}.usda"
        run(petzval, "usd", "set-lens", str(path), "--camera", "/Cam", "-o", str(layer), *extra)
        img, h = render(layer, name)
        diff = np.abs(img - base).mean() / base.mean()
        assert diff > 0.02, (name, diff)
        if name == "lens":
            assert "double-gauss" in h["petzval/lens"]
        if name == "tilt":
            assert float(h["petzval/tiltXDeg"]) == 8.0
    assert float(hb["petzval/fNumber"]) == pytest.approx(2.8)


def test_intrinsic_shapes_fill_pxr_extents(petzval: Path, tmp_path: Path) -> None:
    path = tmp_path / "shapes.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Cube.Define(stage, "/Cube").CreateSizeAttr(3.0)
    UsdGeom.Sphere.Define(stage, "/Sphere")
    for axis in ("X", "Y", "Z"):
        c = UsdGeom.Cylinder.Define(stage, f"/Cyl{axis}")
        c.CreateAxisAttr(axis)
        c.CreateRadiusAttr(0.5)
        c.CreateHeightAttr(3.0)
        k = UsdGeom.Cone.Define(stage, f"/Cone{axis}")
        k.CreateAxisAttr(axis)
        k.CreateHeightAttr(1.5)
        UsdGeom.Capsule.Define(stage, f"/Capsule{axis}").CreateAxisAttr(axis)
        UsdGeom.Plane.Define(stage, f"/Plane{axis}").CreateAxisAttr(axis)
    stage.GetRootLayer().Save()
    rep = info(petzval, path)
    assert not any("not supported" in w for w in rep["warnings"])
    for m in rep["meshes"]:
        prim = stage.GetPrimAtPath(m["prim"])
        ext = UsdGeom.Boundable.ComputeExtentFromPlugins(UsdGeom.Boundable(prim), Usd.TimeCode.Default())
        np.testing.assert_allclose(np.array(m["bounds"]), np.array(ext), atol=1e-5, err_msg=m["prim"])
        assert m["triangles"] > 0


def test_dome_map_inside_a_usdz_package(petzval: Path, tmp_path: Path) -> None:
    """A DomeLight's EXR inside a usdz package (pxr's UsdUtils packs it; Blender's usdz export of a
    world texture is this) is read from the archive as an environment map, as beside a usda; it
    was listed as missing and the dome rendered magenta."""
    import OpenEXR
    from pxr import UsdUtils

    (tmp_path / "env").mkdir()
    rgb = np.full((8, 16, 3), 0.5, dtype=np.float32)
    rgb[:4] = (1.0, 0.8, 0.6)  # a brighter upper half
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, {"RGB": rgb}) as f:
        f.write(str(tmp_path / "env" / "sky.exr"))
    src = tmp_path / "dome.usda"
    stage = Usd.Stage.CreateNew(str(src))
    quad(stage, "/Q")
    dome = UsdLux.DomeLight.Define(stage, "/Env")
    dome.CreateTextureFileAttr("./env/sky.exr")
    UsdGeom.Camera.Define(stage, "/Cam")
    stage.GetRootLayer().Save()
    usdz = tmp_path / "dome.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(src)), str(usdz))
    for path in (src, usdz):
        rep = info(petzval, path)
        assert not rep["warnings"], (path, rep["warnings"])
        assert rep["environment"] == "map", (path, rep["environment"])
    # both render the same image
    means = []
    for path in (src, usdz):
        out = tmp_path / f"{path.suffix[1:]}.exr"
        run(petzval, "render", str(path), "-o", str(out), "--resolution", "24x16", "--spp", "4", "--no-png")
        with OpenEXR.File(str(out)) as f:
            means.append(float(np.mean(f.channels()["RGBA"].pixels[..., :3])))
    assert means[0] == means[1] and means[0] > 0.1, means


def test_textures_from_files_and_usdz_packages(petzval: Path, tmp_path: Path) -> None:
    import zlib

    def png(path: Path, rgb: tuple[int, int, int]) -> None:
        import struct

        raw = b"".join(b"\x00" + bytes(rgb) * 2 for _ in range(2))

        def chunk(t: bytes, d: bytes) -> bytes:
            return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))

        ihdr = struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0)
        body = chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
        path.write_bytes(b"\x89PNG\r\n\x1a\n" + body)

    (tmp_path / "tex").mkdir()
    png(tmp_path / "tex" / "red.png", (255, 0, 0))
    src = tmp_path / "tex.usda"
    stage = Usd.Stage.CreateNew(str(src))
    m = quad(stage, "/Q")
    UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
        [(0, 0), (1, 0), (1, 1), (0, 1)]
    )
    mat = UsdShade.Material.Define(stage, "/Looks/M")
    sh = UsdShade.Shader.Define(stage, "/Looks/M/S")
    sh.CreateIdAttr("UsdPreviewSurface")
    tex = UsdShade.Shader.Define(stage, "/Looks/M/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./tex/red.png")
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)
    stage.GetRootLayer().Save()
    from pxr import UsdUtils

    usdz = tmp_path / "tex.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(src)), str(usdz))
    for path in (src, usdz):
        rep = info(petzval, path)
        assert not rep["warnings"], (path, rep["warnings"])
        (mat_rep,) = [x for x in rep["materials"] if x["name"] == "/Looks/M"]
        assert mat_rep["base_color_texture"] and "red.png" in mat_rep["base_color_texture"]
    # the texture's UsdPrimvarReader_float2 names the primvar the mesh's coordinates come from
    stage = Usd.Stage.Open(str(src))
    UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Q")).CreatePrimvar(
        "uvAlt", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    ).Set([(0, 0), (2, 0), (2, 2), (0, 2)])
    reader = UsdShade.Shader.Define(stage, "/Looks/M/Reader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("uvAlt")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    UsdShade.Shader(stage.GetPrimAtPath("/Looks/M/Tex")).CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.ConnectableAPI(), "result"
    )
    stage.GetRootLayer().Save()
    assert info(petzval, src)["meshes"][0]["st_primvar"] == "primvars:uvAlt"
    # UsdTransform2d between the reader and the texture: applied (st' = R·(st⊙scale) + t, as the
    # UsdPreviewSurface spec defines it), in the renderer's top-left coordinates (v = 1 − t)
    xf = UsdShade.Shader.Define(stage, "/Looks/M/Xf")
    xf.CreateIdAttr("UsdTransform2d")
    xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    xf.CreateInput("rotation", Sdf.ValueTypeNames.Float).Set(30.0)
    xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set((2.0, 0.5))
    xf.CreateInput("translation", Sdf.ValueTypeNames.Float2).Set((0.25, -0.1))
    xf.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    UsdShade.Shader(stage.GetPrimAtPath("/Looks/M/Tex")).GetInput("st").ConnectToSource(xf.ConnectableAPI(), "result")
    stage.GetRootLayer().Save()
    rep = info(petzval, src)
    assert not [w for w in rep["warnings"] if "Transform2d" in w], rep["warnings"]
    (mat_rep,) = [x for x in rep["materials"] if x["name"] == "/Looks/M"]
    m00, m01, m10, m11, ox, oy = mat_rep["base_color_uv_transform"]
    th = np.radians(30.0)
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    for st in ([0.0, 0.0], [1.0, 0.0], [0.3, 0.8]):
        st2 = rot @ (np.array(st) * [2.0, 0.5]) + [0.25, -0.1]
        uv = np.array([st[0], 1.0 - st[1]])
        uv2 = np.array([[m00, m01], [m10, m11]]) @ uv + [ox, oy]
        assert np.allclose(uv2, [st2[0], 1.0 - st2[1]], atol=1e-5), (st, uv2, st2)
    # a missing texture: a warning naming the shader and the file, and magenta
    (tmp_path / "tex" / "red.png").unlink()
    rep = info(petzval, src)
    assert any("/Looks/M/Tex" in w and "red.png" in w for w in rep["warnings"]), rep["warnings"]


def test_colour_primvars_render_as_pxr_flattens_them(petzval: Path, tmp_path: Path) -> None:
    """A 4 × 3 grid whose UsdPreviewSurface takes diffuseColor from a UsdPrimvarReader_float3
    reading an indexed faceVarying primvar (one colour per face through `indices`), seen from
    above through an orthographic camera under a white dome: a white-based Lambertian plane
    under a uniform sky reflects its colour, so each face's pixels must show the colour pxr's
    `ComputeFlattened` gives its corners (within 3 %, 64 spp). Before session 27 the reader was
    taken for a texture and the grid rendered magenta."""
    import OpenEXR

    src = tmp_path / "painted.usda"
    stage = Usd.Stage.CreateNew(str(src))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    nx, ny = 4, 3
    m = UsdGeom.Mesh.Define(stage, "/Grid")
    m.CreatePointsAttr([(x, y, 0) for y in range(ny + 1) for x in range(nx + 1)])
    m.CreateFaceVertexCountsAttr([4] * (nx * ny))
    idx = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            idx += [a, a + 1, a + nx + 2, a + nx + 1]
    m.CreateFaceVertexIndicesAttr(idx)
    rng = np.random.default_rng(7)
    palette = [tuple(float(c) for c in rng.uniform(0.1, 0.9, 3)) for _ in range(5)]
    cd = UsdGeom.PrimvarsAPI(m).CreatePrimvar("Cd", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.faceVarying)
    cd.Set(palette)
    cd.SetIndices([f % len(palette) for f in range(nx * ny) for _ in range(4)])
    mat = UsdShade.Material.Define(stage, "/Looks/Paint")
    sh = UsdShade.Shader.Define(stage, "/Looks/Paint/S")
    sh.CreateIdAttr("UsdPreviewSurface")
    sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(1.0)
    sh.CreateInput("specular", Sdf.ValueTypeNames.Float).Set(0.0)
    reader = UsdShade.Shader.Define(stage, "/Looks/Paint/Reader")
    reader.CreateIdAttr("UsdPrimvarReader_float3")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("Cd")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float3)
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(reader.ConnectableAPI(), "result")
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    cam.CreateHorizontalApertureAttr(10.0 * nx)
    cam.CreateVerticalApertureAttr(10.0 * ny)
    UsdGeom.Xformable(cam).AddTranslateOp().Set(Gf.Vec3d(nx / 2, ny / 2, 10.0))
    UsdLux.DomeLight.Define(stage, "/Sky").CreateIntensityAttr(1.0)
    stage.GetRootLayer().Save()
    # pxr's flattened values: each face's four corners
    flat = np.array(UsdGeom.PrimvarsAPI(m).GetPrimvar("Cd").ComputeFlattened()).reshape(nx * ny, 4, 3)
    assert np.all(flat == flat[:, :1])
    rep = info(petzval, src)
    assert not rep["warnings"], rep["warnings"]
    assert rep["meshes"][0]["color_primvar"] == "primvars:Cd"
    px = 16
    out = tmp_path / "painted.exr"
    run(petzval, "render", str(src), "--camera", "/Cam", "--resolution", f"{nx * px}x{ny * px}", "--spp", "64",
        "--no-png", "-o", str(out))  # fmt: skip
    with OpenEXR.File(str(out), separate_channels=True) as f:
        ch = f.channels()
        img = np.stack([np.asarray(ch[c].pixels, dtype=np.float64) for c in ("R", "G", "B")], axis=-1)
    for f in range(nx * ny):
        i, j = f % nx, f // nx
        rows = slice((ny - 1 - j) * px + 4, (ny - j) * px - 4)
        cols = slice(i * px + 4, (i + 1) * px - 4)
        got = img[rows, cols].reshape(-1, 3).mean(axis=0)
        assert np.allclose(got, flat[f, 0], rtol=0.03, atol=0.005), (f, got, flat[f, 0])
