"""Vertex colours against Cycles through Blender's GLB export: spheres whose Base Color comes
from a Color Attribute node (a per-corner colour that varies across each sphere), which
Blender's exporter writes as the primitive's `COLOR_0` with a white base colour factor, and
which glTF multiplies into the base colour. Rendered by Cycles from the .blend and by
`petzval render` from the export, under a point light and a grey world.

The whole image is compared in 8×8 blocks (z-test, two seeds a side; the criteria of
test_cycles_match.py), and each sphere's mean over the middle of its disc within 1 % or four
standard errors. Before session 27 `COLOR_0` was not read: the spheres rendered white (the
binary from before gives mean z² in the thousands on this scene; docs/cycles-comparison.md,
"Vertex colours").
"""

from __future__ import annotations

from pathlib import Path

import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

import blender_scenes as S

SPP = 64
SEEDS = (0, 1)
RESOLUTION = (192, 96)
WORLD_RGB = (0.3, 0.3, 0.32)
CAMERA = S.pinhole_camera("VertexColourCam", (0.0, -6.0, 0.9), (0.0, 0.0, 0.0), 40.0)
SPHERE_RADIUS = 0.5
# (name, roughness, x): each sphere's colour runs red → green across it and blue with height
SPHERES = (
    ("PaintedMatte", 1.0, -1.3),
    ("PaintedSatin", 0.5, 0.0),
    ("PaintedDark", 0.8, 1.3),
)
MAX_MEAN_Z2 = 1.5
MAX_ABS_Z = 5.0
MEAN_TOL = 0.01


def _painted(name: str, roughness: float):
    mat = S._principled(bpy, name, roughness=roughness)
    nt = mat.node_tree
    attr = nt.nodes.new("ShaderNodeVertexColor")
    attr.layer_name = "Paint"
    nt.links.new(attr.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def _paint(obj, scale: float) -> None:
    """A per-corner colour attribute "Paint": red → green along x, blue with height, times
    `scale`, and each face's corners a little apart (so the colours are per corner)."""
    me = obj.data
    paint = me.color_attributes.new("Paint", "FLOAT_COLOR", "CORNER")
    for loop in me.loops:
        co = me.vertices[loop.vertex_index].co / SPHERE_RADIUS
        u = 0.5 + 0.5 * co.x
        rgb = (0.9 * u, 0.9 * (1.0 - u), 0.2 + 0.6 * (0.5 + 0.5 * co.z))
        paint.data[loop.index].color = (*(c * scale * (1.0 - 0.1 * (loop.index % 2)) for c in rgb), 1.0)


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the painted spheres' scene."""

    def materials():
        spheres = [(name, _painted(name, rough), x) for name, rough, x in SPHERES]
        return S._principled(bpy, "Floor", base=(0.5, 0.5, 0.5)), spheres

    light = ((2.0, -2.5, 2.5), 300.0)
    S.spheres_on_floor(tmpdir, WORLD_RGB, materials, SPHERE_RADIUS, light, CAMERA, RESOLUTION)
    for (name, *_), scale in zip(SPHERES, (1.0, 1.0, 0.3), strict=True):
        _paint(bpy.data.objects[name], scale)


@pytest.fixture(scope="module")
def painted_run(blender_run):
    """The painted scene's export and renders; afterwards rebuilds the main scene, which the
    other modules' tests read from Blender."""
    xs = [x for *_, x in SPHERES]
    yield from S.sphere_scene_renders(
        blender_run, "vertex-colours", ("test_vertex_colors_cycles.py", "blender_scenes.py"), build_scene, CAMERA,
        WORLD_RGB, RESOLUTION, SPP, SEEDS, xs, SPHERE_RADIUS,
    )  # fmt: skip


def test_painted_spheres_match_cycles_through_gltf(painted_run, report):
    glb, cyc, pz, windows = painted_run
    # the export carries the colours as COLOR_0, with a white base colour
    from test_cycles_match import _glb_json

    doc = _glb_json(glb)
    nodes = {n["name"]: n for n in doc["nodes"]}
    for name, *_ in SPHERES:
        prims = doc["meshes"][nodes[name]["mesh"]]["primitives"]
        assert all("COLOR_0" in p["attributes"] for p in prims), f"{name}: no COLOR_0 in the export"

    names = [name for name, *_ in SPHERES]
    label = f"vertex colours (glTF COLOR_0): {len(SPHERES)} painted spheres vs Cycles, {SPP} spp"
    S.assert_spheres_match(cyc, pz, windows, names, label, report, MAX_MEAN_Z2, MAX_ABS_Z, MEAN_TOL)
