"""Anisotropic specular lobes against Cycles through Blender's GLB export: Principled BSDF
spheres with Anisotropic and Anisotropic Rotation (what `KHR_materials_anisotropy` carries;
Blender's exporter writes Anisotropic as the strength and the rotation in radians, and its
importer reads them back so, with Cycles' default tangent, radial about the object's Z axis),
lit by a point light and a grey world, rendered by Cycles from the .blend and by `petzval render`
from the export.

The whole image is compared in 8×8 blocks (z-test, two seeds a side; the criteria of
test_cycles_match.py), and each sphere's mean over the middle of its disc within 1 % or four
standard errors. The spheres: a gold metal (roughness 0.35, Anisotropic 0.7), a blue dielectric
(0.3, 0.5, turned 0.15 of a turn) and a near-white metal whose rough side saturates (roughness
0.7, Anisotropic 1: alpha along the tangent would be 1.55, Cycles clamps it to 1 and reads its
albedo tables at (alpha_x alpha_y)^(1/4)). Before session 35 the extension was listed as unsupported and the
spheres rendered isotropic (docs/cycles-comparison.md, "Anisotropy").
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

import blender_scenes as S

SPP = 128
SEEDS = (0, 1)
RESOLUTION = (192, 96)
WORLD_RGB = (0.3, 0.3, 0.32)
CAMERA = S.pinhole_camera("AnisoCam", (0.0, -6.0, 0.9), (0.0, 0.0, 0.0), 40.0)
SPHERE_RADIUS = 0.5
# (name, base colour, metallic, roughness, anisotropic, rotation (turns), x)
SPHERES = (
    ("BrushedGold", (1.0, 0.7, 0.3), 1.0, 0.35, 0.7, 0.0, -1.3),
    ("BrushedBlue", (0.1, 0.2, 0.6), 0.0, 0.3, 0.5, 0.15, 0.0),
    ("BrushedSilver", (0.9, 0.9, 0.9), 1.0, 0.7, 1.0, 0.0, 1.3),
)
MAX_MEAN_Z2 = 1.5
MAX_ABS_Z = 5.0
MEAN_TOL = 0.01


def _brushed(name, base, metallic, roughness, anisotropic, rotation):
    mat = S._principled(bpy, name, base=base, roughness=roughness)
    p = mat.node_tree.nodes.get("Principled BSDF")
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Anisotropic"].default_value = anisotropic
    p.inputs["Anisotropic Rotation"].default_value = rotation
    if metallic == 0.0:
        p.inputs["Specular IOR Level"].default_value = 0.5
    return mat


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the anisotropic spheres' scene."""

    def materials():
        spheres = [(name, _brushed(name, *rest[:-1]), rest[-1]) for name, *rest in SPHERES]
        return S._principled(bpy, "Floor", base=(0.5, 0.5, 0.5)), spheres

    light = ((2.0, -2.5, 2.5), 300.0)
    S.spheres_on_floor(tmpdir, WORLD_RGB, materials, SPHERE_RADIUS, light, CAMERA, RESOLUTION)


@pytest.fixture(scope="module")
def aniso_run(blender_run):
    """The scene's export and renders; afterwards rebuilds the main scene, which the other
    modules' tests read from Blender."""
    xs = [x for *_, x in SPHERES]
    yield from S.sphere_scene_renders(
        blender_run, "anisotropy", ("test_anisotropy_cycles.py", "blender_scenes.py"), build_scene, CAMERA,
        WORLD_RGB, RESOLUTION, SPP, SEEDS, xs, SPHERE_RADIUS,
    )  # fmt: skip


def test_anisotropic_spheres_match_cycles_through_gltf(aniso_run, report):
    glb, cyc, pz, windows = aniso_run
    # the export carries the lobes as KHR_materials_anisotropy
    from test_cycles_match import _glb_json

    doc = _glb_json(glb)
    assert str(doc.get("asset", {}).get("generator", "")).startswith("Khronos glTF Blender I/O"), doc.get("asset")
    exts = {
        m["name"]: m.get("extensions", {}).get("KHR_materials_anisotropy") for m in doc["materials"] if "name" in m
    }
    for name, _base, _metallic, _roughness, anisotropic, rotation, _x in SPHERES:
        ext = exts.get(name)
        assert ext is not None, f"{name}: no KHR_materials_anisotropy in the export ({exts})"
        assert math.isclose(ext.get("anisotropyStrength", 0.0), anisotropic, abs_tol=1e-6), ext
        assert math.isclose(ext.get("anisotropyRotation", 0.0), rotation * 2 * math.pi, abs_tol=1e-5), ext

    names = [name for name, *_ in SPHERES]
    label = f"anisotropy (glTF path): {len(SPHERES)} brushed spheres vs Cycles, {SPP} spp"
    S.assert_spheres_match(cyc, pz, windows, names, label, report, MAX_MEAN_Z2, MAX_ABS_Z, MEAN_TOL)
