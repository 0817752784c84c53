"""Time to equal error against Cycles (issue 14): a benchmark, not a test (pytest does not collect it).

    .venv/bin/python tests/blender/bench_equal_error.py [--target 0.02] [--reference-spp 2048]

On tests/blender's scene (MainCam, 240x160, 2 threads each), each renderer renders a converged
reference of its own (fixed samples, no adaptive sampling); then Cycles with its default
adaptive sampling (noise threshold 0.01 by default, here a ladder of thresholds) and petzval over
a ladder of samples and a ladder of its own adaptive thresholds (`--adaptive-threshold`), and
each run's relative RMSE against its own renderer's reference (the two references differ by
the renderers' small systematic differences, which tests/blender bounds; this measures
convergence). The time to the target error is interpolated in log-log between the
two runs that bracket it (extrapolated with error ∝ time^-1/2 when none does). Prints a Markdown
table; docs/performance.md records it.
"""

from __future__ import annotations

import argparse
import itertools
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO / "tests" / "optics"))

import blender_scenes as S  # noqa: E402
import petzval_cli  # noqa: E402
from blender_compare import read_rgb  # noqa: E402


def rel_rmse(ref: np.ndarray, img: np.ndarray) -> float:
    return float(np.sqrt(np.mean((img - ref) ** 2)) / np.sqrt(np.mean(ref**2)))


def cycles(workdir: Path, spp: int, seed: int, threshold: float | None) -> tuple[np.ndarray, float]:
    """A Cycles render: fixed `spp` (threshold None) or adaptive with at most `spp` samples."""
    bpy = S._import_bpy()
    S.configure_cycles(S.CyclesSettings(samples=spp, seed=seed), S.MAIN_CAM.name)
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
    binary: Path, glb: Path, workdir: Path, spp: int, seed: int, threshold: float | None = None
) -> tuple[np.ndarray, float]:
    """A petzval render: fixed `spp` (threshold None) or adaptive (`--adaptive-threshold`, the
    same test and scale as Cycles' noise threshold) with at most `spp` samples."""
    out = workdir / f"petzval_{spp}_{seed}_{threshold}.exr"
    w, h = S.RESOLUTION
    cmd = [
        str(binary), "render", str(glb), "-o", str(out), "--no-png",
        *S.petzval_cycles_args(S.MAIN_CAM),
        "--environment", S.world_rgb_arg(),
        "--max-depth", str(S.PETZVAL_MAX_DEPTH),
        "--resolution", f"{w}x{h}", "--spp", str(spp), "--seed", str(seed), "--threads", "2",
    ]  # fmt: skip
    if threshold is not None:
        cmd += ["--adaptive-threshold", str(threshold)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return read_rgb(out), time.perf_counter() - t0


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--target", type=float, default=0.02)
    ap.add_argument("--reference-spp", type=int, default=2048)
    args = ap.parse_args()
    workdir = REPO / "tests" / "out" / "bench-equal-error"
    workdir.mkdir(parents=True, exist_ok=True)
    S.build_scene(workdir)
    glb = S.export_glb(workdir / "scene.glb")
    binary = petzval_cli.ensure_binary()
    cycles(workdir, 1, 0, None)  # warm-up (kernels, scene sync)
    ref_c, t_rc = cycles(workdir, args.reference_spp, 99, None)
    ref_p, t_rp = petzval(binary, glb, workdir, args.reference_spp, 99)
    print(f"references: Cycles {args.reference_spp} spp {t_rc:.1f} s, petzval {t_rp:.1f} s; "
          f"the two differ by rel. RMSE {rel_rmse(ref_c, ref_p):.4f}", file=sys.stderr)  # fmt: skip
    rows, c_runs, p_runs = [], [], []
    for thr in (0.1, 0.05, 0.02, 0.01, 0.005):
        img, t = cycles(workdir, 4096, 1, thr)
        e = rel_rmse(ref_c, img)
        c_runs.append((t, e))
        rows.append(("Cycles", f"adaptive, threshold {thr} (≤ 4096 spp)", t, e))
    for spp in (16, 32, 64, 128, 256, 512):
        img, t = petzval(binary, glb, workdir, spp, 1)
        e = rel_rmse(ref_p, img)
        p_runs.append((t, e))
        rows.append(("petzval", f"{spp} spp", t, e))
    a_runs = []
    for thr in (0.1, 0.05, 0.02, 0.01):
        img, t = petzval(binary, glb, workdir, 4096, 1, thr)
        e = rel_rmse(ref_p, img)
        a_runs.append((t, e))
        rows.append(("petzval", f"adaptive, threshold {thr} (≤ 4096 spp)", t, e))
    w, h = S.RESOLUTION
    print(f"tests/blender's scene, MainCam {w}x{h}, 2 threads each; references {args.reference_spp} spp "
          "(seed 99), runs seed 1; wall seconds of the render call (Cycles, in process) and of the "
          "whole `petzval render` process.\n")  # fmt: skip
    print("| renderer | run | seconds | rel. RMSE against its own reference |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.2f} | {r[3]:.4f} |")
    tc, how_c = time_to(c_runs, args.target)
    tp, how_p = time_to(p_runs, args.target)
    ta, how_a = time_to(a_runs, args.target)
    print(f"\nTime to a relative RMSE of {args.target}: Cycles (adaptive) {tc:.1f} s ({how_c}); "
          f"petzval fixed samples {tp:.1f} s ({how_p}), ratio {tp / tc:.2f}; "
          f"petzval adaptive {ta:.1f} s ({how_a}), ratio {ta / tc:.2f}.")  # fmt: skip


if __name__ == "__main__":
    main()
