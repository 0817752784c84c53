"""A scene of the built-in demo's kind against Cycles: the miniature street at dusk of
street_scene.py (built in Blender, exported as GLB, rendered by both through Blender's thin lens).

* The path tracer alone (``--bokeh-paths 0``) must converge to Cycles' image: the metric and
  tolerances of test_cycles_match.py (two seeds per renderer, 8 x 8 block z-test on luminance,
  mean z² ≤ 1.5 and every |z| ≤ 5; image means within 1 % per channel).
* The default render (bokeh light paths ``auto``: light traced from the blurred lamps through
  the lens onto the film) must keep the image mean within the same 1 %. Its pixels are not
  independent (a light path lands in every pixel under the filter), so the block test's
  per-pixel variance does not hold for it; its noise is reported, from the two seeds.
* The time of each at equal samples and threads against Cycles' is reported, not asserted
  (issue 14's target is ≤ 0.5x; docs/performance.md records the measurements).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

import street_scene as T
from renders import cache_key, cached_render, run_petzval
from test_cycles_match import MEAN_TOL, _block_verdict, _fmt_verdict, _passes

import blender_compare as B
import blender_scenes as S

HERE = Path(__file__).resolve().parent
SPP = 128
SEEDS = (0, 1)


class StreetRun:
    """The street's GLB, its Cycles renders (cached like the main scene's) and petzval renders."""

    def __init__(self, blender_run):
        self.binary = blender_run.binary
        self.workdir = blender_run.workdir / "street"
        key = cache_key(bpy, "street_scene.py", "blender_scenes.py")
        self.cache_dir = blender_run.cache_dir.parent / f"cycles-street-{key}"
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        T.build_scene(self.workdir)
        self.glb = S.export_glb(self.workdir / "street.glb")
        self.args = {paths: T.petzval_args(paths) for paths in ("0", "auto")}
        self.timings: dict[str, float] = {}
        self.fresh: set[str] = set()

    def cycles(self, seed: int) -> np.ndarray:
        name = f"cycles_{T.CAMERA.name}_spp{SPP}_seed{seed}"
        settings = S.CyclesSettings(samples=SPP, seed=seed)
        exr, self.timings[name], fresh = cached_render(
            bpy, self.cache_dir, name, lambda out: S.render_cycles(settings, T.CAMERA.name, out)
        )
        if fresh:
            self.fresh.add(name)
        return B.read_rgb(exr)

    def petzval(self, seed: int, bokeh_paths: str) -> np.ndarray:
        out = self.workdir / f"petzval_paths{bokeh_paths}_spp{SPP}_seed{seed}.exr"
        self.timings[out.stem], _ = run_petzval(self.binary, self.glb, out, self.args[bokeh_paths], SPP, seed)
        return B.read_rgb(out)


@pytest.fixture(scope="module")
def street(blender_run):
    """Builds the street in this Blender session and renders it with both; afterwards rebuilds
    the main scene, which the other modules' tests read from Blender."""
    try:
        run = StreetRun(blender_run)
        run.cyc = [run.cycles(s) for s in SEEDS]
        run.camera_only = [run.petzval(s, "0") for s in SEEDS]
        run.default = [run.petzval(s, "auto") for s in SEEDS]
        yield run
    finally:
        S.build_scene(blender_run.workdir)


def _noise(pair: list[np.ndarray]) -> float:
    """Relative RMS noise of one render, from two seeds: RMS(a − b)/√2 over the RMS image."""
    a, b = pair
    return float(np.sqrt(np.mean((a - b) ** 2) / 2) / np.sqrt(np.mean(((a + b) / 2) ** 2)))


def test_street_path_tracer_matches_cycles(street, report):
    """Camera paths alone (no light paths): the image within noise of Cycles', block by block."""
    c0, c1 = street.cyc
    p0, p1 = street.camera_only
    v = _block_verdict(B.compare_blocks(c0, c1, p0, p1))
    ratio = B.mean_ratio((p0 + p1) / 2, (c0 + c1) / 2)
    w, h = T.RESOLUTION
    report.line(f"Street (demo's kind) {w}x{h}, {SPP} spp x seeds {SEEDS}, petzval " + " ".join(street.args["0"]))
    report.line(
        f"  camera paths alone: blocks {_fmt_verdict(v)}; image mean petzval/Cycles R,G,B "
        f"{ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f} (tolerance ±{MEAN_TOL * 100:.0f} %)"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert _passes(v), f"blocks differ beyond noise: {_fmt_verdict(v)}"


def test_street_with_light_paths_keeps_the_image(street, report):
    """The default render (light paths from the blurred lamps): the same image mean, less noise."""
    c = (street.cyc[0] + street.cyc[1]) / 2
    d = (street.default[0] + street.default[1]) / 2
    ratio = B.mean_ratio(d, c)
    n_c, n_p0, n_p = _noise(street.cyc), _noise(street.camera_only), _noise(street.default)
    report.line(
        f"  with light paths (auto): image mean petzval/Cycles R,G,B {ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}; "
        f"relative noise at {SPP} spp: Cycles {n_c:.4f}, petzval camera paths {n_p0:.4f}, with light paths {n_p:.4f}"
    )
    assert np.all(np.abs(ratio - 1) <= MEAN_TOL), f"image mean ratio {ratio}"
    assert n_p < n_p0, f"light paths did not lower the noise ({n_p:.4f} against {n_p0:.4f})"


def test_street_speed_against_cycles(street, report):
    """Equal samples, bounces and threads (2): wall time of one render each, reported."""
    c = f"cycles_{T.CAMERA.name}_spp{SPP}_seed{SEEDS[0]}"
    t_c = street.timings[c]
    t_0 = street.timings[f"petzval_paths0_spp{SPP}_seed{SEEDS[0]}"]
    t_a = street.timings[f"petzval_pathsauto_spp{SPP}_seed{SEEDS[0]}"]
    cached = "" if c in street.fresh else " (Cycles' time from the cache, another run)"
    report.line(
        f"  speed at {SPP} spp, 2 threads: Cycles {t_c:.2f} s{cached}; petzval camera paths {t_0:.2f} s "
        f"(ratio {t_0 / t_c:.2f}), with light paths {t_a:.2f} s (ratio {t_a / t_c:.2f}); target ≤ 0.5"
    )
    assert t_c > 0 and t_0 > 0 and t_a > 0
