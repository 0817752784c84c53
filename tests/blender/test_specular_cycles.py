"""Dielectric specular layers against Cycles through Blender's GLB export: a glossy ground and
three glossy spheres (Specular IOR Level 0.5, 0.25 and 1, roughness 0.15 to 0.6, over coloured,
white and black bases) under a point light and a grey world, rendered by Cycles from the .blend
and by `petzval render` from the export (`KHR_materials_specular` carries the level × 2 as
specularFactor).

Cycles' Principled BSDF reflects by the exact dielectric Fresnel of the index whose F0 is
F0(IOR) × 2 × level; petzval used Schlick's Fresnel until session 26, which made the ground's
reflection of the light, seen about 60° off its normal, a quarter too dark. The image means
per channel must agree within 1 % and each sphere's mean within 1 % (or four standard errors).
The 8×8-block z-test of test_cycles_match.py is an expected failure: the ground seen at grazing
angles is 0.2–0.6 % brighter than Cycles' (mean z² 1.6–1.8); before session 26 the ground's
reflection of the light was 25 % dark and the sphere of level 1 41 % dark (mean z² 6 571, max
|z| 695, image means 0.953–0.972).
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
CAMERA = S.pinhole_camera("SpecCam", (0.0, -6.0, 1.4), (0.0, 0.0, -0.4), 40.0)
SPHERE_RADIUS = 0.5
# (name, base colour, roughness, Specular IOR Level, x)
GROUND = ("GlossyGround", (0.2, 0.3, 0.5), 0.35, 0.5)
SPHERES = (
    ("RedGloss", (0.7, 0.08, 0.05), 0.25, 0.5, -1.3),
    ("WhiteHalfLevel", (0.8, 0.8, 0.8), 0.6, 0.25, 0.0),
    ("BlackLevel1", (0.02, 0.02, 0.02), 0.15, 1.0, 1.3),
)
MAX_MEAN_Z2 = 1.5
MAX_ABS_Z = 5.0
MEAN_TOL = 0.01


def _glossy(name, base, roughness, level):
    mat = S._principled(bpy, name, base=base, roughness=roughness)
    mat.node_tree.nodes.get("Principled BSDF").inputs["Specular IOR Level"].default_value = level
    return mat


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the glossy scene."""

    def materials():
        spheres = [(name, _glossy(name, base, roughness, level), x) for name, base, roughness, level, x in SPHERES]
        return _glossy(*GROUND), spheres

    light = ((0.5, 2.5, 2.0), 300.0)
    S.spheres_on_floor(tmpdir, WORLD_RGB, materials, SPHERE_RADIUS, light, CAMERA, RESOLUTION)

@pytest.fixture(scope="module")
def specular_run(blender_run):
    """The glossy scene's renders and the spheres' windows; afterwards rebuilds the main scene,
    which the other modules' tests read from Blender."""
    xs = [x for *_, x in SPHERES]
    yield from S.sphere_scene_renders(
        blender_run, "specular", ("test_specular_cycles.py", "blender_scenes.py"), build_scene, CAMERA,
        WORLD_RGB, RESOLUTION, SPP, SEEDS, xs, SPHERE_RADIUS,
    )  # fmt: skip


def test_specular_layers_match_cycles_on_average(specular_run, report):
    """The image means per channel within 1 %, and each sphere's mean over the middle of its
    disc within 1 % or four standard errors."""
    _, cyc, pz, windows = specular_run
    ratio = B.mean_ratio((pz[0] + pz[1]) / 2, (cyc[0] + cyc[1]) / 2)
    spheres = [(name, r, se) for (name, *_), (r, se) in zip(SPHERES, S.window_means(cyc, pz, windows), strict=True)]
    report.line(
        f"specular layers (glTF path), a glossy ground and 3 glossy spheres (levels 0.5, 0.25, 1) vs Cycles, "
        f"{RESOLUTION[0]}x{RESOLUTION[1]} {SPP} spp x seeds {SEEDS}: image mean petzval/Cycles R,G,B "
        f"{ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}; spheres "
        + "; ".join(f"{n} " + " ".join(f"{x:.4f}" for x in r) for n, r, _ in spheres)
    )
    assert np.all(np.abs(ratio - 1.0) <= MEAN_TOL), f"image mean ratio {ratio}"
    for name, r, se in spheres:
        assert np.all(np.abs(r - 1.0) <= np.maximum(MEAN_TOL, 4 * se)), f"{name}: sphere mean ratio {r} ± {se}"


@pytest.mark.xfail(
    strict=False,
    reason="the glossy ground seen at grazing angles (the rows below the horizon) is 0.2-0.6 % brighter "
    "than Cycles' (mean z² 1.6-1.8, max |z| 4-7.5 in session 26; 1.53 and 4.72 in session 29, once the uniform "
    "world stopped being a light); docs/cycles-comparison.md, 'Specular layers'",
)
def test_specular_layers_match_cycles_block_for_block(specular_run, report):
    _, cyc, pz, _ = specular_run
    z = B.compare_blocks(cyc[0], cyc[1], pz[0], pz[1]).z
    mean_z2, max_abs_z = float(np.mean(z**2)), float(np.max(np.abs(z)))
    report.line(
        f"specular layers (glTF path), blocks: mean z² {mean_z2:.3f} (≤ {MAX_MEAN_Z2}), max |z| {max_abs_z:.2f} "
        f"(≤ {MAX_ABS_Z})"
    )
    assert mean_z2 <= MAX_MEAN_Z2 and max_abs_z <= MAX_ABS_Z, f"blocks: mean z² {mean_z2:.3f}, max |z| {max_abs_z:.2f}"
