"""Linear-interpolated 8-bit sRGB images against Cycles through Blender's GLB export. Cycles
keeps an image in the sRGB colour space encoded (`compress_as_srgb`), filters the encoded
values and decodes after; glTF's spec asks for decoding before filtering. Between two texels of
a coarse checker the two differ by up to ~80 %, and on a checker floor seen at a few texels per
pixel by ~5 % in the mean. petzval filters the colour images of files Blender wrote (asset
generator "Khronos glTF Blender I/O") as Cycles does, and every other file's by the spec.

The scene: an 8×8 checker (8-bit sRGB PNG, Linear interpolation) stretched over a 20 m floor
and over a sphere, a plain sphere, a point light and a grey world. The whole image is compared in
8×8 blocks (z-test, two seeds a side; the criteria of test_cycles_match.py) and the spheres'
means. The negative control is the same export with its generator string changed: it is then
filtered by the spec, and must fail the same z-test by far (docs/cycles-comparison.md, "Image
filtering").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

try:
    import bpy
except Exception as e:  # ImportError, or a broken install
    pytest.skip(f"Blender's Python module cannot be imported ({type(e).__name__}: {e})", allow_module_level=True)

from renders import edit_glb, run_petzval

import blender_compare as B
import blender_scenes as S

SPP = 64
SEEDS = (0, 1)
RESOLUTION = (192, 96)
WORLD_RGB = (0.3, 0.3, 0.32)
CAMERA = S.pinhole_camera("CheckerCam", (0.0, -6.0, 1.6), (0.0, 0.0, 0.0), 35.0)
SPHERE_RADIUS = 0.5
SPHERES = (("CheckerBall", -0.8), ("PlainBall", 0.8))
MAX_MEAN_Z2 = 1.5
MAX_ABS_Z = 5.0
MEAN_TOL = 0.01


def build_scene(tmpdir: Path) -> None:
    """Resets Blender and builds the checker scene."""

    def materials():
        image = S._checker_image(bpy, tmpdir, n_tiles=8, px_per_tile=1, light=220, dark=30)
        floor = S._principled(bpy, "CheckerFloor", image=image)
        ball = S._principled(bpy, "CheckerBallMat", image=image)
        for mat in (floor, ball):
            mat.node_tree.nodes["Image Texture"].interpolation = "Linear"
        plain = S._principled(bpy, "PlainMat", base=(0.6, 0.6, 0.6))
        return floor, [("CheckerBall", ball, SPHERES[0][1]), ("PlainBall", plain, SPHERES[1][1])]

    S.spheres_on_floor(tmpdir, WORLD_RGB, materials, SPHERE_RADIUS, ((2.0, -2.5, 2.5), 300.0), CAMERA, RESOLUTION)


@pytest.fixture(scope="module")
def checker_run(blender_run):
    """The checker scene's export and renders: (glb, Cycles images, petzval images, the
    spheres' windows); afterwards rebuilds the main scene, which the other modules' tests read
    from Blender."""
    key_files = ("test_texture_filtering_cycles.py", "blender_scenes.py")
    xs = [x for _, x in SPHERES]
    yield from S.sphere_scene_renders(
        blender_run, "texture-filtering", key_files, build_scene, CAMERA, WORLD_RGB, RESOLUTION, SPP, SEEDS, xs,
        SPHERE_RADIUS,
    )  # fmt: skip


def test_linear_checker_matches_cycles_through_gltf(checker_run, report):
    glb, cyc, pz, windows = checker_run
    from test_cycles_match import _glb_json

    doc = _glb_json(glb)
    assert doc["asset"]["generator"].startswith("Khronos glTF Blender I/O"), doc["asset"]
    assert doc["samplers"][0].get("magFilter") == 9729, "the export's sampler is not LINEAR"
    names = [name for name, _ in SPHERES]
    label = f"Linear 8-bit sRGB checker (glTF, Blender-written): floor and sphere vs Cycles, {SPP} spp"
    S.assert_spheres_match(cyc, pz, windows, names, label, report, MAX_MEAN_Z2, MAX_ABS_Z, MEAN_TOL)


def test_spec_filtering_is_the_negative_control(checker_run, blender_run, report):
    """The same export, said to be written by another tool: decoded before filtering, as the glTF
    spec asks. The z-test that the Blender-written file passes fails by far."""
    glb, cyc, *_ = checker_run
    other = edit_glb(glb, glb.with_name("spec.glb"), lambda doc: doc["asset"].update(generator="another exporter"))
    args = S.pinhole_args(CAMERA, WORLD_RGB, S.PETZVAL_MAX_DEPTH, RESOLUTION)
    spec = []
    for seed in SEEDS:
        out = glb.with_name(f"spec_seed{seed}.exr")
        run_petzval(blender_run.binary, other, out, args, SPP, seed)
        spec.append(B.read_rgb(out))
    z = B.compare_blocks(cyc[0], cyc[1], spec[0], spec[1]).z
    mean_z2 = float(np.mean(z**2))
    ratio = float(np.mean(spec[0] + spec[1]) / np.mean(cyc[0] + cyc[1]))
    report.line(
        f"Linear checker, filtered by the glTF spec (negative control): blocks mean z² {mean_z2:.1f} "
        f"(must exceed {20 * MAX_MEAN_Z2}), image mean {ratio:.4f}× Cycles'"
    )
    assert mean_z2 > 20 * MAX_MEAN_Z2, f"the spec's filtering passes the z-test (mean z² {mean_z2:.2f})"
