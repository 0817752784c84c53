"""Specular Tint on the dielectric part of a Principled BSDF against Cycles, through Blender's
GLB export: three glossy spheres with coloured or grey tints (Specular IOR Level 0.5 and 1,
roughness 0.2 to 0.45, over black, white and blue bases) on a matte floor, under a point light
and a grey world, rendered by Cycles from the .blend and by `petzval render` from the export.

Blender's exporter writes the tint into `KHR_materials_specular`'s specularColorFactor (times
the level × 2 where that is above 1). Cycles' layer reflects F0 × tint head-on and 1 at grazing
(its generalized Schlick over the exact Fresnel curve), and dims the base under it by the
layer's brightest channel. Until session 29 petzval used the colour's mean as a level: the
black sphere's highlight came out grey. The image means per channel must agree within 1 %,
each sphere's mean within 1 % (or four standard errors), and the 8×8 blocks pass the z-test of
test_cycles_match.py (session 29: mean z² 1.16, max |z| 3.99; with the mean-as-level of before,
mean z² 17.9, max |z| 23.9, the black sphere's red 0.68× and blue 1.40× Cycles'). While the
uniform world was still a light, next-event estimation chose the point light half of the time
and the sharpest highlight's tail block came out at z −8.5.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

import blender_compare as B
import blender_scenes as S

SPP = 128
SEEDS = (0, 1)
RESOLUTION = (192, 96)
WORLD_RGB = (0.3, 0.3, 0.32)
CAMERA = S.pinhole_camera("TintCam", (0.0, -6.0, 1.4), (0.0, 0.0, -0.4), 40.0)
SPHERE_RADIUS = 0.5
# (name, base colour, roughness, Specular IOR Level, Specular Tint, x)
SPHERES = (
    ("BlackOrangeTint", (0.02, 0.02, 0.02), 0.2, 0.5, (1.0, 0.35, 0.1), -1.3),
    ("WhiteBlueTintLevel1", (0.8, 0.8, 0.8), 0.45, 1.0, (0.2, 0.6, 1.0), 0.0),
    ("BlueGreyTint", (0.1, 0.2, 0.6), 0.3, 0.5, (0.5, 0.5, 0.5), 1.3),
)
MAX_MEAN_Z2 = 1.5
MAX_ABS_Z = 5.0
MEAN_TOL = 0.01


def _tinted(name, base, roughness, level, tint):
    mat = S._principled(bpy, name, base=base, roughness=roughness)
    p = mat.node_tree.nodes.get("Principled BSDF")
    p.inputs["Specular IOR Level"].default_value = level
    p.inputs["Specular Tint"].default_value = (*tint, 1.0)
    return mat


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the tinted scene (a matte, untinted floor)."""

    def materials():
        spheres = [(name, _tinted(name, *args), x) for name, *args, x in SPHERES]
        return S._principled(bpy, "MatteFloor", base=(0.45, 0.45, 0.45), roughness=1.0), spheres

    light = ((0.5, 2.5, 2.0), 300.0)
    S.spheres_on_floor(tmpdir, WORLD_RGB, materials, SPHERE_RADIUS, light, CAMERA, RESOLUTION)


@pytest.fixture(scope="module")
def tint_run(blender_run):
    """The tinted scene's renders and the spheres' windows."""
    yield from S.sphere_scene_renders(
        blender_run, "specular_tint", ("test_specular_tint_cycles.py", "blender_scenes.py"), build_scene, CAMERA,
        WORLD_RGB, RESOLUTION, SPP, SEEDS, [x for *_, x in SPHERES], SPHERE_RADIUS,
    )  # fmt: skip


def test_specular_tint_matches_cycles(tint_run, report):
    """The image means per channel within 1 %; each sphere's mean over the middle of its disc
    within 1 % or four standard errors, and the 8×8-block z-test."""
    _, cyc, pz, windows = tint_run
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    report.line(
        f"specular tint (glTF path), {SPP} spp: image mean petzval/Cycles R,G,B "
        f"{ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}"
    )
    assert np.all(np.abs(ratio - 1.0) <= MEAN_TOL), f"image mean ratio {ratio}"
    label = "specular tint (glTF path), 3 tinted glossy spheres vs Cycles"
    names = [name for name, *_ in SPHERES]
    S.assert_spheres_match(cyc, pz, windows, names, label, report, MAX_MEAN_Z2, MAX_ABS_Z, MEAN_TOL)
