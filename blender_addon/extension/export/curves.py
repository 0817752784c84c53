"""Blender Curves objects (hair curves) as ``Scene.add_curves`` tubes, read as Cycles 5.0 reads
them (``intern/cycles/blender/curves.cpp``: ``export_hair_curves``, ``sync_hair``).

| Curves data | read as | when missing |
|---|---|---|
| ``position`` (point) | control points, object space | — |
| ``radius`` (point) | tube radius | :data:`DEFAULT_RADIUS` (Cycles' fallback) |
| ``curve_offset_data`` | points per curve | — |
| ``curve_type`` (curve) | the first curve's, for all (Cycles): POLY straight; others Catmull-Rom [1] | Catmull-Rom |
| ``cyclic`` (curve) | ignored: Cycles renders every hair curve open | — |
| ``material_index`` (curve) | ignored: Cycles renders every strand with the object's first material slot | — |
| other attributes (colours, UVs, ``tilt``) | ignored | — |

[1] through the control points, pinned to the end points; Bézier handles, NURBS weights and
knots ignored, as Cycles does.

Legacy particle hair (a mesh's Particle System of type Hair) is not read: it is listed as
unsupported (convert it to a Curves object).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_RADIUS", "curves_data", "particle_hair_note"]

# Cycles' radius for a Curves point without a ``radius`` attribute (0.01 m wide strands).
DEFAULT_RADIUS = 0.005
# Blender's ``curve_type`` values used here.
CATMULL_ROM, POLY = 0, 1


def _attr(cu, name: str, prop: str, n: int, width: int, dtype):
    """Attribute ``name`` as an (n,) or (n, width) array, or None when absent or mis-sized."""
    a = cu.attributes.get(name)
    if a is None or len(a.data) != n:
        return None
    out = np.empty(n * width, dtype=dtype)
    a.data.foreach_get(prop, out)
    return out.reshape(n, width) if width > 1 else out


def curves_data(cu) -> dict | None:
    """The arguments of ``Scene.add_curves`` (without materials and transform) for Curves
    data-block ``cu``; None when it has no points."""
    n = len(cu.points)
    if n == 0 or len(cu.curves) == 0:
        return None
    # Step 1: points and radii
    positions = _attr(cu, "position", "vector", n, 3, np.float32)
    if positions is None:
        return None
    radii = _attr(cu, "radius", "value", n, 1, np.float32)
    if radii is None:
        radii = np.full(n, DEFAULT_RADIUS, dtype=np.float32)
    # Step 2: points per curve, and Cycles' one basis for the object (from the first curve)
    offsets = np.empty(len(cu.curves) + 1, dtype=np.int32)
    cu.curve_offset_data.foreach_get("value", offsets)
    counts = np.diff(offsets).astype(np.int64)
    types = _attr(cu, "curve_type", "value", len(counts), 1, np.int32)
    poly = types is not None and int(types[0]) == POLY
    return {
        "positions": positions.astype(np.float64),
        "radii": np.maximum(radii.astype(np.float64), 0.0),
        "counts": counts,
        "curve_types": np.full(len(counts), POLY if poly else CATMULL_ROM, dtype=np.int64),
    }


def particle_hair_note(obj) -> str | None:
    """A note for an object's legacy particle hair systems (not rendered), or None."""
    names = [ps.name for ps in getattr(obj, "particle_systems", ())
             if ps.settings is not None and ps.settings.type == "HAIR" and ps.settings.render_type == "PATH"]
    if not names:
        return None
    return f"particle hair ('{obj.name}': {', '.join(names)}; convert it to a Curves object)"
