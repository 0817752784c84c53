"""The renders of the Blender comparisons: cached Cycles renders (tests/out is gitignored) and
petzval runs.

A Cycles render is kept as ``NAME.exr`` with ``NAME.json`` (its wall seconds and Blender's version) in
a cache folder whose name carries :func:`cache_key`: the hash of the scene-building modules and
of Blender's version and build, so a change to a scene or to Blender renders anew.
``PETZVAL_BLENDER_NO_CACHE=1`` renders anew regardless.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

HERE = Path(__file__).resolve().parent


def cache_key(bpy, *modules: str) -> str:
    """16 hex digits of the hash of `modules` (file names beside this one) and of Blender."""
    h = hashlib.sha256()
    for f in modules:
        h.update((HERE / f).read_bytes())
    h.update(bpy.app.version_string.encode())
    h.update(bpy.app.build_hash if isinstance(bpy.app.build_hash, bytes) else str(bpy.app.build_hash).encode())
    return h.hexdigest()[:16]


def cached_render(bpy, cache_dir: Path, name: str, render: Callable[[Path], float]) -> tuple[Path, float, bool]:
    """The EXR of render `name` in `cache_dir`, its wall seconds and whether it was rendered now:
    from the cache when there, else `render(exr_path)` (which returns its seconds) is run."""
    exr, meta = cache_dir / f"{name}.exr", cache_dir / f"{name}.json"
    if exr.is_file() and meta.is_file() and not os.environ.get("PETZVAL_BLENDER_NO_CACHE"):
        return exr, json.loads(meta.read_text())["seconds"], False
    seconds = render(exr)
    meta.write_text(json.dumps({"seconds": seconds, "blender": bpy.app.version_string}))
    return exr, seconds, True


def run_petzval(binary: Path, glb: Path, out: Path, args: list[str], spp: int, seed: int) -> tuple[float, str]:
    """Renders `glb` with `petzval render ARGS` at `spp` and `seed` on 2 threads into `out`
    (no PNG); returns the process's wall seconds and its stderr, or fails naming the command."""
    cmd = [
        str(binary), "render", str(glb), "-o", str(out), "--no-png", *args,
        "--spp", str(spp), "--seed", str(seed), "--threads", "2",
    ]  # fmt: skip
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0 or not out.is_file():
        raise AssertionError(f"`{' '.join(cmd)}` exited {proc.returncode}:\n{proc.stderr[-3000:]}")
    return seconds, proc.stderr


def edit_glb(glb: Path, out: Path, edit: Callable[[dict], None]) -> Path:
    """A copy of `glb` at `out` with its JSON chunk changed in place by `edit(doc)` (the binary
    chunk kept): for negative controls that remove or alter one thing in an export."""
    import struct

    data = glb.read_bytes()
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20 : 20 + json_len])
    edit(doc)
    chunk = json.dumps(doc).encode()
    chunk += b" " * (-len(chunk) % 4)
    rest = data[20 + json_len :]
    header = struct.pack("<4sII", b"glTF", 2, 20 + len(chunk) + len(rest)) + struct.pack("<I4s", len(chunk), b"JSON")
    out.write_bytes(header + chunk + rest)
    return out


def scene_pairs(blender_run, name: str, key_files, build, camera: str, args: list[str], spp: int, seeds, export=None):
    """For a test module's fixture: builds a scene with `build(workdir)`, exports it as GLB
    (`export(path)`, default the suite's static export) and renders it with Cycles from `camera`
    (cached by `key_files`' text) and with `petzval render ARGS`, once per seed: (glb, Cycles
    images, petzval images, the workdir). The caller rebuilds the main scene afterwards."""
    import blender_compare as B
    import blender_scenes as S

    bpy = S._import_bpy()
    workdir = blender_run.workdir / name
    cache_dir = blender_run.cache_dir.parent / f"cycles-{name}-{cache_key(bpy, *key_files)}"
    cache_dir.mkdir(parents=True, exist_ok=True)
    build(workdir)
    glb = (export or S.export_glb)(workdir / f"{name}.glb")
    cyc, pz = [], []
    for seed in seeds:
        cfg = S.CyclesSettings(samples=spp, seed=seed)
        render = lambda out, cfg=cfg: S.render_cycles(cfg, camera, out)  # noqa: E731
        exr, _, _ = cached_render(bpy, cache_dir, f"cycles_spp{spp}_seed{seed}", render)
        cyc.append(B.read_rgb(exr))
        out = workdir / f"petzval_seed{seed}.exr"
        run_petzval(blender_run.binary, glb, out, args, spp, seed)
        pz.append(B.read_rgb(out))
    return glb, cyc, pz, workdir


def pinhole_glb_args(camera: str, world_rgb, resolution: tuple[int, int], sensor_mm: float = 36.0) -> list[str]:
    """`petzval render` options for a pinhole Blender camera by name (no depth of field), its
    sensor width, Cycles' 1.5 px filter, the world colour and the bounce limit."""
    import blender_scenes as S

    w, h = resolution
    return [
        "--camera", camera, "--lens", "pinhole", "--sensor-width", f"{sensor_mm:g}", "--natural-vignetting", "off",
        "--filter-width", "1.5", "--environment", ",".join(str(c) for c in world_rgb),
        "--max-depth", str(S.PETZVAL_MAX_DEPTH), "--resolution", f"{w}x{h}",
    ]  # fmt: skip
