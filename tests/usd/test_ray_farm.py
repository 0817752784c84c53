"""The Ray fan-out (usd/farm/ray_render.py) on a local Ray cluster on 127.0.0.1: six frames of
an animated shot, one task per frame; the first attempt of frame 3 is killed mid-render
(SIGKILL), retried, and every EXR ends complete with no broken or temporary file left.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("ray")
pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, UsdLux  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "usd" / "farm" / "ray_render.py"


def petzval() -> Path:
    env = os.environ.get("PETZVAL_BIN")
    return Path(env) if env else REPO / "target" / "release" / "petzval"


def test_six_frames_with_a_killed_frame_retried(tmp_path: Path) -> None:
    shot = tmp_path / "shot.usda"
    stage = Usd.Stage.CreateNew(str(shot))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(6)
    m = UsdGeom.Mesh.Define(stage, "/Q")
    m.CreatePointsAttr([(-1, -1, -3), (1, -1, -3), (1, 1, -3), (-1, 1, -3)])
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    t = m.AddTranslateOp()
    t.Set((0, 0, 0), 1)
    t.Set((1, 0, 0), 6)
    UsdLux.DomeLight.Define(stage, "/Env")
    cam = UsdGeom.Camera.Define(stage, "/Cam")
    cam.CreateFocalLengthAttr(0.5)
    cam.CreateHorizontalApertureAttr(0.36)
    cam.CreateVerticalApertureAttr(0.24)
    stage.GetRootLayer().Save()
    out = tmp_path / "out"
    out.mkdir()
    marker = tmp_path / "killed"
    env = dict(os.environ, PETZVAL_FARM_KILL_ONCE=f"3:{marker}", RAY_USAGE_STATS_ENABLED="0")
    r = subprocess.run(
        [
            sys.executable,
            str(SCRIPT),
            str(shot),
            "--frames",
            "1-6",
            "-o",
            str(out / "f.####.exr"),
            "--retries",
            "2",
            "--petzval",
            str(petzval()),
            "--",
            "--resolution",
            "48x32",
            "--spp",
            "1500",
            "--threads",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    assert marker.exists(), "frame 3's first attempt was killed"
    names = sorted(p.name for p in out.iterdir())
    assert names == [f"f.{i:04d}.exr" for i in range(1, 7)], names
    sys.path.insert(0, str(SCRIPT.parent))
    from ray_render import exr_complete

    assert all(exr_complete(out / n) for n in names)
    assert "[6/6]" in r.stdout
