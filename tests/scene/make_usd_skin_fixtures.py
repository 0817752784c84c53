"""Writes usd/tests/data/skel/ for usd/tests/stage.rs's UsdSkel tests, with two references
nobody here wrote:

- `skinned.usdc`: the scene of make_gltf_skin_fixtures.py (a tube bent by an animated two-bone
  armature, an icosphere with two shape keys, one animated) exported by Blender's USD exporter
  (bpy 5.0.1) with its animation: a Skeleton with a SkelAnimation, BlendShapes weighted by a
  SkelAnimation's blendShapeWeights;
- `frame_F.json` (F = 1, 7, 13, 24): per mesh prim, Pixar's UsdSkel (usd-core,
  `UsdSkel.BakeSkinning`) posed points in the stage's world space at time code F, and Blender's
  own evaluated mesh at frame F (world-space vertex positions and normals; Blender's axes are
  the stage's: z up, metres), rounded to 10⁻⁶.

bpy bundles its own pxr, so the export and the bake run in separate processes. Usage:
.venv/bin/python tests/scene/make_usd_skin_fixtures.py
"""

import json
import subprocess
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[2] / "usd" / "tests" / "data" / "skel"
FRAMES = (1, 7, 13, 24)


def export_with_blender() -> None:
    """The scene from Blender: the USD file and Blender's evaluated meshes per frame."""
    import bpy

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import make_gltf_skin_fixtures as scene

    scene.build()
    blender = {}
    for f in FRAMES:
        bpy.context.scene.frame_set(f)
        blender[f] = scene.evaluated_meshes(y_up=False)
    (OUT / "blender.json").write_text(json.dumps(blender))
    bpy.context.scene.frame_set(1)
    bpy.ops.wm.usd_export(filepath=str(OUT / "skinned.usdc"), export_animation=True)


def bake_with_pxr() -> None:
    """Pixar's UsdSkel posing of the exported file; written beside Blender's meshes."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel

    blender = json.loads((OUT / "blender.json").read_text())
    (OUT / "blender.json").unlink()
    stage = Usd.Stage.Open(str(OUT / "skinned.usdc"))
    if not UsdSkel.BakeSkinning(stage.Traverse()):
        raise SystemExit("UsdSkel.BakeSkinning failed")
    for f in FRAMES:
        pxr = {}
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh):
                points = UsdGeom.Mesh(prim).GetPointsAttr().Get(f)
                xf = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(f)
                pxr[str(prim.GetPath())] = [[round(x, 6) for x in xf.Transform(Gf.Vec3d(*p))] for p in points]
        doc = {"pxr_points": pxr, "blender": blender[str(f)]}
        (OUT / f"frame_{f}.json").write_text(json.dumps(doc, separators=(",", ":")) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] == ["--export"]:
        export_with_blender()
    elif sys.argv[1:] == ["--bake"]:
        bake_with_pxr()
    else:
        OUT.mkdir(parents=True, exist_ok=True)
        for step in ("--export", "--bake"):
            subprocess.run([sys.executable, __file__, step], check=True, capture_output=step == "--export")
