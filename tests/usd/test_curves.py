"""UsdGeomBasisCurves rendered as tubes (usd/src/curves.rs): `usd info` lists the curves prims,
and Blender 5.0's USD export of a hair Curves object renders as Cycles renders the object.

The Blender scene (tests/usd/blender_hair_scene.py): 24 tapering Catmull-Rom strands, diffuse
red (0.8, 0.2, 0.1), under a uniform white world, so a strand pixel is its albedo and the
background white; Cycles renders them as "3D Curves" (round, radius = Blender's radius), we
from the USD file alone (widths = 2 × radius, the world as a dome light). Compared: the strands'
coverage (pixels with green < 0.6) and the mean colour of the window around them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "blender"))
from blender_compare import read_rgb  # noqa: E402


def petzval() -> Path:
    env = os.environ.get("PETZVAL_BIN")
    return Path(env) if env else REPO / "target" / "release" / "petzval"


def run(*args: str) -> subprocess.CompletedProcess:
    p = subprocess.run([str(petzval()), *args], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    return p


def coverage(img: np.ndarray) -> float:
    """The fraction of the image the red strands cover (the background is white)."""
    return float((img[..., 1] < 0.6).mean())


def render(usd: Path) -> np.ndarray:
    """Renders a USD file as Cycles renders (no natural vignetting, its 1.5 px filter)."""
    exr = usd.with_suffix(".exr")
    args = ["--resolution", "160x120", "--spp", "32", "--natural-vignetting", "off", "--filter-width", "1.5"]
    p = run("render", str(usd), *args, "--no-png", "-o", str(exr))
    assert "warning" not in p.stderr, p.stderr
    return read_rgb(exr)


def test_usd_info_lists_curves() -> None:
    fixture = REPO / "usd" / "tests" / "data" / "curves" / "curves.usda"
    rep = json.loads(run("usd", "info", str(fixture), "--json").stdout)
    curves = {m["prim"]: m["curves"] for m in rep["meshes"] if "curves" in m}
    assert len(curves) == 12
    c = curves["/C/catmullRom_pinned"]
    assert (c["kind"], c["basis"], c["wrap"], c["curves"], c["tessellated"]) == ("cubic", "catmullRom", "pinned", 2, 2)
    assert curves["/C/bad_counts"]["bad_counts"] == 1
    text = run("usd", "info", str(fixture)).stdout
    assert "curves /C/bezier_closed: cubic bezier periodic (widths), 1 curves, 1 tessellated" in text, text
    assert "not supported" not in text


def test_blender_hair_export_renders_as_cycles(tmp_path: Path) -> None:
    pytest.importorskip("bpy")
    r = subprocess.run(
        [sys.executable, str(Path(__file__).with_name("blender_hair_scene.py")), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    ours, cyc = render(tmp_path / "hair.usda"), read_rgb(tmp_path / "cycles.exr")
    cov_o, cov_c = coverage(ours), coverage(cyc)
    # the window around the strands
    ys, xs = np.nonzero(cyc[..., 1] < 0.6)
    win = np.s_[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    mo, mc = ours[win].reshape(-1, 3).mean(0), cyc[win].reshape(-1, 3).mean(0)
    # strand pixels' colour (well inside a strand: green < 0.3)
    so, sc = ours[ours[..., 1] < 0.3].mean(0), cyc[cyc[..., 1] < 0.3].mean(0)
    print(f"coverage ours {cov_o:.4f} Cycles {cov_c:.4f}; window mean ours {mo} Cycles {mc}")
    print(f"strand colour ours {so} Cycles {sc}; mean |d green| {np.abs(ours[..., 1] - cyc[..., 1]).mean():.4f}")
    assert cov_c > 0.03, "the strands are not in the picture"
    # measured: coverage 0.06474 vs 0.06464 (+0.2 %; an octagon's mean width is 2.6 % under
    # its circle's, the mitred rings and the filter make up most of it), window mean within
    # 0.5 %, strand colour within 0.012, mean |Δ green| 0.0023
    assert abs(cov_o / cov_c - 1) < 0.03, (cov_o, cov_c)
    assert np.all(np.abs(mo / mc - 1) < 0.01), (mo, mc)
    assert np.all(np.abs(so - sc) < 0.03), (so, sc)
    # the whole picture pixel by pixel: where the strands are, not only how many
    assert np.abs(ours[..., 1] - cyc[..., 1]).mean() < 0.01
    # negative control: widths read as radii (twice as thick) are far off
    text = (tmp_path / "hair.usda").read_text()
    start = text.index("float[] widths = [")
    end = text.index("]", start + 18)
    doubled = ", ".join(str(2 * float(w)) for w in text[start + 18 : end].split(","))
    thick = tmp_path / "thick.usda"
    thick.write_text(text[: start + 18] + doubled + text[end:])
    cov_t = coverage(render(thick))
    print(f"widths doubled: coverage {cov_t:.4f}")
    assert cov_t / cov_c > 1.3, (cov_t, cov_c)  # measured 1.44 (the strands overlap more)
