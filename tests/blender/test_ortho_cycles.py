"""Orthographic cameras against Cycles: tests/blender's scene through ``OrthoCam`` (Blender's
Orthographic type, Orthographic Scale 2.2 m, AUTO fit, shifted, clip start 0.5 m), rendered by
Cycles and by petzval from

* the GLB export: Blender's exporter writes ``xmag``/``ymag`` = half the window (the larger side
  spans the Orthographic Scale); glTF has no shift, so it is passed as ``--shift-x/-y`` in mm of
  the 36 mm sensor width, as for a perspective camera;
* a USD stage: Blender 5.0's USD exporter writes an orthographic camera as a bare Xform, so the
  camera is authored with Pixar's ``pxr`` (usd-core) into Blender's USD export of the scene:
  ``projection = "orthographic"`` with the window in tenths of a scene unit (GfCamera's
  convention, checked here against ``GfCamera.frustum``), the shift as aperture offsets. The
  stage's colours cannot match Cycles block by block (the checker's Closest interpolation is
  lost by the USD export: test_usd_export_cycles.py's strict xfail; by hand, mean z² 15.9 here),
  so the USD camera is checked by its depth image, which must equal the GLB camera's.

Metric and tolerances are test_cycles_match.py's (8 x 8 block z-test over both seeds: mean z² ≤
1.5, every |z| ≤ 5; image mean within 1 % per channel). Negative control: the window 3 % too
wide must be rejected by the same test.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from test_cycles_match import MEAN_TOL, SEEDS, _block_verdict, _fmt_verdict, _passes

import blender_compare as B
import blender_scenes as S

SPP_CYCLES = 64
SPP_PETZVAL = 256  # petzval is the cheaper side: its noise is kept below Cycles'
SPP_CONTROL = 64
SPP_DEPTH = 16  # the USD render is compared by depth alone
SENSOR_MM = 36.0  # the CLI's default sensor width, which the shift in mm refers to
CAM = S.ORTHO_CAM


def _shift_args() -> list[str]:
    return ["--shift-x", f"{CAM.shift[0] * SENSOR_MM:.7g}", "--shift-y", f"{CAM.shift[1] * SENSOR_MM:.7g}"]


def _filter_args() -> list[str]:
    return ["--filter-width", f"{bpy.context.scene.cycles.filter_width:.7g}"]


AUTHOR_USD = textwrap.dedent(
    """
    import json, sys
    from pxr import Gf, Sdf, Usd, UsdGeom
    src, dst, spec = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
    stage = Usd.Stage.Open(src)
    stage.GetRootLayer().Export(dst)
    stage = Usd.Stage.Open(dst)
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    cam = UsdGeom.Camera.Define(stage, "/OrthoCamUsd")
    cam.AddTransformOp().Set(Gf.Matrix4d(*spec["matrix_rows"]))
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    w_units, h_units = spec["window_m"][0] / mpu, spec["window_m"][1] / mpu
    cam.CreateHorizontalApertureAttr(w_units * 10.0)  # tenths of a scene unit
    cam.CreateVerticalApertureAttr(h_units * 10.0)
    cam.CreateHorizontalApertureOffsetAttr(spec["shift_m"][0] / mpu * 10.0)
    cam.CreateVerticalApertureOffsetAttr(spec["shift_m"][1] / mpu * 10.0)
    cam.CreateClippingRangeAttr(Gf.Vec2f(spec["clip_m"][0] / mpu, spec["clip_m"][1] / mpu))
    stage.GetRootLayer().Save()
    win = cam.GetCamera(Usd.TimeCode.Default()).frustum.GetWindow()
    print(json.dumps({"window_min": list(win.GetMin()), "window_max": list(win.GetMax()), "mpu": mpu}))
    """
)


@pytest.fixture(scope="module")
def ortho(blender_run):
    """Cycles' OrthoCam pair and petzval's pairs from the GLB, from the USD stage and the control."""
    w, h = S.RESOLUTION
    cyc = [B.read_rgb(blender_run.cycles(CAM.name, s, SPP_CYCLES)) for s in SEEDS]
    args = ["--camera", CAM.name, *_shift_args(), *_filter_args()]
    gltf = [B.read_rgb(blender_run.petzval(args, s, SPP_PETZVAL, "ortho")) for s in SEEDS]
    # the control: a window 3 % wider (Orthographic Scale × 1.03)
    wide = ["--ortho-scale", f"{CAM.ortho_scale * 1.03:.7g}"]
    control = [B.read_rgb(blender_run.petzval([*args, *wide], s, SPP_CONTROL, "ortho_wide")) for s in SEEDS]
    # USD: Blender's export of the scene plus the camera authored with pxr
    exported = blender_run.workdir / "ortho_blender.usdc"
    stage = blender_run.workdir / "ortho.usda"
    bpy.ops.wm.usd_export(filepath=str(exported))
    obj = bpy.data.objects[CAM.name]
    window = (CAM.ortho_scale, CAM.ortho_scale * h / w)  # AUTO fit: the larger side (width) spans it
    m = np.array(obj.matrix_world)  # column vectors, Blender's Z-up world (the stage's too)
    spec = {
        "matrix_rows": m.T.ravel().tolist(),  # USD's row-vector convention
        "window_m": window,
        "shift_m": (CAM.shift[0] * CAM.ortho_scale, CAM.shift[1] * CAM.ortho_scale),
        "clip_m": CAM.clip,
    }
    p = subprocess.run(
        [sys.executable, "-c", AUTHOR_USD, str(exported), str(stage), json.dumps(spec)],
        capture_output=True,
        text=True,
        check=True,
    )
    frustum = json.loads(p.stdout.strip().splitlines()[-1])
    out = blender_run.workdir / f"petzval_ortho_usd_spp{SPP_DEPTH}_seed0.exr"
    cmd = [
        str(blender_run.binary), "render", str(stage), "-o", str(out), "--no-png",
        "--camera", "/OrthoCamUsd", *_filter_args(),
        "--max-depth", str(S.PETZVAL_MAX_DEPTH), "--resolution", f"{w}x{h}",
        "--spp", str(SPP_DEPTH), "--seed", "0", "--threads", "2",
    ]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    # the GLB's depth with the same samples (depth is averaged over a pixel's samples)
    blender_run.petzval(args, 0, SPP_DEPTH, "ortho_depth")
    runs = (("gltf", "ortho_depth", SPP_DEPTH), ("usd", "ortho_usd", SPP_DEPTH), ("control", "ortho_wide", SPP_CONTROL))
    depth = {k: B.read_exr(blender_run.workdir / f"petzval_{tag}_spp{spp}_seed0.exr")["Z"] for k, tag, spp in runs}
    return {"cyc": cyc, "gltf": gltf, "control": control, "frustum": frustum, "window": window, "depth": depth}


def _verdict(run, key):
    c, p = run["cyc"], run[key]
    v = _block_verdict(B.compare_blocks(c[0], c[1], p[0], p[1]))
    ratio = B.mean_ratio((p[0] + p[1]) / 2, (c[0] + c[1]) / 2)
    return v, ratio


def test_orthographic_camera_matches_cycles(ortho, report):
    """Blender's orthographic camera, from the GLB, renders Cycles' image within noise."""
    source = "gltf"
    v, ratio = _verdict(ortho, source)
    w, h = S.RESOLUTION
    report.line(
        f"OrthoCam ({source}) vs Cycles, {w}x{h}, petzval {SPP_PETZVAL} spp, Cycles {SPP_CYCLES} spp x seeds "
        f"{SEEDS}: {_fmt_verdict(v)}; image mean R,G,B {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"


def test_usd_orthographic_depth_is_the_glb_cameras(ortho, report):
    """The USD stage's orthographic camera sees every surface at the depth the GLB's camera (which
    matches Cycles) sees it: same window, shift, orientation and origin. The 3 % wider window of
    the control moves the depths by far more than the tolerance."""
    d = ortho["depth"]
    rel = {k: np.abs(d[k] - d["gltf"]) / d["gltf"] for k in ("usd", "control")}
    q = {k: float(np.quantile(r, 0.99)) for k, r in rel.items()}
    report.line(f"OrthoCam depth, USD against GLB: 99th percentile relative difference {q['usd']:.2e} "
                f"(control {q['control']:.2e})")  # fmt: skip
    assert np.all(np.isfinite(d["usd"])) and q["usd"] < 1e-4, q
    assert q["control"] > 1e-2, q


def test_usd_window_is_gf_cameras(ortho):
    """The window authored in tenths of a scene unit is the one GfCamera's frustum has (pxr's
    reading of the convention petzval follows)."""
    f = ortho["frustum"]
    size = np.subtract(f["window_max"], f["window_min"]) * f["mpu"]
    assert size == pytest.approx(ortho["window"], rel=1e-6)


def test_a_wrong_window_is_rejected(ortho, report):
    """Negative control: the Orthographic Scale 3 % too large fails the same block test."""
    v, _ = _verdict(ortho, "control")
    report.line(f"OrthoCam control, window 3 % too wide: {_fmt_verdict(v)}")
    assert not _passes(v), f"a 3 % wrong window passed: {_fmt_verdict(v)}"
