"""Time to equal error against Cycles (issue 14): a benchmark, not a test (pytest does not collect it).

    .venv/bin/python tests/blender/bench_equal_error.py [--scene main|street] [--target 0.02] [--reference-spp 2048]
        [--display-target 0.05] [--adaptive-thresholds 0.1,0.05,0.02,0.01] [--skip-cycles]

On tests/blender's scene (MainCam, 240x160, 2 threads each; or with ``--scene street`` the
miniature street of street_scene.py, a scene of the built-in demo's kind, StreetCam, where
petzval's runs also trace bokeh light paths by default and a ladder without them is added),
each renderer renders a converged reference of its own (fixed samples, no adaptive sampling,
two seeds averaged: a run's error is measured against the truth by taking the reference's own
noise, estimated from its two seeds, out of it; at 2048 spp Cycles' own noise on the street's
bokeh is about 1.3 %); then Cycles with its default
adaptive sampling (noise threshold 0.01 by default, here a ladder of thresholds) and petzval over
a ladder of samples and a ladder of its own adaptive thresholds (`--adaptive-threshold`), and
each run's relative RMSE against its own renderer's reference (the two references differ by
the renderers' small systematic differences, which tests/blender bounds; this measures
convergence). The time to the target error is interpolated in log-log between the
two runs that bracket it (extrapolated with error ∝ time^-1/2 when none does). Each run's error
is also given display-referred (every image clipped to [0, 1] and raised to 1/2.2 before the
same relative RMSE; the linear figure is carried by the few pixels far above 1, such as lamp
cores, which a display clips), with its own target. Prints a Markdown table;
docs/performance.md records it. `--skip-cycles` renders petzval's runs alone (to compare two
petzval binaries: PETZVAL_BIN names the one to run).
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO / "tests" / "optics"))

import street_scene as T  # noqa: E402
from renders import run_petzval  # noqa: E402

import blender_scenes as S  # noqa: E402
import petzval_cli  # noqa: E402
from blender_compare import read_rgb  # noqa: E402


class Reference:
    """A renderer's converged image: the mean of two renders with different seeds, and its own
    noise, so that a run's error can be measured against the truth rather than against a noisy
    reference. A run's squared relative error against the mean of two references is its own
    plus the mean's noise; that noise is estimated from the two renders' difference
    (E[(a − b)²]/4 per pixel for the mean of a and b) and subtracted."""

    def __init__(self, a: np.ndarray, b: np.ndarray):
        self.image = (a + b) / 2
        self.norm2 = float(np.mean(self.image**2))
        self.noise2 = float(np.mean((a - b) ** 2) / 4) / self.norm2

    @property
    def noise(self) -> float:
        """Relative RMS noise of the reference itself."""
        return math.sqrt(self.noise2)

    def rel_rmse(self, img: np.ndarray) -> float:
        """The run's relative RMSE against the truth (the reference's noise taken out; never
        below a tenth of the raw figure)."""
        raw2 = float(np.mean((img - self.image) ** 2)) / self.norm2
        return math.sqrt(max(raw2 - self.noise2, raw2 / 100))


def display(img: np.ndarray) -> np.ndarray:
    """Display-referred values: clipped to [0, 1], gamma 1/2.2."""
    return np.clip(img, 0.0, 1.0) ** (1 / 2.2)


def rel_rmse(ref: np.ndarray, img: np.ndarray) -> float:
    return float(np.sqrt(np.mean((img - ref) ** 2)) / np.sqrt(np.mean(ref**2)))


def cycles(workdir: Path, camera: str, spp: int, seed: int, threshold: float | None) -> tuple[np.ndarray, float]:
    """A Cycles render: fixed `spp` (threshold None) or adaptive with at most `spp` samples."""
    bpy = S._import_bpy()
    S.configure_cycles(S.CyclesSettings(samples=spp, seed=seed), camera)
    c = bpy.context.scene.cycles
    if threshold is not None:
        c.use_adaptive_sampling = True
        c.adaptive_threshold = threshold
        c.adaptive_min_samples = 0  # Cycles' default: chosen from the threshold
    out = workdir / f"cycles_{spp}_{seed}_{threshold}.exr"
    bpy.context.scene.render.filepath = str(out)
    with S._quiet(workdir / "blender.log"):
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        dt = time.perf_counter() - t0
    return read_rgb(out), dt


def petzval(
    binary: Path,
    glb: Path,
    workdir: Path,
    ladder: str,
    args: list[str],
    spp: int,
    seed: int,
    threshold: float | None = None,
) -> tuple[np.ndarray, float]:
    """A petzval render with the scene's options `args` (`ladder` names them in the file name):
    fixed `spp` (threshold None) or adaptive (`--adaptive-threshold`, the same test and scale as
    Cycles' noise threshold) with at most `spp` samples."""
    out = workdir / f"petzval_{ladder}_{spp}_{seed}_{threshold}.exr"
    adaptive = [] if threshold is None else ["--adaptive-threshold", str(threshold)]
    seconds, _ = run_petzval(binary, glb, out, [*args, *adaptive], spp, seed)
    return read_rgb(out), seconds


def time_to(runs: list[tuple[float, float]], target: float) -> tuple[float, str]:
    """Seconds to reach `target` from (seconds, error) runs: log-log interpolation between the
    bracketing pair, else extrapolation from the nearest run with error ∝ time^-1/2."""
    runs = sorted(runs)
    for (t0, e0), (t1, e1) in itertools.pairwise(runs):
        if e0 >= target >= e1 and e0 > e1:
            a = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e1))
            return math.exp(math.log(t0) + a * (math.log(t1) - math.log(t0))), "interpolated"
    t, e = min(runs, key=lambda r: abs(math.log(r[1] / target)))
    return t * (e / target) ** 2, "extrapolated"


def thresholds_arg(text: str) -> list[float]:
    """`--adaptive-thresholds`: comma-separated noise thresholds in (0, 1]."""
    try:
        values = [float(t) for t in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected comma-separated numbers, such as 0.1,0.05") from None
    if not values or not all(0.0 < v <= 1.0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: every threshold must be in (0, 1]")
    return values


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", type=float, default=0.02)
    ap.add_argument("--reference-spp", type=int, default=2048)
    ap.add_argument("--scene", choices=("main", "street"), default="main")
    ap.add_argument("--display-target", type=float, default=0.05)
    ap.add_argument("--adaptive-thresholds", type=thresholds_arg, default="0.1,0.05,0.02,0.01")
    ap.add_argument("--skip-cycles", action="store_true")
    args = ap.parse_args()
    thresholds = args.adaptive_thresholds
    workdir = REPO / "tests" / "out" / f"bench-equal-error-{args.scene}"
    workdir.mkdir(parents=True, exist_ok=True)
    if args.scene == "main":
        S.build_scene(workdir)
        camera, (w, h) = S.MAIN_CAM.name, S.RESOLUTION
        world = ["--environment", S.world_rgb_arg(), "--max-depth", str(S.PETZVAL_MAX_DEPTH)]
        ladders = {"": [*S.petzval_cycles_args(S.MAIN_CAM), *world, "--resolution", f"{w}x{h}"]}
    else:
        T.build_scene(workdir)
        camera, (w, h) = T.CAMERA.name, T.RESOLUTION
        ladders = {"": T.petzval_args("auto"), ", no light paths": T.petzval_args("0")}
    glb = S.export_glb(workdir / "scene.glb")
    binary = petzval_cli.ensure_binary()
    (p_a, t_rp), (p_b, _) = (petzval(binary, glb, workdir, "ref", ladders[""], args.reference_spp, s) for s in (99, 98))
    ref_p, ref_pd = Reference(p_a, p_b), Reference(display(p_a), display(p_b))
    if not args.skip_cycles:
        cycles(workdir, camera, 1, 0, None)  # warm-up (kernels, scene sync)
        (c_a, t_rc), (c_b, _) = (cycles(workdir, camera, args.reference_spp, s, None) for s in (99, 98))
        ref_c, ref_cd = Reference(c_a, c_b), Reference(display(c_a), display(c_b))
        print(f"references: Cycles {args.reference_spp} spp {t_rc:.1f} s, petzval {t_rp:.1f} s; "
              f"the two differ by rel. RMSE {rel_rmse(ref_c.image, ref_p.image):.4f}; their own noise "
              f"(two seeds each): Cycles {ref_c.noise:.4f}, petzval {ref_p.noise:.4f}", file=sys.stderr)  # fmt: skip
    # (renderer, run, seconds, linear error, display-referred error)
    rows: list[tuple[str, str, float, float, float]] = []
    c_runs, p_runs = [], {name: [] for name in ladders}
    if not args.skip_cycles:
        for thr in (0.1, 0.05, 0.02, 0.01, 0.005):
            img, t = cycles(workdir, camera, 4096, 1, thr)
            e, ed = ref_c.rel_rmse(img), ref_cd.rel_rmse(display(img))
            c_runs.append((t, e, ed))
            rows.append(("Cycles", f"adaptive, threshold {thr} (≤ 4096 spp)", t, e, ed))
    for k, (name, pargs) in enumerate(ladders.items()):
        for spp in (16, 32, 64, 128, 256, 512):
            img, t = petzval(binary, glb, workdir, f"ladder{k}", pargs, spp, 1)
            e, ed = ref_p.rel_rmse(img), ref_pd.rel_rmse(display(img))
            p_runs[name].append((t, e, ed))
            rows.append(("petzval", f"{spp} spp{name}", t, e, ed))
    a_runs = []
    for thr in thresholds:
        img, t = petzval(binary, glb, workdir, "adaptive", ladders[""], 4096, 1, thr)
        e, ed = ref_p.rel_rmse(img), ref_pd.rel_rmse(display(img))
        a_runs.append((t, e, ed))
        rows.append(("petzval", f"adaptive, threshold {thr} (≤ 4096 spp)", t, e, ed))
    print(f"{args.scene} scene, {camera} {w}x{h}, 2 threads each; references {args.reference_spp} spp "
          "(the mean of seeds 99 and 98, whose own noise is taken out of each run's error), runs seed 1; "
          "wall seconds of the render call (Cycles, in process) and of the "
          f"whole `petzval render` process ({' '.join(ladders[''])}).\n")  # fmt: skip
    print("| renderer | run | seconds | rel. RMSE against its own reference (its noise taken out) "
          "| the same, display-referred |")  # fmt: skip
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.2f} | {r[3]:.4f} | {r[4]:.4f} |")
    print_times_to(1, args.target, "a relative RMSE", c_runs, p_runs, a_runs)
    print_times_to(2, args.display_target, "a display-referred relative RMSE", c_runs, p_runs, a_runs)


def print_times_to(col: int, target: float, label: str, c_runs: list, p_runs: dict, a_runs: list) -> None:
    """Prints each ladder's time to `target` in error column `col` of its (seconds, linear error,
    display-referred error) runs, and its ratio to Cycles' when Cycles ran."""

    def runs_of(runs: list) -> list[tuple[float, float]]:
        return [(r[0], r[col]) for r in runs]

    tc, how_c = time_to(runs_of(c_runs), target) if c_runs else (math.nan, "not run")

    def ratio(t: float) -> str:
        return f", ratio {t / tc:.2f}" if c_runs else ""

    ta, how_a = time_to(runs_of(a_runs), target)
    fixed = []
    for name, runs in p_runs.items():
        tp, how_p = time_to(runs_of(runs), target)
        fixed.append(f"petzval fixed samples{name} {tp:.1f} s ({how_p}){ratio(tp)}")
    print(f"\nTime to {label} of {target}: Cycles (adaptive) {tc:.1f} s ({how_c}); "
          + "; ".join(fixed)
          + f"; petzval adaptive {ta:.1f} s ({how_a}){ratio(ta)}.")  # fmt: skip


if __name__ == "__main__":
    main()
