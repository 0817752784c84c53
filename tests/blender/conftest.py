"""Fixtures for the comparison against Blender's Cycles (bpy==5.0.1 as a Python module).

- ``blender_run``: builds the scene of ``blender_scenes.py`` in Blender (in this process, in
  memory), exports it as GLB into ``tests/out/blender/`` and provides
  ``cycles(camera, seed, spp)`` (Cycles CPU render, cached) and
  ``petzval(camera_args, seed, spp, tag)`` (our render of the exported GLB).
- Cycles renders are cached in ``tests/out/blender/cycles-<key>/`` (tests/out is gitignored),
  keyed by a hash of ``blender_scenes.py`` (which holds the scene and every Cycles setting), the
  Blender version and its build hash; a clean checkout renders them afresh, a rerun
  reuses them. ``PETZVAL_BLENDER_NO_CACHE=1`` forces fresh Cycles renders.
- ``report``: result lines, printed as they come with -s (else collected in pytest's terminal
  summary at the end) and written to ``tests/out/blender/report.md``, so a passing run shows
  its numbers either way.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from suite_report import SuiteReport

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO / "tests" / "optics"))

from renders import cache_key, cached_render  # noqa: E402

import petzval_cli  # noqa: E402  (binary location/build shared with the optics suite)

OUT = REPO / "tests" / "out" / "blender"

_SUITE_REPORT = SuiteReport("Cycles comparison (tests/blender)", OUT)


@pytest.fixture(scope="session")
def report() -> SuiteReport:
    return _SUITE_REPORT


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    _SUITE_REPORT.terminal_summary(terminalreporter, config)


class BlenderRun:
    """One built scene: its GLB, cached Cycles renders and petzval renders."""

    def __init__(self, bpy, scenes, workdir: Path, cache_dir: Path, binary: Path):
        self.bpy = bpy
        self.S = scenes
        self.workdir = workdir
        self.cache_dir = cache_dir
        self.binary = binary
        self.glb = scenes.export_glb(workdir / "scene.glb")
        self.timings: dict[str, float] = {}  # wall seconds per render
        self.cpu_times: dict[str, float] = {}  # CPU seconds (all threads) of renders made in this run
        self.fresh_cycles: set[str] = set()
        self.stderr: dict[str, str] = {}

    def cycles(self, camera: str, seed: int, spp: int, cache: bool = True) -> Path:
        """Path of a Cycles render (rendered now unless cached); its time is in `timings`."""
        name = f"cycles_{camera}_spp{spp}_seed{seed}"

        def render(exr: Path) -> float:
            cpu0 = time.process_time()  # this process: Cycles renders in-process, on its own threads
            secs = self.S.render_cycles(self.S.CyclesSettings(samples=spp, seed=seed), camera, exr)
            self.cpu_times[name] = time.process_time() - cpu0
            return secs

        if cache:
            exr, self.timings[name], fresh = cached_render(self.bpy, self.cache_dir, name, render)
        else:
            exr = self.workdir / f"{name}.exr"
            self.timings[name], fresh = render(exr), True
        if fresh:
            self.fresh_cycles.add(name)
        return exr

    def petzval_cmd(self, args: list[str], seed: int, spp: int, out: Path) -> list[str]:
        w, h = self.S.RESOLUTION
        return [
            str(self.binary), "render", str(self.glb), "-o", str(out), "--no-png",
            *args,
            "--environment", self.S.world_rgb_arg(),
            "--max-depth", str(self.S.PETZVAL_MAX_DEPTH),
            "--resolution", f"{w}x{h}",
            "--spp", str(spp), "--seed", str(seed), "--threads", "2",
        ]

    def petzval(self, args: list[str], seed: int, spp: int, tag: str) -> Path:
        """Renders the exported GLB with petzval; returns the EXR (time in `timings`)."""
        out = self.workdir / f"petzval_{tag}_spp{spp}_seed{seed}.exr"
        cmd = self.petzval_cmd(args, seed, spp, out)
        ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        secs = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        self.cpu_times[out.stem] = (ru1.ru_utime + ru1.ru_stime) - (ru0.ru_utime + ru0.ru_stime)
        if proc.returncode != 0 or not out.is_file():
            raise AssertionError(f"`{' '.join(cmd)}` exited {proc.returncode}:\n{proc.stderr[-3000:]}")
        self.timings[out.stem] = secs
        self.stderr[out.stem] = proc.stderr
        return out


def _cache_key(bpy) -> str:
    return cache_key(bpy, "blender_scenes.py")


@pytest.fixture(scope="session")
def blender_run(report) -> BlenderRun:
    import bpy  # the test module is skipped before this when bpy cannot be imported

    import blender_scenes as scenes

    try:
        binary = petzval_cli.ensure_binary()
    except petzval_cli.PetzvalError as e:
        pytest.fail(f"cannot get the petzval binary: {e}", pytrace=False)
    key = _cache_key(bpy)
    workdir = OUT / "run"
    cache_dir = OUT / f"cycles-{key}"
    workdir.mkdir(parents=True, exist_ok=True)
    cache_dir.mkdir(parents=True, exist_ok=True)
    built = scenes.build_scene(workdir)
    run = BlenderRun(bpy, scenes, workdir, cache_dir, binary)
    report.line(
        f"Blender {built.blender_version} (bpy), Cycles CPU; petzval {binary}; cache {cache_dir.relative_to(REPO)}"
    )
    return run
