"""Spot lights against Cycles: a hard spot (blend 0) and a soft one (blend 0.2), direct lighting
only, on the scene of spot_scenes.py (built in Blender, exported as GLB, rendered by both).

What is compared, and why (docs/cycles-comparison.md, "Spot lights"):

* The hard spot everywhere, and on its own in the band of pixels whose footprint straddles its
  cone edge, split into the pixels whose centre is inside and those outside the cone. Blender's
  exporter writes blend 0 as innerConeAngle = outerConeAngle; petzval takes that as a step at the
  outer cone, as Cycles has one. (KHR_lights_punctual's sample code divides by
  max(0.001, cos inner − cos outer), a ramp 2.4 mrad wide inside a 25° cone: that was the dark
  band of disagreement 2; the negative control renders it and must be rejected.)
* The soft spot everywhere, its fade zone included: Blender fades with a smoothstep in cos θ over
  [cos θo, cos θo + (1 − cos θo)·blend], and petzval, reading a file Blender's exporter wrote,
  recovers blend = 1 − inner/outer from the exported cones and fades the same way (other glTF
  files keep the spec's squared ramp). Until session 38 petzval used the spec's ramp for every
  file and the fade zone was excluded here (it rendered 0.25–0.9× Cycles there); its pixels
  (spot_scenes.pixel_masks) are now also compared on their own.

The metric and tolerances are test_cycles_match.py's: two seeds per renderer, 8 x 8 block z-test
(mean z² ≤ 1.5, every |z| ≤ 5) over all blocks, the mean of the pixels within 1 % per channel, and
|z| ≤ 5 for the band sums and the fade zone's sum.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from renders import cache_key, cached_render, run_petzval
from test_cycles_match import MAX_ABS_Z, MEAN_TOL, _block_verdict, _fmt_verdict, _passes

import blender_compare as B
import blender_scenes as S
import spot_scenes as SP

HERE = Path(__file__).resolve().parent
SPP = 64
SEEDS = (0, 1)
CONTROL_SEED = 7


def _read_glb(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    magic, _version, _length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF"
    n, kind = struct.unpack_from("<I4s", data, 12)
    assert kind == b"JSON"
    return json.loads(data[20 : 20 + n]), data[20 + n :]


def _write_glb(path: Path, doc: dict, rest: bytes) -> None:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + rest
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)


def _gltf_spots(doc: dict) -> dict:
    return {lt["name"]: lt for lt in doc["extensions"]["KHR_lights_punctual"]["lights"] if lt["type"] == "spot"}


class SpotRun:
    """The spot scene's GLB, Cycles renders (cached like the main scene's) and petzval renders."""

    def __init__(self, blender_run):
        self.binary = blender_run.binary
        self.workdir = blender_run.workdir / "spots"
        key = cache_key(bpy, "spot_scenes.py", "blender_scenes.py")
        self.cache_dir = blender_run.cache_dir.parent / f"cycles-spots-{key}"
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        SP.build_scene(self.workdir)
        self.glb = S.export_glb(self.workdir / "spots.glb")
        self.timings: dict[str, float] = {}
        self.stderr: dict[str, str] = {}

    def cycles(self, seed: int) -> np.ndarray:
        name = f"cycles_{SP.CAMERA.name}_spp{SPP}_seed{seed}"
        exr, self.timings[name], _ = cached_render(
            bpy, self.cache_dir, name, lambda out: SP.render_cycles(SPP, seed, out)
        )
        return B.read_rgb(exr)

    def petzval(self, seed: int, tag: str, glb: Path | None = None) -> np.ndarray:
        out = self.workdir / f"petzval_{tag}_spp{SPP}_seed{seed}.exr"
        self.timings[out.stem], self.stderr[out.stem] = run_petzval(
            self.binary, glb or self.glb, out, SP.petzval_args(), SPP, seed
        )
        return B.read_rgb(out)


@pytest.fixture(scope="module")
def spot_run(blender_run):
    """Builds the spot scene in this Blender session; afterwards rebuilds the main scene, which
    the other modules' tests read from Blender (cameras, the USD export)."""
    try:
        run = SpotRun(blender_run)
        run.masks = SP.pixel_masks()
        run.centre_inside = SP.hard_edge_side()
        run.cyc = [run.cycles(s) for s in SEEDS]
        run.pz = [run.petzval(s, "spots") for s in SEEDS]
        yield run
    finally:
        S.build_scene(blender_run.workdir)


def _lum_pair(pair):
    return [B.luminance(x) for x in pair]


def _region_z(cyc, pz, mask, var_single=None):
    """Ratio of the luminance summed over `mask`, petzval/Cycles (two-seed averages, or a single
    petzval image with per-pixel variance `var_single`), its z-score and its relative σ."""
    c0, c1 = _lum_pair(cyc)
    cm, var_c = (c0 + c1) / 2, (c0 - c1) ** 2 / 4
    if var_single is None:
        p0, p1 = _lum_pair(pz)
        pm, var_p = (p0 + p1) / 2, (p0 - p1) ** 2 / 4
    else:
        pm, var_p = B.luminance(pz[0]), var_single
    sc, sp = cm[mask].sum(), pm[mask].sum()
    sigma = math.sqrt(var_c[mask].sum() + var_p[mask].sum())
    return sp / sc, (sp - sc) / sigma, sigma / sc


def _block_comparison(cyc, pz, keep_blocks):
    return _block_verdict(B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]), keep_blocks)


def test_spot_export_cones(spot_run, report):
    """What Blender's exporter writes for the two spots, and that petzval reads the hard one
    (inner = outer, outside the spec's inner < outer) without a warning."""
    doc, _ = _read_glb(spot_run.glb)
    spots = _gltf_spots(doc)
    hard, soft = spots[SP.SPOT_HARD.name]["spot"], spots[SP.SPOT_SOFT.name]["spot"]
    assert hard["outerConeAngle"] == pytest.approx(SP.SPOT_HARD.outer, rel=1e-6)
    assert hard["innerConeAngle"] == pytest.approx(hard["outerConeAngle"], rel=1e-6)
    assert soft["outerConeAngle"] == pytest.approx(SP.SPOT_SOFT.outer, rel=1e-6)
    assert soft["innerConeAngle"] == pytest.approx(SP.SPOT_SOFT.gltf_inner, rel=1e-5)
    err = spot_run.stderr[f"petzval_spots_spp{SPP}_seed{SEEDS[0]}"]
    assert "ConeAngle" not in err, err
    m = spot_run.masks
    report.line(
        f"Spots ({SP.RESOLUTION[0]}x{SP.RESOLUTION[1]}, direct light, {SPP} spp x seeds {SEEDS}): exported cones hard "
        f"{math.degrees(hard['innerConeAngle']):.2f}°/{math.degrees(hard['outerConeAngle']):.2f}°, soft "
        f"{math.degrees(soft['innerConeAngle']):.2f}°/{math.degrees(soft['outerConeAngle']):.2f}° (inner/outer; "
        f"Blender's smoothstep reaches 1 at {math.degrees(SP.SPOT_SOFT.blender_inner):.2f}°); pixels: soft fade "
        f"zone {int(m.soft_transition.sum())}, hard edge band {int(m.hard_band.sum())}, inside the soft "
        f"inner cones {int(m.soft_inner.sum())}, inside the hard cone {int(m.hard_inside.sum())}"
    )


def test_spot_blocks_match_cycles(spot_run, report):
    """Every 8 x 8 block, the mean of the image, and the soft spot's fade zone summed."""
    m = spot_run.masks
    keep_blocks = B.block_sum(m.soft_transition.astype(int), 8) >= 0
    v = _block_comparison(spot_run.cyc, spot_run.pz, keep_blocks)
    keep_px = np.kron(keep_blocks, np.ones((8, 8), bool))
    pm = (spot_run.pz[0] + spot_run.pz[1]) / 2
    cm = (spot_run.cyc[0] + spot_run.cyc[1]) / 2
    ratio = pm[keep_px].mean(axis=0) / cm[keep_px].mean(axis=0)
    r_fade, z_fade, s_fade = _region_z(spot_run.cyc, spot_run.pz, m.soft_transition)
    report.line(
        f"  spots, all blocks: {_fmt_verdict(v)}; noise floor (median relative std of a "
        f"block mean) Cycles {v['rel_noise_c'] * 100:.2f} %, petzval {v['rel_noise_p'] * 100:.2f} %"
    )
    report.line(
        f"  spots, mean of those pixels petzval/Cycles R,G,B: {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f} "
        f"(tolerance ±{MEAN_TOL * 100:.0f} %); the soft spot's fade zone: {r_fade:.4f} (z {z_fade:+.1f}, "
        f"σ {s_fade * 100:.2f} %)"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"mean ratio {ratio}"
    assert abs(z_fade) <= MAX_ABS_Z, f"fade zone {r_fade:.4f}, z {z_fade:+.1f}"
    assert v["n_blocks"] >= 300, v
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"


def _band_stats(cyc, pz, masks, centre_inside, **kw):
    band = masks.hard_band
    return {
        "all": _region_z(cyc, pz, band, **kw),
        "inside": _region_z(cyc, pz, band & centre_inside, **kw),
        "outside": _region_z(cyc, pz, band & ~centre_inside, **kw),
        "soft inner": _region_z(cyc, pz, masks.soft_inner, **kw),
        "hard inside": _region_z(cyc, pz, masks.hard_inside, **kw),
    }


def _fmt_band(st: dict) -> str:
    return "; ".join(f"{k} {r:.4f} (z {z:+.1f}, σ {s * 100:.2f} %)" for k, (r, z, s) in st.items())


def test_hard_spot_edge_band_matches_cycles(spot_run, report):
    """The pixels straddling the hard spot's edge: summed, and split by the side of the edge
    their centre sees; plus the regions well inside each spot."""
    st = _band_stats(spot_run.cyc, spot_run.pz, spot_run.masks, spot_run.centre_inside)
    report.line(f"  spots, petzval/Cycles: hard edge band {_fmt_band(st)}")
    bad = {k: v for k, v in st.items() if abs(v[1]) > MAX_ABS_Z}
    assert not bad, f"differ beyond {MAX_ABS_Z} σ: {_fmt_band(bad)}"


def test_spot_negative_control_old_falloff(spot_run, report):
    """The metric must see the old hard-spot falloff: petzval renders the GLB with the hard
    spot's innerConeAngle set so that cos inner − cos outer = 0.001 (what the spec's sample code,
    and petzval before, did with inner = outer); the band, just inside the edge, must be
    rejected while the regions well inside the cones still match."""
    doc, rest = _read_glb(spot_run.glb)
    hard = _gltf_spots(doc)[SP.SPOT_HARD.name]["spot"]
    hard["innerConeAngle"] = math.acos(math.cos(hard["outerConeAngle"]) + 0.001)
    glb = spot_run.workdir / "spots_control_ramp.glb"
    _write_glb(glb, doc, rest)
    img = spot_run.petzval(CONTROL_SEED, "control_ramp", glb)
    p0, p1 = _lum_pair(spot_run.pz)
    var_single = (p0 - p1) ** 2 / 4 * 2.0  # one seed: twice the variance of the pair's average
    st = _band_stats(spot_run.cyc, [img], spot_run.masks, spot_run.centre_inside, var_single=var_single)
    report.line(
        f"  negative control, hard spot with a 0.001 ramp in cos (inner {math.degrees(hard['innerConeAngle']):.3f}°), "
        f"petzval/Cycles: {_fmt_band(st)}"
    )
    assert st["inside"][1] < -MAX_ABS_Z, f"the metric did not notice the old falloff: {_fmt_band(st)}"
    assert abs(st["soft inner"][1]) <= MAX_ABS_Z and abs(st["hard inside"][1]) <= MAX_ABS_Z, _fmt_band(st)
