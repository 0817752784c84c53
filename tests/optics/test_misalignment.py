"""Decentred and tilted elements (the lens format's ``decenter_*``/``tilt_*`` fields) against
optiland's coordinate systems.

The lens: a wide stop, a decentred and tilted singlet, and a cemented doublet decentred and
tilted as one body (the misalignment on its first surface moves all three of its surfaces).
optiland places every surface by its own absolute coordinate system (``x, y, z, rx, ry``;
``globalize`` applies rx, then ry, then the translation, the same order as ours); each surface
of a misaligned element sits at ``pivot + offset + R (0, 0, z - z_pivot)`` with the element's
rotation. Real rays traced scene → film by ``petzval lens trace`` must meet the image plane
where optiland's do, to 1e-6 mm, and the same rays must be absorbed.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import optiland.backend as be
import pytest
from optiland.materials import IdealMaterial
from optiland.optic import Optic
from optiland.physical_apertures import RadialAperture
from optiland.rays import RealRays

import petzval_cli as pz

INTERCEPT_TOL_MM = 1e-6

# (radius, thickness, index after, semi-diameter, stop, misalignment (dx, dy, tx_deg, ty_deg))
SURFACES = [
    (0.0, 5.0, 1.0, 20.0, True, None),
    (60.0, 6.0, 1.5168, 15.0, False, (0.6, -0.3, 1.2, -2.0)),
    (-60.0, 4.0, 1.0, 15.0, False, None),
    (40.0, 8.0, 1.62, 12.0, False, (-0.25, 0.4, -0.8, 1.5)),
    (-30.0, 2.0, 1.75, 12.0, False, None),
    (-120.0, 50.0, 1.0, 12.0, False, None),
]


def lens_toml() -> str:
    out = ['[lens]\nname = "misaligned test lens"\nsource = "tests/optics/test_misalignment.py"\n']
    for r, t, n, sd, stop, mis in SURFACES:
        out.append("[[surface]]")
        out.append(f"radius_mm = {r}\nthickness_mm = {t}\nsemi_diameter_mm = {sd}")
        if n != 1.0:
            out.append(f"material = {{ nd = {n}, vd = 0.0 }}")
        if stop:
            out.append("stop = true")
        if mis:
            dx, dy, tx, ty = mis
            out.append(f"decenter_x_mm = {dx}\ndecenter_y_mm = {dy}\ntilt_x_deg = {tx}\ntilt_y_deg = {ty}")
        out.append("")
    return "\n".join(out)


def rotation(tx_deg: float, ty_deg: float) -> np.ndarray:
    a, b = math.radians(tx_deg), math.radians(ty_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    return ry @ rx


def optiland_optic() -> tuple[Optic, float]:
    optic = Optic(name="misaligned")
    optic.surfaces.add(index=0, radius=be.inf, thickness=be.inf)
    z = 0.0
    placement = None  # (pivot z, offset, R, tilt_x, tilt_y) of the element being placed
    for i, (r, t, n, sd, stop, mis) in enumerate(SURFACES):
        if mis:
            dx, dy, tx, ty = mis
            placement = (z, np.array([dx, dy, 0.0]), rotation(tx, ty), tx, ty)
        if placement is not None:
            zp, offset, rot, tx, ty = placement
            pos = np.array([0.0, 0.0, zp]) + offset + rot @ np.array([0.0, 0.0, z - zp])
            kw = dict(x=float(pos[0]), y=float(pos[1]), z=float(pos[2]), rx=math.radians(tx), ry=math.radians(ty))
        else:
            kw = dict(x=0.0, y=0.0, z=z)
        optic.surfaces.add(
            index=i + 1,
            radius=be.inf if r == 0.0 else r,
            is_stop=stop,
            material=IdealMaterial(n=n),
            aperture=RadialAperture(r_max=sd),
            **kw,
        )
        if placement is not None and n == 1.0:
            placement = None  # the element ends where air follows
        z += t
    optic.surfaces.add(index=len(SURFACES) + 1, x=0.0, y=0.0, z=z)
    optic.set_aperture(aperture_type="float_by_stop_size", value=40.0)
    optic.fields.set_type(field_type="angle")
    optic.fields.add(y=0.0)
    optic.wavelengths.add(value=0.5876, is_primary=True)
    return optic, z


def test_misaligned_elements_match_optiland(petzval_bin, tmp_path):
    lens_file = tmp_path / "misaligned.toml"
    lens_file.write_text(lens_toml(), encoding="utf-8")
    info = pz.lens_info(str(lens_file))
    assert info["rotationally_symmetric"] is False

    optic, z_img = optiland_optic()
    # a grid of rays over the front aperture at three field angles (x and y), from z = -20
    rays = []
    for ax, ay in [(0.0, 0.0), (4.0, -3.0), (-8.0, 6.0)]:
        d = np.array([math.tan(math.radians(ax)), math.tan(math.radians(ay)), 1.0])
        d /= np.linalg.norm(d)
        for u in np.linspace(-13.0, 13.0, 11):
            for v in np.linspace(-13.0, 13.0, 11):
                o = np.array([u, v, 0.0]) - d * (20.0 / d[2])
                rays.append([*o, *d])
    rays = np.array(rays)

    ours = pz.trace(str(lens_file), rays.tolist(), direction="scene-to-film")
    rr = RealRays(*(rays[:, k].copy() for k in range(6)), np.ones(len(rays)), np.full(len(rays), 0.5876))
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        optic.surfaces.trace(rr)
    ref_x = np.asarray(be.to_numpy(rr.x), dtype=float)
    ref_y = np.asarray(be.to_numpy(rr.y), dtype=float)
    ref_ok = (np.asarray(be.to_numpy(rr.i), dtype=float) > 0) & np.isfinite(ref_x) & np.isfinite(ref_y)

    passed, worst, disagree = 0, 0.0, []
    for k, res in enumerate(ours):
        if res["ok"] != bool(ref_ok[k]):
            disagree.append((k, res, bool(ref_ok[k])))
            continue
        if not res["ok"]:
            continue
        o, d = np.array(res["origin"]), np.array(res["direction"])
        at = o + d * ((z_img - o[2]) / d[2])
        err = math.hypot(at[0] - ref_x[k], at[1] - ref_y[k])
        worst = max(worst, err)
        passed += 1
    assert not disagree, f"{len(disagree)} rays pass in one tracer only, e.g. {disagree[:3]}"
    assert passed > 200, f"too few rays passed ({passed} of {len(rays)})"
    print(f"misaligned lens: {passed} rays, worst intercept difference {worst:.2e} mm")
    assert worst < INTERCEPT_TOL_MM, f"image intercepts differ by up to {worst:.3e} mm"


@pytest.mark.parametrize(
    ("field", "value"),
    [("decenter_x_mm", 0.5), ("tilt_y_deg", 1.0)],
)
def test_misalignment_inside_an_element_is_refused(petzval_bin, tmp_path, field, value):
    # on the singlet's rear surface (glass before it): the error names the surface and field
    text = lens_toml().replace("radius_mm = -60.0\n", f"radius_mm = -60.0\n{field} = {value}\n", 1)
    lens_file = tmp_path / "bad.toml"
    lens_file.write_text(text, encoding="utf-8")
    with pytest.raises(pz.PetzvalError) as e:
        pz.lens_info(str(lens_file))
    assert f"surface[3].{field}" in str(e.value)
