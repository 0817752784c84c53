"""A black glossy plane (or sphere) under a point light, Cycles against `petzval render` on
Blender's GLB export: a probe, not a test (pytest does not collect it). It prints the two image
sums per seed; docs/cycles-comparison.md ("Clear coat") quotes its output.

    .venv/bin/python tests/blender/probe_specular_fresnel.py ROUGHNESS plane|sphere

Needs the release binary (`cargo build --release`); writes under /tmp/petzval_probe_*.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bpy
from renders import run_petzval

import blender_compare as B
import blender_scenes as S

REPO = Path(__file__).resolve().parents[2]


def main() -> None:
    rough, shape = float(sys.argv[1]), sys.argv[2]
    wd = Path(f"/tmp/petzval_probe_{shape}_{rough}")
    wd.mkdir(exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    S.set_world_colour(bpy, scene, (0.0, 0.0, 0.0))
    mat = S._principled(bpy, "Spec", base=(0.0, 0.0, 0.0), roughness=rough)
    mat.node_tree.nodes.get("Principled BSDF").inputs["Specular IOR Level"].default_value = 0.5
    if shape == "sphere":
        S._add_mesh(bpy, "uv_sphere", "Ball", (0.0, 0.0, 0.0), mat, 0.5)
    else:
        S._add_mesh(bpy, "plane", "Floor", (0.0, 0.0, 0.0), mat, 4.0, smooth=False)
    # the light's mirror image is seen about 56° from the plane's normal
    S._add_light(bpy, "POINT", "Key", (0.0, 1.0, 1.0), 100.0)
    spec = S.pinhole_camera("C", (0.0, -2.0, 1.0), (0.0, 0.0, 0.0), 50.0)
    cam = S._add_camera(bpy, spec)
    cam.data.dof.use_dof = False
    scene.camera = cam
    res = (96, 64)
    scene.render.resolution_x, scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    glb = S.export_glb(wd / "scene.glb")
    args = S.pinhole_args(spec, (0.0, 0.0, 0.0), S.PETZVAL_MAX_DEPTH, res)
    sums = []
    for seed in (0, 1):
        S.render_cycles(S.CyclesSettings(samples=64, seed=seed), "C", wd / f"cycles{seed}.exr")
        run_petzval(REPO / "target" / "release" / "petzval", glb, wd / f"petzval{seed}.exr", args, 64, seed)
        c = float(B.read_rgb(wd / f"cycles{seed}.exr").sum())
        p = float(B.read_rgb(wd / f"petzval{seed}.exr").sum())
        sums.append(f"seed {seed}: Cycles {c:.1f}, petzval {p:.1f} ({p / c:.3f}x)")
    print(f"roughness {rough}, {shape}: " + "; ".join(sums))


if __name__ == "__main__":
    main()
