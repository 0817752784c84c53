"""LRTF correction mode on optiland's captures: the start lens is optiland's Cooke triplet with
surface 3's radius 1 % off, and the fit may change no prescription value, only the correction of
the start lens's outgoing rays (``correction.*``). The corrected table is baked with ``--lrtf``
and the renderer renders through it. The parametric fit of the same captures (conftest's
``optiland_fit``, the radius itself free, started 2 % off) is the comparison.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import tomllib
from pathlib import Path

from conftest import OUT, RADIUS_SURFACE, REPO

from optiland_captures import manifest

TERMS = ["defocus", "spherical", "coma", "astigmatism", "field_curvature", "pupil_scale"]
# measured (docs/lens-fit.md): 0.8–1.5 % with 320 evaluations (the parametric fit: 0.1–0.4 %); stated bound
RESIDUAL_MAX = 0.03
RENDER_ARGS = ["--resolution", "64x48", "--spp", "2"]


def _perturbed_zmx(src: Path, dst: Path, factor: float) -> None:
    """The exported lens with surface RADIUS_SURFACE's radius times ``factor`` (its CURV / factor)."""
    text = src.read_text()
    block = re.search(rf"SURF {RADIUS_SURFACE}\n(.*?)\n  CURV ([-+0-9.Ee]+)", text, re.S)
    assert block, "no CURV line for the surface in the exported lens"
    curv = float(block.group(2)) / factor
    start, end = block.span(2)
    dst.write_text(text[:start] + f"{curv:.16E}" + text[end:])


def _petzval_bin() -> str:
    return os.environ.get("PETZVAL_BIN", str(REPO / "target" / "release" / "petzval"))


def test_correction_mode_fits_a_wrong_start_lens_and_renders(optiland_fit, petzval_fit_bin):
    _perturbed_zmx(OUT / "cooke_triplet.zmx", OUT / "cooke_wrong.zmx", 1.01)
    train = tomllib.loads((OUT / "train.toml").read_text())
    free = [{"param": f"correction.{t}", "min": -10.0, "max": 10.0} for t in TERMS]
    # the sensor's place: the wrong lens's focus setting puts it elsewhere than the true lens's
    free.append({"param": "sensor.offset_mm", "min": -0.5, "max": 0.5})
    (OUT / "correction.toml").write_text(manifest("cooke_wrong.zmx", free, train["capture"]))
    lens, table, report = OUT / "corrected.toml", OUT / "corrected.lrtf", OUT / "correction"
    cmd = [str(petzval_fit_bin), str(OUT / "correction.toml"), "-o", str(lens), "--lrtf", str(table)]
    # an evaluation budget (deterministic on any machine; the time limit is only a cap). 160
    # evaluations were enough on the captures of earlier hosts (0.9–2.1 %), but not on those of
    # an AMD EPYC host (2026-12-04: 0.7–3.8 %, the same with petzval-fit built from older
    # commits, so the captures or the host's maths libraries differ, not the fit code); 320 gives
    # 0.8–1.5 % there, 640 the same
    budget = ["--max-evaluations", "320", "--rays", "16384", "--time-limit", "120"]
    p = subprocess.run([*cmd, "--report", str(report), *budget], capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr
    fit = json.loads((report / "fit.json").read_text())
    residuals = [c["residual"] for c in fit["captures"]]
    parametric = [c["residual"] for c in optiland_fit["fit"]["captures"]]
    print(
        f"\ncorrection mode from a lens 1 % off: residuals {', '.join(f'{r:.4f}' for r in residuals)}"
        f" ({fit['seconds']:.1f} s); parametric fit: {', '.join(f'{r:.4f}' for r in parametric)}\n"
        + ", ".join(f"{k} {v['value']:.4f}" for k, v in fit["params"].items())
    )
    assert all(r < RESIDUAL_MAX for r in residuals), residuals
    # the renderer renders through the corrected table
    out = OUT / "corrected_render.exr"
    r = subprocess.run(
        [_petzval_bin(), "render", "--lens", str(lens), "--lrtf-file", str(table), *RENDER_ARGS, "-o", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert out.is_file() and out.stat().st_size > 0
