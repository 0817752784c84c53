"""The same Blender scene as test_cycles_match.py, exported with Blender's USD exporter
(`bpy.ops.wm.usd_export`, the world as a dome light) and rendered by petzval from the USD
file alone — camera, lights, materials, textures and world from the stage, no `--environment`
or `--sensor-width` — against Cycles' render of the scene, with the same 8x8 block z-test and
image-mean tolerance as the glTF comparison.

The ground's checker is switched from Closest to Linear (Blender's default) for this comparison,
in the export and in Cycles' render (cached apart from the main scene's): a `UsdUVTexture` has
no filter input, so Blender's USD export records neither, and on a stage Blender wrote petzval
filters sRGB images as Cycles filters Linear ones (encoded, decoded after). Through USD a
Closest image is filtered bilinearly: 0.985–0.988× Cycles' image mean on this scene
(docs/cycles-comparison.md, "Image filtering in files Blender wrote").
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from renders import cache_key, cached_render
from test_cycles_match import MEAN_TOL, SEEDS, SPP, _block_verdict, _fmt_verdict, _passes

import blender_compare as B
import blender_scenes as S

# petzval's side at a quarter of the glTF comparison's samples (the image mean's seed noise is
# still ~0.05 %, far inside the 1 % tolerance); Cycles' pair is at the glTF comparison's 256 spp
SPP_USD = 64
# tests/blender/conftest.py's OUT (not imported from there: with other suites' conftest.py
# collected in the same run, `import conftest` may find one of theirs)
OUT = Path(__file__).resolve().parents[1] / "out" / "blender"


def _cycles_linear(seed: int) -> np.ndarray:
    """Cycles' MainCam render of the scene with the Linear checker (cached by this file and
    blender_scenes.py, beside the main scene's cache)."""
    key = cache_key(bpy, "test_usd_export_cycles.py", "blender_scenes.py")
    cache_dir = OUT / f"cycles-usd-linear-{key}"
    cache_dir.mkdir(parents=True, exist_ok=True)
    cfg = S.CyclesSettings(samples=SPP, seed=seed)
    exr, _, _ = cached_render(
        bpy, cache_dir, f"cycles_MainCam_spp{SPP}_seed{seed}", lambda out: S.render_cycles(cfg, S.MAIN_CAM.name, out)
    )
    return B.read_rgb(exr)


@pytest.fixture(scope="module")
def usd_renders(blender_run):
    """petzval's renders (seeds 0, 1) of the USD export, the Cycles pair and the stage report,
    with the ground's checker Linear (restored to Closest afterwards)."""
    checker = bpy.data.materials["Ground"].node_tree.nodes["Image Texture"]
    assert checker.interpolation == "Closest", checker.interpolation
    checker.interpolation = "Linear"
    try:
        usd = blender_run.workdir / "scene.usdc"
        bpy.ops.wm.usd_export(filepath=str(usd))
        cyc = [_cycles_linear(s) for s in SEEDS]
    finally:
        checker.interpolation = "Closest"
    info = subprocess.run(
        [str(blender_run.binary), "usd", "info", str(usd), "--json"], capture_output=True, text=True, check=True
    )
    rep = json.loads(info.stdout)
    (cam,) = [c["path"] for c in rep["cameras"] if f"/{S.MAIN_CAM.name}/" in c["path"] + "/"]
    # Blender's camera from the stage: drop what glTF needed on the command line
    args = S.petzval_cycles_args(S.MAIN_CAM)
    i = args.index("--camera")
    args[i + 1] = cam
    j = args.index("--sensor-width")
    del args[j : j + 2]
    w, h = S.RESOLUTION
    pz = []
    for seed in SEEDS:
        out = blender_run.workdir / f"petzval_usd_spp{SPP_USD}_seed{seed}.exr"
        cmd = [
            str(blender_run.binary), "render", str(usd), "-o", str(out), "--no-png", *args,
            "--max-depth", str(S.PETZVAL_MAX_DEPTH), "--resolution", f"{w}x{h}",
            "--spp", str(SPP_USD), "--seed", str(seed), "--threads", "2",
        ]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, p.stderr[-3000:]
        pz.append(B.read_rgb(out))
    return pz, cyc, rep, cam


def test_usd_export_image_mean_matches_cycles(usd_renders, report):
    pz, cyc, rep, cam = usd_renders
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    report.line(f"MainCam from the USD export ({cam}), petzval {SPP_USD} spp, Cycles {SPP} spp, seeds {SEEDS}")
    report.line(f"  image mean petzval(USD)/Cycles R,G,B: {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}")
    assert not [w for w in rep["warnings"] if "magenta" in w], rep["warnings"]
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}; warnings {rep['warnings']}"


def test_usd_export_blocks_match_cycles(usd_renders, report):
    pz, cyc, _, _ = usd_renders
    v = _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]))
    report.line(f"  blocks (USD export): {_fmt_verdict(v)}")
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"
