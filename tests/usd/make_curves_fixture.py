"""Writes usd/tests/data/curves/: `curves.usda` (one BasisCurves prim per type, basis and wrap),
`blender_hair.usda` (Blender 5.0's USD export of a Curves object with Catmull-Rom strands) and
`expected.json`: every curve's centre line evaluated here (pxr reads the stage; numpy evaluates
pxr's documented basis matrices, the pinned ends expanded as Hydra's
HdsiPinnedCurveExpandingSceneIndex does) and Blender's own evaluation of its strands (the Curves
object converted to a mesh: 12 points per span). usd/tests/curves.rs compares
petzval_usd::curves::centre_lines with both.

Run: .venv/bin/python tests/usd/make_curves_fixture.py
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

OUT = Path(__file__).resolve().parents[2] / "usd" / "tests" / "data" / "curves"
RINGS = 4

M = {
    "bezier": np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 3, 0, 0], [1, 0, 0, 0]], float),
    "bspline": np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 0, 3, 0], [1, 4, 1, 0]], float) / 6,
    "catmullRom": np.array([[-1, 3, -3, 1], [2, -5, 4, -1], [-1, 0, 1, 0], [0, 2, 0, 0]], float) / 2,
}
VSTEP = {"bezier": 3, "bspline": 1, "catmullRom": 1}

# (name, type, basis, wrap, counts): counts per curve
CASES = [
    ("linear_open", "linear", "bezier", "nonperiodic", [3, 4]),
    ("linear_closed", "linear", "bezier", "periodic", [4]),
    ("bezier_open", "cubic", "bezier", "nonperiodic", [4, 7]),
    ("bezier_closed", "cubic", "bezier", "periodic", [6]),
    ("bezier_pinned", "cubic", "bezier", "pinned", [7]),
    ("bspline_open", "cubic", "bspline", "nonperiodic", [4, 6]),
    ("bspline_closed", "cubic", "bspline", "periodic", [5]),
    ("bspline_pinned", "cubic", "bspline", "pinned", [2, 5]),
    ("catmullRom_open", "cubic", "catmullRom", "nonperiodic", [5]),
    ("catmullRom_closed", "cubic", "catmullRom", "periodic", [4]),
    ("catmullRom_pinned", "cubic", "catmullRom", "pinned", [2, 6]),
    ("bad_counts", "cubic", "bezier", "nonperiodic", [5, 4]),  # 5 cannot be a Bézier curve
]


def author(path: Path) -> None:
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    rng = np.random.default_rng(7)
    for name, ty, basis, wrap, counts in CASES:
        c = UsdGeom.BasisCurves.Define(stage, f"/C/{name}")
        pts = rng.uniform(-1, 1, (sum(counts), 3)).round(3)
        c.CreatePointsAttr([tuple(map(float, p)) for p in pts])
        c.CreateCurveVertexCountsAttr(counts)
        c.CreateTypeAttr(ty)
        c.CreateBasisAttr(basis)
        c.CreateWrapAttr(wrap)
        c.CreateWidthsAttr([0.05] * sum(counts))
        c.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    stage.GetRootLayer().Save()


def expand(n: int, basis: str, wrap: str) -> list[int] | None:
    """Hydra's pinned expansion: catmullRom repeats each end once, bspline twice."""
    if wrap == "pinned" and basis in ("bspline", "catmullRom"):
        k = 1 if basis == "catmullRom" else 2
        return [0] * k + list(range(n)) + [n - 1] * k if n >= 2 else None
    return list(range(n))


def evaluate(pts: np.ndarray, ty: str, basis: str, wrap: str, rings: int) -> list[list[float]]:
    n = len(pts)
    periodic = wrap == "periodic"
    if ty == "linear":
        if n < (3 if periodic else 2):
            return []
        segs = [(pts[i], pts[(i + 1) % n]) for i in range(n if periodic else n - 1)]
        out = [a for a, _ in segs] + ([] if periodic else [segs[-1][1]])
        return np.array(out).tolist()
    idx = expand(n, basis, wrap)
    if idx is None:
        return []
    m, v = len(idx), VSTEP[basis]
    if periodic:
        if m < 3 or m % v:
            return []
        segs = [[idx[(s * v + k) % m] for k in range(4)] for s in range(m // v)]
    else:
        if m < 4 or (m - 4) % v:
            return []
        segs = [[idx[s * v + k] for k in range(4)] for s in range((m - 4) // v + 1)]
    out = []
    for si, seg in enumerate(segs):
        ts = np.arange(rings + (1 if si == len(segs) - 1 and not periodic else 0)) / rings
        T = np.stack([ts**3, ts**2, ts, np.ones_like(ts)], 1)
        out.extend(T @ M[basis] @ pts[seg])
    return np.array(out).tolist()


def expected(path: Path, rings: int) -> dict:
    stage = Usd.Stage.Open(str(path))
    res = {}
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.BasisCurves):
            continue
        c = UsdGeom.BasisCurves(prim)
        pts = np.array(c.GetPointsAttr().Get(), float)
        counts = list(c.GetCurveVertexCountsAttr().Get())
        ty, basis, wrap = c.GetTypeAttr().Get(), c.GetBasisAttr().Get(), c.GetWrapAttr().Get()
        starts = np.cumsum([0, *counts])
        curves = [evaluate(pts[a:b], ty, basis, wrap, rings) for a, b in itertools.pairwise(starts)]
        extent = np.array(c.ComputeExtent(pts, c.GetWidthsAttr().Get())).tolist()
        res[str(prim.GetPath())] = {"curves": curves, "extent": extent}
    return res


def blender_hair(path: Path) -> dict:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    cu = bpy.data.hair_curves.new("Hair")
    counts = [4, 5, 6]
    cu.add_curves(counts)
    rng = np.random.default_rng(3)
    k = 0
    for i, n in enumerate(counts):
        for j in range(n):
            cu.points[k].position = (0.4 * i + rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), j * 0.25)
            cu.points[k].radius = 0.01 + 0.005 * j
            k += 1
    ob = bpy.data.objects.new("Hair", cu)
    bpy.context.scene.collection.objects.link(ob)
    bpy.ops.wm.usd_export(filepath=str(path))
    # Blender's evaluated strands: the object converted to a mesh (edges along each strand)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.convert(target="MESH")
    me = bpy.context.active_object.data
    co = np.array([v.co[:] for v in me.vertices])
    spans = [n - 1 for n in counts]
    starts = np.cumsum([0] + [12 * s + 1 for s in spans])
    assert starts[-1] == len(co), (starts, len(co))
    return {"resolution": 12, "curves": [co[a:b].tolist() for a, b in itertools.pairwise(starts)]}


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    author(OUT / "curves.usda")
    exp = {"rings": RINGS, "prims": expected(OUT / "curves.usda", RINGS)}
    exp["blender"] = blender_hair(OUT / "blender_hair.usda")
    exp["blender_prims"] = expected(OUT / "blender_hair.usda", 12)
    (OUT / "expected.json").write_text(json.dumps(exp))
    print("wrote", OUT)
