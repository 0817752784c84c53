"""Shared set-up of the lens-fit suite: the petzval-fit binary and one fit to optiland's captures.

- ``petzval_fit_bin``: ``$PETZVAL_FIT_BIN``, else ``petzval-fit`` next to ``$PETZVAL_BIN`` (tests/run
  sets it to target/release/petzval), else target/release/petzval-fit (built with ``cargo build
  --release -p petzval-fit`` when missing).
- ``optiland_fit``: nine captures of optiland's Cooke triplet rendered by optiland
  (optiland_captures.py) into tests/out/lens_fit; petzval-fit fits six of them from the exported
  lens with surface 3's radius started 2 % off, then predicts the other three with ``--evaluate``.
  Both test files read this one fit (it takes ~40 s; the renders ~25 s).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from optiland_captures import OptilandCamera, Shot, manifest, write_exr

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "tests" / "out" / "lens_fit"

RADIUS_SURFACE = 3  # petzval's and optiland's numbering agree for this lens (no surface added)
START_FACTOR = 1.02
SIZE = 48
FIT_ARGS = ["--time-limit", "20", "--rays", "32768"]

# six captures to fit: in focus on and off the axis, defocused both ways, f/5.6 and f/8; one
# (and one held out) with its distances from the sensor, the rest from the entrance pupil
TRAIN = [
    Shot((0.0, 0.0, 2.0), 2.0, 5.6),
    Shot((0.25, 0.15, 2.0), 2.0, 5.6),
    Shot((0.0, 0.0, 1.4), 2.0, 5.6),
    Shot((-0.2, 0.1, 1.5), 2.0, 5.6),
    Shot((0.15, -0.1, 3.0), 2.0, 8.0),
    Shot((0.0, 0.0, 1.2), 1.6, 8.0, from_sensor=True),
]
# three to predict: other field positions, focus distances and f-numbers
HELD_OUT = [
    Shot((-0.3, -0.15, 2.5), 2.5, 6.3),
    Shot((0.1, 0.2, 1.0), 1.5, 7.1, from_sensor=True),
    Shot((0.0, 0.0, 3.0), 1.5, 5.6),
]


@pytest.fixture(scope="session")
def petzval_fit_bin() -> Path:
    if os.environ.get("PETZVAL_FIT_BIN"):
        return Path(os.environ["PETZVAL_FIT_BIN"])
    if os.environ.get("PETZVAL_BIN"):
        sibling = Path(os.environ["PETZVAL_BIN"]).with_name("petzval-fit")
        if sibling.is_file():
            return sibling
    path = REPO / "target" / "release" / "petzval-fit"
    if not path.is_file():
        subprocess.run(["cargo", "build", "--release", "-p", "petzval-fit"], cwd=REPO, check=True)
    return path


def _render(camera: OptilandCamera, shots: list[Shot], folder: Path, prefix: str) -> list[dict]:
    folder.mkdir(parents=True, exist_ok=True)
    captures = []
    for i, s in enumerate(shots):
        img, origin = camera.render(s, SIZE)
        name = f"{prefix}{i + 1:02d}.exr"
        write_exr(folder / name, img / img.max())
        captures.append(
            {
                "image": name,
                "crop_origin_px": origin,
                "source_m": list(s.source_m),
                "focus_m": s.focus_m,
                "distances_from": "sensor" if s.from_sensor else "entrance_pupil",
                "f_number": s.f_number,
                "wavelength_nm": 550.0,
            }
        )
    return captures


def _run(cmd: list[str]) -> float:
    t = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True)
    assert p.returncode == 0, f"{' '.join(cmd)}\n{p.stdout}\n{p.stderr}"
    return time.monotonic() - t


@pytest.fixture(scope="session")
def optiland_fit(petzval_fit_bin) -> dict:
    if OUT.exists():
        shutil.rmtree(OUT)
    OUT.mkdir(parents=True)
    camera = OptilandCamera()
    camera.save_zemax(OUT / "cooke_triplet.zmx")
    truth = camera.radius(RADIUS_SURFACE)
    lo, hi = sorted([truth * 0.95, truth * 1.05])
    free = [{"param": f"surface.{RADIUS_SURFACE}.radius_mm", "min": lo, "max": hi, "start": truth * START_FACTOR}]
    t = time.monotonic()
    train = _render(camera, TRAIN, OUT, "train")
    held = _render(camera, HELD_OUT, OUT, "held")
    render_s = time.monotonic() - t
    (OUT / "train.toml").write_text(manifest("cooke_triplet.zmx", free, train))
    (OUT / "held_out.toml").write_text(manifest("cooke_triplet.zmx", free, held))
    bin_ = str(petzval_fit_bin)
    fit_s = _run(
        [bin_, str(OUT / "train.toml"), "-o", str(OUT / "fitted.toml"), "--report", str(OUT / "fit"), *FIT_ARGS]
    )
    eval_s = _run(
        [bin_, str(OUT / "held_out.toml"), "--evaluate", str(OUT / "fit"), "--report", str(OUT / "eval"), *FIT_ARGS]
    )
    return {
        "truth_radius": truth,
        "start_radius": truth * START_FACTOR,
        "fit": json.loads((OUT / "fit" / "fit.json").read_text()),
        "eval": json.loads((OUT / "eval" / "fit.json").read_text()),
        "render_s": render_s,
        "fit_s": fit_s,
        "eval_s": eval_s,
        "param": f"surface.{RADIUS_SURFACE}.radius_mm",
    }
