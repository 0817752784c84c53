"""Independent-reference tests: Petzval's optics against optiland (PyPI, pure Python/NumPy).

Part 1 (library lenses). For each lens, ``petzval lens export LENS --json`` at 587.5618 nm gives
the resolved prescription; the same lens is rebuilt in optiland with constant-index materials
(``IdealMaterial(n=index_after)``), so dispersion models play no part:

* paraxial: EFL, BFL, FFL, entrance / exit pupil position and diameter, principal planes,
  f-number, total track and f1 = -f2 against ``optic.paraxial`` (``f2 f1 F1 F2 P1 P2 EPL EPD
  XPL XPD FNO``), converted to our frame (see ``optiland_paraxial``), to 1e-6 relative
  (1e-9 mm absolute near 0);
* real rays: explicit rays (field angles along x and y, grids over the paraxial entrance pupil
  and over the region of the front element that the beam really passes, and pairs 1e-6 mm
  either side of the vignetting boundary) traced by ``petzval lens trace --direction
  scene-to-film`` and by ``optic.surfaces.trace(RealRays)``; image-plane intercepts must agree
  to 1e-6 mm and the sets of vignetted rays must agree except for rays within 1e-9 mm of a
  clipping edge (optiland clips with a RadialAperture per surface: our semi-diameters, and the
  stop's current opening);
* reversibility: each transmitted ray, taken back from the image plane with
  ``--direction film-to-scene``, must come out on the incoming ray (1e-9 mm, 1e-9 in direction).

Surfaces: ours A4, A6, ... -> optiland ``even_asphere`` coefficients [0, A4, A6, ...] (its list
starts at r^2); cylinders -> ``toroidal`` (curved in y: radius_x = inf, radius_y = R; curved in
x: radius_x = R, radius_y = inf), whose paraxial radius is the y-z one, so the y meridian is
compared directly and efl_x_mm on the same lens with the cylinder axes exchanged. optiland's
Newton tolerance is set to 1e-14 (its surface-factory default, 1e-6 mm of sag residual, alone
moves intercepts by ~1e-6 mm).

Known disagreements are strict xfails (KNOWN_FAILURES, with the diagnosis as the reason): the
test still runs, and becomes a failure once the cause is fixed, so the mark must then go.

Part 2 (Zemax round trip). optiland writes some of its sample lenses as .zmx
(``optiland.fileio.save_zemax_file``); ``petzval lens info/export/trace FILE.zmx`` imports them
and the results are compared with optiland's own model of the lens with its real glasses, at
587.5618 and 486.1327 nm.

Frame conversions (optiland -> ours; ours is z from the first vertex, +z to the film):
  efl = f2();  f1() = -efl in air;  ffl = -F1()  (F1 is relative to surface 1);
  bfl = image_distance + F2()  (F2 is relative to the image surface);
  front principal z = P1()  (relative to surface 1);  back principal z = z_image + P2();
  entrance pupil z = EPL()  (relative to surface 1);  exit pupil z = z_image + XPL();
  EPD = EPD() (from the stop size: aperture type 'float_by_stop_size');  XPD = |XPD()|;
  f_number = FNO() (= f2 / EPD for this aperture type);  focal points: F1(), z_image + F2();
  our total_track_mm is first vertex -> sensor at the current focus (infinity here), so it is
  compared with the rear focal point z_image + F2() (optiland's own total_track ends at its image
  surface, which is the export's design image plane, not the focused sensor).

Lens selection: every library lens while ``petzval lens list`` has at most ALL_LENSES_UP_TO;
beyond that the five named lenses below plus lentil-based lenses picked by name (Biotar,
Petzval, an aspheric fisheye, a retrofocus/wide angle, an anamorphic lens), at least MIN_LENSES.
``PETZVAL_OPTILAND_LENSES=all`` (or a comma-separated list of names) overrides.

Run:  /work/main/.venv/bin/python -m pytest tests/optics -q   (from /work/main)
"""

from __future__ import annotations

import functools
import math
import os
import re
import warnings
from dataclasses import dataclass, field

import numpy as np
import optiland.backend as be
import pytest
from optiland.materials import IdealMaterial
from optiland.optic import Optic
from optiland.physical_apertures import RadialAperture
from optiland.rays import RealRays

import petzval_cli as pz

D_NM = 587.5618
F_NM = 486.1327

PARAXIAL_REL = 1e-6
PARAXIAL_ABS_MM = 1e-9
INTERCEPT_TOL_MM = 1e-6
FAR_INTERCEPT_MM = 1000.0  # beyond 1 m off axis: relative tolerance (see compare_real_rays)
FAR_INTERCEPT_REL = 1e-8
REVERSE_TOL_MM = 1e-9
REVERSE_TOL_DIR = 1e-9
EDGE_TOL_MM = 1e-9
NEWTON_TOL = 1e-14  # optiland's Newton residual tolerance for aspheres/toroids (its default is 1e-6)

SENSOR_HALF_DIAGONAL_MM = 21.6  # 36 x 24 mm
FISHEYE_HALF_FIELD_DEG = 85.0
FIELD_FRACTIONS = (0.0, 0.3, 0.6, 0.9, 1.0)

REQUIRED_LENSES = (
    "double-gauss-50mm",
    "wide-22mm",
    "fisheye-10mm",
    "telephoto-250mm",
    "biconvex-singlet-50mm",
)
MIN_LENSES = 8
# While the library is small every lens is tested (about 3 s each); past this, a selection.
ALL_LENSES_UP_TO = 24


# --------------------------------------------------------------------------------------------
# Lens selection (at collection time)
# --------------------------------------------------------------------------------------------


@functools.cache
def _export_cached(name: str, wavelength: float = D_NM) -> dict:
    return pz.lens_export(name, wavelength=wavelength)


def _has_aspheric(name: str) -> bool:
    try:
        return any(any(a != 0.0 for a in (s.get("aspheric") or [])) for s in _export_cached(name)["surfaces"])
    except pz.PetzvalError:
        return False


def _has_cylinder(name: str) -> bool:
    try:
        return any(s.get("cylinder") for s in _export_cached(name)["surfaces"])
    except pz.PetzvalError:
        return False


def select_lenses() -> list[str]:
    """The lenses to test: the required five plus picks from the library (see module doc)."""
    env = os.environ.get("PETZVAL_OPTILAND_LENSES", "").strip()
    try:
        names = list(pz.lens_list())
    except pz.PetzvalError:
        # No binary: the tests themselves report the failure through the petzval_bin fixture.
        return list(REQUIRED_LENSES)
    if env == "all" or (not env and len(names) <= ALL_LENSES_UP_TO):
        return names
    if env:
        return [n.strip() for n in env.split(",") if n.strip()]
    chosen = list(REQUIRED_LENSES)
    rest = [n for n in names if n not in chosen]

    def pick(pred):
        for n in rest:
            if n not in chosen and pred(n):
                chosen.append(n)
                return

    low = lambda n: n.lower()  # noqa: E731
    pick(lambda n: "biotar" in low(n))
    pick(lambda n: "petzval" in low(n))
    pick(lambda n: "fisheye" in low(n) and _has_aspheric(n))
    pick(lambda n: re.search(r"retro|distagon|angulon|flektogon|wide|ultra", low(n)) is not None)
    pick(_has_aspheric)  # any other aspheric lens
    pick(_has_cylinder)  # an anamorphic lens (real rays only)
    for n in rest:  # fill up to the minimum
        if len(chosen) >= MIN_LENSES:
            break
        if n not in chosen:
            chosen.append(n)
    return chosen


# Known disagreements, diagnosed and reported. Each is a strict xfail: the test still runs, and
# turns into a failure (XPASS) as soon as the cause is fixed, so the mark must then be removed.
# (The four found when this suite was written -- quadric root choice for rays starting beyond the
# centre of curvature, no refraction at a stop on glass, a curved Zemax stop moved to a plane,
# and the EVENASPH r^2 term -- are fixed.)
OPTILAND_R2_PARAXIAL = (
    "reference-side: optiland 0.6.3's paraxial trace uses only the radius of an even asphere and "
    "ignores its r^2 coefficient (PARM 1), so its EFL (25.4868 mm) is that of the surface without "
    "it; its real rays include the term and agree with ours to 1e-6 mm, and our paraxial EFL "
    "(25.7181 mm at 587.56 nm) is the h -> 0 limit of both tracers' real rays"
)
KNOWN_FAILURES: dict = {
    # (test name, lens or sample) -> diagnosis
    ("test_zemax_sample_paraxial", "aspheric-singlet"): OPTILAND_R2_PARAXIAL,
}


def _with_known_failures(test_name: str, names: list[str]) -> list:
    out = []
    for n in names:
        reason = KNOWN_FAILURES.get((test_name, n))
        out.append(
            pytest.param(n, id=n, marks=pytest.mark.xfail(strict=True, reason=reason))
            if reason
            else pytest.param(n, id=n)
        )
    return out


def pytest_generate_tests(metafunc):
    name = metafunc.function.__name__
    if "lens_name" in metafunc.fixturenames:
        metafunc.parametrize("lens_name", _with_known_failures(name, select_lenses()))
    if "sample" in metafunc.fixturenames:
        metafunc.parametrize("sample", _with_known_failures(name, SAMPLE_NAMES))
    if "more_sample" in metafunc.fixturenames:
        metafunc.parametrize("more_sample", _with_known_failures(name, MORE_SAMPLE_NAMES))


# --------------------------------------------------------------------------------------------
# optiland model of an exported prescription
# --------------------------------------------------------------------------------------------


def _radius(r_mm: float) -> float:
    return float(be.inf) if r_mm == 0.0 else float(r_mm)


def check_export_consistency(exp: dict) -> None:
    """The export is self-consistent: positions match thicknesses, media chain, air outside."""
    surfs = exp["surfaces"]
    assert surfs, "export has no surfaces"
    assert abs(surfs[0]["z_mm"]) < 1e-12, f"first vertex at z = {surfs[0]['z_mm']} (expected 0)"
    assert surfs[0]["index_before"] == 1.0, f"object space index {surfs[0]['index_before']} != 1"
    assert surfs[-1]["index_after"] == 1.0, f"image space index {surfs[-1]['index_after']} != 1"
    for i in range(len(surfs) - 1):
        a, b = surfs[i], surfs[i + 1]
        assert abs(a["z_mm"] + a["thickness_mm"] - b["z_mm"]) <= 1e-9 * max(1.0, abs(b["z_mm"])), (
            f"surface {i}: z {a['z_mm']} + thickness {a['thickness_mm']} != next z {b['z_mm']}"
        )
        assert a["index_after"] == b["index_before"], f"surface {i}->{i + 1}: index_after != next index_before"
    stops = [i for i, s in enumerate(surfs) if s["is_stop"]]
    assert stops == [exp["stop_index"]], f"stop flags {stops} vs stop_index {exp['stop_index']}"


def optiland_from_export(exp: dict, *, clip: bool = True, open_stop: bool = False, swap_xy: bool = False) -> Optic:
    """optiland Optic equivalent to `petzval lens export --json` output.

    Object at infinity; one surface per exported surface (same order); constant-index media;
    image surface at image_distance_mm after the last vertex; aperture = the stop's current
    opening (`float_by_stop_size`, so optiland derives the entrance pupil itself). With `clip`,
    every surface gets a RadialAperture of its semi-diameter, and the stop one of its current
    opening, so optiland vignettes like our tracer does (a circular opening).

    Cylinders become optiland toroids. optiland's paraxial model reads a toroid's y-z radius, so
    it sees our y meridian; `swap_xy` exchanges the cylinder axes (the lens turned 90 degrees
    about z), which puts our x meridian there (for efl_x_mm).
    """
    surfs = exp["surfaces"]
    n_surf = len(surfs)
    wl_um = exp["wavelength_nm"] / 1000.0
    optic = Optic(name=exp.get("name", ""))
    optic.surfaces.add(index=0, radius=be.inf, thickness=be.inf)
    for i, s in enumerate(surfs):
        thickness = exp["image_distance_mm"] if i == n_surf - 1 else s["thickness_mm"]
        kw: dict = dict(
            index=i + 1,
            thickness=thickness,
            is_stop=bool(s["is_stop"]),
            material=IdealMaterial(n=float(s["index_after"])),
        )
        if clip:
            # the stop: its current opening, or with open_stop its housing (export's semi-diameter)
            r_max = exp["stop_semi_diameter_mm"] if s["is_stop"] and not open_stop else s["semi_diameter_mm"]
            kw["aperture"] = RadialAperture(r_max=float(r_max))
        radius = _radius(s["radius_mm"])
        conic = float(s.get("conic") or 0.0)
        asph = [float(a) for a in (s.get("aspheric") or [])]
        cyl = s.get("cylinder")
        if swap_xy and cyl:
            cyl = {"x": "y", "y": "x"}[cyl]
        plane = s["radius_mm"] == 0.0 and not any(asph)
        if cyl is None or plane:
            if any(asph):
                # optiland's even asphere: coefficients[i] multiplies r^(2(i+1)), r^2 first;
                # ours are A4, A6, ... -> prepend a zero r^2 term.
                kw.update(
                    surface_type="even_asphere",
                    radius=radius,
                    conic=conic,
                    coefficients=[0.0, *asph],
                    tol=NEWTON_TOL,
                    max_iter=200,
                )
            else:
                kw.update(surface_type="standard", radius=radius, conic=conic)
        elif cyl == "y" or (cyl == "x" and (conic != 0.0 or any(asph))):
            # Toroidal, rotation radius infinite: z = z_y(y) (conic + y^2, y^4, ... polynomial).
            # A curved-in-x surface with conic/asphere is the same, turned 90 degrees about z.
            kw.update(
                surface_type="toroidal",
                radius_x=float(be.inf),
                radius_y=radius,
                conic=conic,
                toroidal_coeffs_poly_y=[0.0, *asph],
                tol=NEWTON_TOL,
                max_iter=200,
            )
            if cyl == "x":
                kw["rz"] = math.pi / 2
        elif cyl == "x":
            # Plain circular cylinder curved along x: toroid with R_yz infinite, R_rot = R.
            kw.update(
                surface_type="toroidal",
                radius_x=radius,
                radius_y=float(be.inf),
                conic=0.0,
                tol=NEWTON_TOL,
                max_iter=200,
            )
        else:
            raise ValueError(f"unknown cylinder axis {cyl!r}")
        optic.surfaces.add(**kw)
    optic.surfaces.add(index=n_surf + 1)
    optic.set_aperture(aperture_type="float_by_stop_size", value=2.0 * float(exp["stop_semi_diameter_mm"]))
    optic.fields.set_type(field_type="angle")
    optic.fields.add(y=0.0)
    optic.wavelengths.add(value=wl_um, is_primary=True)
    return optic


def _f(v) -> float:
    return float(np.asarray(be.to_numpy(v)).ravel()[0])


def optiland_paraxial(optic: Optic, last_vertex_z: float, image_distance: float) -> dict:
    """optiland's first-order data, converted to our conventions (see module doc)."""
    p = optic.paraxial
    z_img = last_vertex_z + image_distance
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f2 = _f(p.f2())
        f1 = _f(p.f1())
        F1 = _f(p.F1())
        F2 = _f(p.F2())
        P1 = _f(p.P1())
        P2 = _f(p.P2())
        epl = _f(p.EPL())
        epd = _f(p.EPD())
        xpl = _f(p.XPL())
        xpd = _f(p.XPD())
        fno = _f(p.FNO())
    return {
        "efl_mm": f2,
        "minus_f1_mm": -f1,
        "bfl_mm": image_distance + F2,
        "ffl_mm": -F1,
        "front_principal_z_mm": P1,
        "back_principal_z_mm": z_img + P2,
        "entrance_pupil_z_mm": epl,
        "entrance_pupil_diameter_mm": epd,
        "exit_pupil_z_mm": z_img + xpl,
        "exit_pupil_diameter_mm": abs(xpd),
        "f_number": fno,
        # ours: first vertex -> sensor at the current focus, i.e. at infinity the rear focal point
        "total_track_mm": z_img + F2,
        "front_focal_z_mm": F1,
        "back_focal_z_mm": z_img + F2,
    }


def ours_paraxial(info: dict) -> dict:
    """Our `lens info --json` in the same keys."""
    out = {
        "efl_mm": info["efl_mm"],
        "minus_f1_mm": info["efl_mm"],
        "bfl_mm": info["bfl_mm"],
        "ffl_mm": info["ffl_mm"],
        "front_principal_z_mm": info["principal_planes"]["front_z_mm"],
        "back_principal_z_mm": info["principal_planes"]["back_z_mm"],
        "entrance_pupil_z_mm": info["entrance_pupil"]["z_mm"],
        "entrance_pupil_diameter_mm": info["entrance_pupil"]["diameter_mm"],
        "exit_pupil_z_mm": info["exit_pupil"]["z_mm"],
        "exit_pupil_diameter_mm": info["exit_pupil"]["diameter_mm"],
        "f_number": info["f_number"],
        "total_track_mm": info["total_track_mm"],
        "front_focal_z_mm": info["focal_points"]["front_z_mm"],
        "back_focal_z_mm": info["focal_points"]["back_z_mm"],
    }
    if "efl_x_mm" in info:
        out["efl_x_mm"] = info["efl_x_mm"]
    return out


def petzval_sum(exp: dict) -> float:
    """Sum over surfaces of c (n' - n) / (n n') from the exported prescription (y meridian)."""
    total = 0.0
    for s in exp["surfaces"]:
        if s["radius_mm"] == 0.0 or s.get("cylinder") == "x":
            continue
        n1, n2 = s["index_before"], s["index_after"]
        total += (n2 - n1) / (s["radius_mm"] * n1 * n2)
    return total


def compare_values(ours: dict, ref: dict, rel: float, abs_mm: float, keys=None) -> tuple[list[str], dict]:
    """Failures (one line each) and the relative deviation per key (absolute below 1 mm scale)."""
    fails, devs = [], {}
    for k in keys or [k for k in ref if k in ours]:
        a, b = float(ours[k]), float(ref[k])
        if math.isinf(a) or math.isinf(b):
            ok = a == b
            dev = 0.0 if ok else math.inf
        else:
            diff = abs(a - b)
            tol = max(rel * abs(b), abs_mm)
            ok = diff <= tol
            dev = diff / abs(b) if abs(b) > 1e-3 else diff
        devs[k] = dev
        if not ok:
            fails.append(
                f"{k}: petzval {a!r} vs optiland {b!r} (diff {a - b:.3e}, tol {max(rel * abs(b), abs_mm):.1e})"
            )
    return fails, devs


# --------------------------------------------------------------------------------------------
# Ray sets
# --------------------------------------------------------------------------------------------


def sag(s: dict, r: float) -> float:
    """Sag of an exported surface at radial (or cylinder-axis) coordinate r (NaN outside)."""
    c = 0.0 if s["radius_mm"] == 0.0 else 1.0 / s["radius_mm"]
    k = float(s.get("conic") or 0.0)
    r2 = r * r
    rad = 1.0 - (1.0 + k) * c * c * r2
    if rad < 0:
        return math.nan
    z = c * r2 / (1.0 + math.sqrt(rad)) + float(s.get("aspheric_r2") or 0.0) * r2
    p = r2
    for a in s.get("aspheric") or []:
        p *= r2
        z += a * p
    for j, b in enumerate(s.get("aspheric_odd") or []):
        z += b * abs(r) ** (2 * j + 1)
    return z


def start_plane_z(exp: dict, z_ep: float) -> float:
    """A z in front of every surface (including sag over the clear aperture) and the pupil."""
    front = 0.0
    for s in exp["surfaces"]:
        for f in np.linspace(0.0, 1.0, 33):
            z = sag(s, f * s["semi_diameter_mm"])
            if math.isfinite(z):
                front = min(front, s["z_mm"] + z)
    return min(front, z_ep if math.isfinite(z_ep) else 0.0) - 10.0


def field_direction(angle_deg: float, axis: str) -> np.ndarray:
    a = math.radians(angle_deg)
    if axis == "x":
        return np.array([math.sin(a), 0.0, math.cos(a)])
    return np.array([0.0, math.sin(a), math.cos(a)])


def disc_grid(n: int = 7, edge: float = 0.99, n_edge: int = 16) -> np.ndarray:
    """Normalised pupil coordinates: an n x n grid clipped to the unit disc, plus n_edge points
    on the circle of radius `edge`."""
    g = np.linspace(-1.0, 1.0, n)
    pts = [(x, y) for y in g for x in g if x * x + y * y < 1.0 - 1e-12]
    for k in range(n_edge):
        t = 2 * math.pi * k / n_edge
        pts.append((edge * math.cos(t), edge * math.sin(t)))
    return np.array(pts)


def rays_through_points(points: np.ndarray, d: np.ndarray, z0: float) -> np.ndarray:
    """Rays with direction d that pass through `points` (N x 3), started on the plane z = z0."""
    s = (points[:, 2] - z0) / d[2]
    origins = points - s[:, None] * d[None, :]
    origins[:, 2] = z0
    dirs = np.broadcast_to(d, origins.shape)
    return np.hstack([origins, dirs])


def perpendicular_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ref = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(d, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    return e1, e2


# --------------------------------------------------------------------------------------------
# optiland real-ray trace
# --------------------------------------------------------------------------------------------


@dataclass
class OptilandTrace:
    ok: np.ndarray  # transmitted (not clipped, finite)
    image_xy: np.ndarray  # N x 2 on the image surface
    edge_margin: np.ndarray  # per ray: smallest |r_max - r| over the clipping surfaces (mm)
    clip_surface: np.ndarray  # per ray: first surface index (0-based, ours) that stopped it, or -1
    reason: np.ndarray  # per ray: why optiland lost it ("" if transmitted)


def optiland_trace(optic: Optic, rays: np.ndarray, wl_um: float) -> OptilandTrace:
    n = len(rays)
    rr = RealRays(
        rays[:, 0].copy(), rays[:, 1].copy(), rays[:, 2].copy(),
        rays[:, 3].copy(), rays[:, 4].copy(), rays[:, 5].copy(),
        np.ones(n), np.full(n, wl_um),
    )
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        optic.surfaces.trace(rr)
    x = np.asarray(be.to_numpy(rr.x), dtype=float)
    y = np.asarray(be.to_numpy(rr.y), dtype=float)
    inten = np.asarray(be.to_numpy(rr.i), dtype=float)
    ok = (inten > 0) & np.isfinite(x) & np.isfinite(y)
    margin = np.full(n, np.inf)
    clip_surface = np.full(n, -1)
    reason = np.full(n, "", dtype=object)
    surfaces = optic.surfaces.surfaces
    for k in range(1, len(surfaces) - 1):
        surf = surfaces[k]
        sx = np.asarray(be.to_numpy(surf.x), dtype=float)
        sy = np.asarray(be.to_numpy(surf.y), dtype=float)
        sl = np.asarray(be.to_numpy(surf.N), dtype=float)
        lost = ~(np.isfinite(sx) & np.isfinite(sy))
        newly = (clip_surface < 0) & lost
        reason = np.where(newly, f"misses surface {k - 1}", reason)
        clip_surface = np.where(newly, k - 1, clip_surface)
        if surf.aperture is not None:
            m = surf.aperture.r_max - np.hypot(sx, sy)
            finite = np.isfinite(m)
            margin = np.where(finite, np.minimum(margin, np.abs(m)), margin)
            newly = (clip_surface < 0) & finite & (m < 0)
            reason = np.where(newly, f"clipped at surface {k - 1}", reason)
            clip_surface = np.where(newly, k - 1, clip_surface)
        newly = (clip_surface < 0) & ~np.isfinite(sl)
        reason = np.where(newly, f"total internal reflection at surface {k - 1}", reason)
        clip_surface = np.where(newly, k - 1, clip_surface)
    return OptilandTrace(
        ok=ok, image_xy=np.column_stack([x, y]), edge_margin=margin, clip_surface=clip_surface, reason=reason
    )


# --------------------------------------------------------------------------------------------
# Our trace
# --------------------------------------------------------------------------------------------


@dataclass
class OurTrace:
    ok: np.ndarray
    origin: np.ndarray
    direction: np.ndarray
    absorbed: list = field(default_factory=list)


def our_trace(lens: str, rays: np.ndarray, direction: str, wavelength: float, open_stop=False) -> OurTrace:
    res = pz.trace(lens, rays.tolist(), direction=direction, wavelength=wavelength, open_stop=open_stop)
    n = len(res)
    ok = np.array([bool(r.get("ok")) for r in res])
    origin = np.full((n, 3), np.nan)
    dirs = np.full((n, 3), np.nan)
    absorbed = []
    for i, r in enumerate(res):
        if r.get("ok"):
            origin[i] = r["origin"]
            dirs[i] = r["direction"]
            absorbed.append(None)
        else:
            absorbed.append(r.get("absorbed", "?"))
    return OurTrace(ok=ok, origin=origin, direction=dirs, absorbed=absorbed)


def image_intercepts(t: OurTrace, z_img: float) -> np.ndarray:
    s = (z_img - t.origin[:, 2]) / t.direction[:, 2]
    p = t.origin + s[:, None] * t.direction
    return p


# --------------------------------------------------------------------------------------------
# The generic ray comparison
# --------------------------------------------------------------------------------------------


@dataclass
class RayComparison:
    n_rays: int = 0
    n_ok_both: int = 0
    n_vignetted_both: int = 0
    n_edge_disagree: int = 0
    max_intercept_dev_mm: float = 0.0
    max_reverse_pos_mm: float = 0.0
    max_reverse_dir: float = 0.0
    failures: list = field(default_factory=list)  # scene-to-film: vignetting and intercepts
    reverse_failures: list = field(default_factory=list)  # film-to-scene round trip
    n_reversed: int = 0  # rays sent back film-to-scene


def field_angles(efl: float, fisheye: bool, max_deg: float | None = None) -> list[float]:
    if max_deg is None:
        max_deg = FISHEYE_HALF_FIELD_DEG if fisheye else math.degrees(math.atan(SENSOR_HALF_DIAGONAL_MM / abs(efl)))
    return [f * max_deg for f in FIELD_FRACTIONS]


def build_rays(exp: dict, info: dict, optic: Optic, angles: list[float], wl_um: float) -> tuple[np.ndarray, list[str]]:
    """All test rays (N x 6) and a label per ray.

    For each field (angle along x and along y): (a) a 7x7 disc grid plus 16 points at 0.99 of
    the paraxial entrance pupil; (b) the same pattern over the ellipse that bounds the rays
    optiland transmits, found by scanning a 61x61 grid in the plane perpendicular to the field
    direction over the front element (this aims rays where the beam really goes, e.g. for
    fisheyes far off axis, where the paraxial pupil is meaningless); (c) pairs of rays 1e-6 mm
    inside and outside the boundary of that beam (bisected in optiland along 16 directions), so
    the clipping edges themselves are compared.
    """
    z_ep = info["entrance_pupil"]["z_mm"]
    r_ep = 0.5 * info["entrance_pupil"]["diameter_mm"]
    z0 = start_plane_z(exp, z_ep)
    s0 = exp["surfaces"][0]
    sd0 = max(s["semi_diameter_mm"] for s in exp["surfaces"][:2])
    z_c = s0["z_mm"] + 0.5 * (
        sag(s0, s0["semi_diameter_mm"]) if math.isfinite(sag(s0, s0["semi_diameter_mm"])) else 0.0
    )
    pattern = disc_grid()
    all_rays, labels = [], []
    fields = [(0.0, "y")] + [(a, ax) for a in angles if a > 0 for ax in ("x", "y")]
    for angle, axis in fields:
        d = field_direction(angle, axis)
        tag = f"{axis}{angle:.2f}deg"
        # (a) paraxial entrance pupil grid
        pts = np.column_stack([pattern[:, 0] * r_ep, pattern[:, 1] * r_ep, np.full(len(pattern), z_ep)])
        all_rays.append(rays_through_points(pts, d, z0))
        labels += [f"{tag}/EP({px:+.2f},{py:+.2f})" for px, py in pattern]
        # (b) aimed grid over the transmitted beam
        e1, e2 = perpendicular_basis(d)
        g = np.linspace(-1.5 * sd0, 1.5 * sd0, 61)
        uu, vv = np.meshgrid(g, g)
        uu, vv = uu.ravel(), vv.ravel()
        c = np.array([0.0, 0.0, z_c])
        pts = c[None, :] + uu[:, None] * e1[None, :] + vv[:, None] * e2[None, :]
        scan = rays_through_points(pts, d, z0)
        tr = optiland_trace(optic, scan, wl_um)
        if tr.ok.sum() >= 4:
            u_ok, v_ok = uu[tr.ok], vv[tr.ok]
            step = g[1] - g[0]
            u_lo, u_hi = u_ok.min() - 0.5 * step, u_ok.max() + 0.5 * step
            v_lo, v_hi = v_ok.min() - 0.5 * step, v_ok.max() + 0.5 * step
            uc, vc, au, av = 0.5 * (u_lo + u_hi), 0.5 * (v_lo + v_hi), 0.5 * (u_hi - u_lo), 0.5 * (v_hi - v_lo)
            pu = uc + pattern[:, 0] * au
            pv = vc + pattern[:, 1] * av
            pts = c[None, :] + pu[:, None] * e1[None, :] + pv[:, None] * e2[None, :]
            all_rays.append(rays_through_points(pts, d, z0))
            labels += [f"{tag}/beam({px:+.2f},{py:+.2f})" for px, py in pattern]
            # (c) rays just inside and just outside the vignetting boundary
            centre = np.array([uc, vc])
            probes = edge_probes(optic, wl_um, d, c, e1, e2, z0, centre, 3.0 * sd0)
            if probes is not None:
                inside, outside = probes
                for k, (pi, po) in enumerate(zip(inside, outside, strict=False)):
                    all_rays.append(rays_through_points(np.vstack([pi, po]), d, z0))
                    labels += [f"{tag}/edge{k}-inside", f"{tag}/edge{k}-outside"]
    return np.vstack(all_rays), labels


EDGE_PROBE_OFFSET_MM = 1e-6
EDGE_PROBE_DIRECTIONS = 16


def edge_probes(optic, wl_um, d, c, e1, e2, z0, centre, reach):
    """Points (in 3-D, on the plane through c perpendicular to d) EDGE_PROBE_OFFSET_MM inside
    and outside the boundary of the beam optiland transmits, found by bisection along
    EDGE_PROBE_DIRECTIONS directions from `centre` (plane coordinates along e1, e2)."""

    def to3d(uv):
        return c[None, :] + uv[:, :1] * e1[None, :] + uv[:, 1:2] * e2[None, :]

    def transmitted(uv):
        return optiland_trace(optic, rays_through_points(to3d(uv), d, z0), wl_um).ok

    if not transmitted(centre[None, :])[0]:
        return None
    ang = 2 * np.pi * (np.arange(EDGE_PROBE_DIRECTIONS) + 0.5) / EDGE_PROBE_DIRECTIONS
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    lo = np.zeros(len(dirs))
    hi = np.full(len(dirs), reach)
    keep = ~transmitted(centre[None, :] + hi[:, None] * dirs)
    dirs, lo, hi = dirs[keep], lo[keep], hi[keep]
    if not len(dirs):
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = transmitted(centre[None, :] + mid[:, None] * dirs)
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
        if np.max(hi - lo) < 1e-12 * reach:
            break
    inside = to3d(centre[None, :] + (lo - EDGE_PROBE_OFFSET_MM)[:, None] * dirs)
    outside = to3d(centre[None, :] + (hi + EDGE_PROBE_OFFSET_MM)[:, None] * dirs)
    return inside, outside


def compare_rays(
    lens: str,
    exp: dict,
    optic: Optic,
    rays: np.ndarray,
    labels: list[str],
    wavelength_nm: float,
    open_stop: bool = False,
) -> RayComparison:
    """Trace `rays` through both, compare intercepts, vignetting and reversibility."""
    out = RayComparison(n_rays=len(rays))
    wl_um = wavelength_nm / 1000.0
    z_img = exp["surfaces"][-1]["z_mm"] + exp["image_distance_mm"]
    ref = optiland_trace(optic, rays, wl_um)
    ours = our_trace(lens, rays, "scene-to-film", wavelength_nm, open_stop=open_stop)
    p_img = image_intercepts(ours, z_img)

    # 1. Which rays get through.
    both = ours.ok & ref.ok
    out.n_ok_both = int(both.sum())
    out.n_vignetted_both = int((~ours.ok & ~ref.ok).sum())
    disagree = np.nonzero(ours.ok != ref.ok)[0]
    hard = []
    for i in disagree:
        if ref.edge_margin[i] <= EDGE_TOL_MM:
            out.n_edge_disagree += 1
        else:
            hard.append(i)
    for i in hard[:10]:
        who = (
            f"petzval transmits, optiland loses it ({ref.reason[i] or 'non-finite'})"
            if ours.ok[i]
            else f"petzval absorbs ({ours.absorbed[i]}), optiland transmits"
        )
        out.failures.append(
            f"vignetting differs for ray {labels[i]} {rays[i].tolist()}: {who}; nearest clipping edge "
            f"{ref.edge_margin[i]:.3e} mm (optiland surface numbering, 0 = first lens surface)"
        )
    if len(hard) > 10:
        out.failures.append(f"... and {len(hard) - 10} more vignetting differences")

    # 2. Image-plane intercepts.
    if both.any():
        dev = np.hypot(p_img[both, 0] - ref.image_xy[both, 0], p_img[both, 1] - ref.image_xy[both, 1])
        # A ray that lands more than FAR_INTERCEPT_MM off axis left the lens within a few degrees
        # of the image plane (near the critical angle, where its direction is ill-conditioned):
        # compare it relative to the distance it travels, not to 1e-6 mm over kilometres.
        far = np.hypot(ref.image_xy[both, 0], ref.image_xy[both, 1])
        tol = np.where(far > FAR_INTERCEPT_MM, FAR_INTERCEPT_REL * far, INTERCEPT_TOL_MM)
        near = far <= FAR_INTERCEPT_MM
        out.max_intercept_dev_mm = float(np.max(dev[near])) if near.any() else 0.0
        bad = np.nonzero(both)[0][dev > tol]
        for i in bad[:10]:
            out.failures.append(
                f"image intercept differs for ray {labels[i]}: petzval {p_img[i, :2].tolist()} vs optiland "
                f"{ref.image_xy[i].tolist()} ({np.hypot(*(p_img[i, :2] - ref.image_xy[i])):.3e} mm)"
            )
        if len(bad) > 10:
            out.failures.append(f"... and {len(bad) - 10} more intercept differences")

    # 3. Reversibility: back from the image plane with the reversed direction.
    idx = np.nonzero(ours.ok)[0]
    if len(idx):
        back_in = np.hstack([p_img[idx], -ours.direction[idx]])
        back = our_trace(lens, back_in, "film-to-scene", wavelength_nm, open_stop=open_stop)
        out.n_reversed = len(idx)
        d_in = rays[idx, 3:6] / np.linalg.norm(rays[idx, 3:6], axis=1)[:, None]
        o_in = rays[idx, 0:3]
        n_absorbed = 0
        for j, i in enumerate(idx):
            if not back.ok[j]:
                n_absorbed += 1
                if n_absorbed <= 10:
                    out.reverse_failures.append(f"reverse trace of ray {labels[i]} absorbed ({back.absorbed[j]})")
                continue
            dd = float(np.max(np.abs(back.direction[j] + d_in[j])))
            w = back.origin[j] - o_in[j]
            dist = float(np.linalg.norm(w - np.dot(w, d_in[j]) * d_in[j]))
            out.max_reverse_dir = max(out.max_reverse_dir, dd)
            out.max_reverse_pos_mm = max(out.max_reverse_pos_mm, dist)
            if (dd > REVERSE_TOL_DIR or dist > REVERSE_TOL_MM) and len(out.reverse_failures) < 20:
                out.reverse_failures.append(
                    f"reverse trace of ray {labels[i]} does not return on the incoming ray: "
                    f"off by {dist:.3e} mm, direction by {dd:.3e}"
                )
        if n_absorbed > 10:
            out.reverse_failures.append(f"... {n_absorbed} of {len(idx)} reversed rays absorbed in all")
    return out


# --------------------------------------------------------------------------------------------
# Part 1: library lenses
# --------------------------------------------------------------------------------------------


@functools.cache
def _lens_data(name: str):
    exp = pz.lens_export(name, wavelength=D_NM)
    info = pz.lens_info(name, wavelength=D_NM)
    return exp, info


def _is_fisheye(name: str, info: dict) -> bool:
    return "fisheye" in name.lower() or "fish-eye" in name.lower()


def _stop_opening_is_circular(name: str) -> bool:
    """Whether the library lens's stop opening is a plain circle (its TOML has no [aperture]
    table with another shape or an anamorphic ratio). `lens export` does not carry the shape."""
    import tomllib

    path = pz.REPO / "renderer" / "optics" / "lenses" / f"{name}.toml"
    if not path.is_file():
        return True
    ap = tomllib.loads(path.read_text()).get("aperture", {})
    return str(ap.get("shape", "circle")) == "circle" and float(ap.get("anamorphic_ratio", 1.0)) == 1.0


def test_export_matches_info(petzval_bin, lens_name):
    """The export and info describe the same lens (basic sanity before the comparisons)."""
    exp, info = _lens_data(lens_name)
    check_export_consistency(exp)
    assert abs(exp["wavelength_nm"] - D_NM) < 1e-9, exp["wavelength_nm"]
    assert info["surface_count"] == len(exp["surfaces"]), (info["surface_count"], len(exp["surfaces"]))


def test_paraxial_vs_optiland(petzval_bin, lens_name, deviation_log):
    exp, info = _lens_data(lens_name)
    check_export_consistency(exp)
    anamorphic = any(s.get("cylinder") for s in exp["surfaces"])
    if any(s.get("cylinder") and (s.get("conic") or any(s.get("aspheric") or [])) for s in exp["surfaces"]):
        pytest.skip(
            "cylinder with conic/asphere: modelled as a turned toroid, which optiland's paraxial model misreads"
        )
    optic = optiland_from_export(exp, clip=False)
    last_z = exp["surfaces"][-1]["z_mm"]
    ref = optiland_paraxial(optic, last_z, exp["image_distance_mm"])
    # x meridian: the same lens with the cylinder axes exchanged (rotationally symmetric: = efl)
    ref["efl_x_mm"] = (
        optiland_paraxial(optiland_from_export(exp, clip=False, swap_xy=True), last_z, exp["image_distance_mm"])[
            "efl_mm"
        ]
        if anamorphic
        else ref["efl_mm"]
    )
    exp_primary = pz.lens_export(lens_name)
    if exp_primary["wavelength_nm"] != D_NM:
        # The sensor (total track) sits at the primary wavelength's focus.
        ref["total_track_mm"] = optiland_paraxial(
            optiland_from_export(exp_primary, clip=False), last_z, exp_primary["image_distance_mm"]
        )["back_focal_z_mm"]
    ours = ours_paraxial(info)
    fails, devs = compare_values(ours, ref, PARAXIAL_REL, PARAXIAL_ABS_MM)
    # Petzval sum against the formula on the exported prescription (optiland has no such call;
    # not defined for anamorphic lenses).
    if not anamorphic:
        pz_ref = petzval_sum(exp)
        pz_diff = abs(info["petzval_sum_per_mm"] - pz_ref)
        devs["petzval_sum"] = pz_diff / abs(pz_ref) if abs(pz_ref) > 1e-12 else pz_diff
        if pz_diff > max(PARAXIAL_REL * abs(pz_ref), 1e-12):
            fails.append(f"petzval_sum_per_mm: petzval {info['petzval_sum_per_mm']!r} vs formula {pz_ref!r}")
    for k, v in devs.items():
        deviation_log.add("paraxial", lens_name, k, v)
    assert not fails, f"{lens_name}: paraxial data disagree with optiland:\n  " + "\n  ".join(fails)


@functools.cache
def _library_ray_comparison(lens_name: str) -> tuple[RayComparison, bool]:
    """Traces the ray set once per lens (both ray tests read it)."""
    exp, info = _lens_data(lens_name)
    check_export_consistency(exp)
    # A non-circular opening (blades, mask, anamorphic ratio) is not modelled in optiland: trace
    # with --open-stop instead, where only the stop's round housing clips.
    open_stop = not _stop_opening_is_circular(lens_name)
    optic = optiland_from_export(exp, clip=True, open_stop=open_stop)
    efl = min(abs(info["efl_mm"]), abs(info.get("efl_x_mm", info["efl_mm"])))
    angles = field_angles(efl, _is_fisheye(lens_name, info))
    rays, labels = build_rays(exp, info, optic, angles, D_NM / 1000.0)
    return compare_rays(lens_name, exp, optic, rays, labels, D_NM, open_stop=open_stop), open_stop


def test_real_rays_vs_optiland(petzval_bin, lens_name, deviation_log):
    """scene-to-film: image-plane intercepts (1e-6 mm) and vignetting against optiland."""
    cmp, open_stop = _library_ray_comparison(lens_name)
    if open_stop:
        deviation_log.add("real rays", lens_name, "mode", "--open-stop (non-circular opening)")
    deviation_log.add("real rays", lens_name, "max image intercept dev (mm)", cmp.max_intercept_dev_mm)
    deviation_log.add("real rays", lens_name, "rays total/both ok/both vignetted/edge-disagree",
                      f"{cmp.n_rays}/{cmp.n_ok_both}/{cmp.n_vignetted_both}/{cmp.n_edge_disagree}")
    assert not cmp.failures, f"{lens_name}: {len(cmp.failures)} real-ray problems:\n  " + "\n  ".join(cmp.failures)
    assert cmp.n_ok_both > 0, f"{lens_name}: no ray got through both tracers"


def test_film_to_scene_returns_on_incoming_ray(petzval_bin, lens_name, deviation_log):
    """Each transmitted ray, sent back from the image plane reversed, leaves the front of the lens
    on the incoming ray (1e-9 mm) with the opposite direction (1e-9)."""
    cmp, _ = _library_ray_comparison(lens_name)
    deviation_log.add("reverse", lens_name, "max position off incoming ray (mm)", cmp.max_reverse_pos_mm)
    deviation_log.add("reverse", lens_name, "max direction dev", cmp.max_reverse_dir)
    assert not cmp.reverse_failures, (
        f"{lens_name}: {len(cmp.reverse_failures)} film-to-scene problems:\n  " + "\n  ".join(cmp.reverse_failures)
    )
    assert cmp.n_reversed > 0, f"{lens_name}: no ray got through scene-to-film, so none could be sent back"


# --------------------------------------------------------------------------------------------
# Part 2: optiland sample lenses through Zemax files
# --------------------------------------------------------------------------------------------


def _aspheric_singlet_a4():
    """optiland's AsphericSinglet with its r^2 coefficient zeroed (so only A4, A6 remain, which
    our format represents) and a separate plane stop in air 2 mm in front of it."""
    from optiland.samples import simple

    optic = simple.AsphericSinglet()
    optic.surfaces.surfaces[1].geometry.coefficients[0] = 0.0
    optic.surfaces.add(index=1, radius=be.inf, thickness=2.0)
    optic.surfaces.stop_index = 1
    return optic


def _aspheric_singlet_a4_stop_on_glass():
    """As _aspheric_singlet_a4 but with the stop on the singlet's plane rear face (glass -> air),
    a configuration Zemax files use freely."""
    from optiland.samples import simple

    optic = simple.AsphericSinglet()
    optic.surfaces.surfaces[1].geometry.coefficients[0] = 0.0
    optic.surfaces.stop_index = 2
    return optic


def _cylinder_singlet():
    """A plano-cylindrical singlet behind a plane stop: optiland's toroidal surface with an
    infinite radius of rotation (curved along y only), which save_zemax_file writes as TYPE
    TOROIDAL."""
    optic = Optic(name="CylinderSinglet")
    optic.surfaces.add(index=0, radius=be.inf, thickness=be.inf)
    optic.surfaces.add(index=1, radius=be.inf, thickness=2.0, is_stop=True)
    optic.surfaces.add(
        index=2, surface_type="toroidal", radius_x=be.inf, radius_y=40.0, conic=0.0, thickness=5.0, material="N-BK7"
    )
    optic.surfaces.add(index=3, radius=be.inf, thickness=75.0)
    optic.surfaces.add(index=4)
    optic.set_aperture("EPD", 10.0)
    optic.fields.set_type("angle")
    optic.fields.add(y=0)
    optic.fields.add(y=5)
    optic.wavelengths.add(value=0.5876, is_primary=True)
    return optic


def _odd_asphere_singlet():
    """A singlet whose front surface is optiland's odd asphere (r^1, r^3, r^4, r^5 terms and a
    conic; no r^2 term, which optiland's paraxial trace leaves out), written as TYPE ODDASPHE."""
    optic = Optic(name="OddAsphereSinglet")
    optic.surfaces.add(index=0, radius=be.inf, thickness=be.inf)
    optic.surfaces.add(index=1, radius=be.inf, thickness=3.0, is_stop=True)
    optic.surfaces.add(
        index=2,
        radius=30.0,
        thickness=5.0,
        material="N-BK7",
        surface_type="odd_asphere",
        conic=-0.3,
        coefficients=[3e-4, 0.0, 2e-6, 1e-7, 1e-9],
    )
    optic.surfaces.add(index=3, radius=-200.0, thickness=50.0)
    optic.surfaces.add(index=4)
    optic.set_aperture("EPD", 10.0)
    optic.fields.set_type("angle")
    optic.fields.add(y=0)
    optic.fields.add(y=8)
    optic.wavelengths.add(value=0.5876, is_primary=True)
    return optic


def _samples():
    from optiland.samples import (
        eyepieces,
        infrared,
        lithography,
        microscopes,
        miscellaneous,
        objectives,
        simple,
        telescopes,
    )

    return {
        "cooke-triplet": objectives.CookeTriplet,
        "tessar": objectives.TessarLens,
        "petzval-f1.4": objectives.PetzvalLens,
        "heliar": objectives.HeliarLens,
        "double-gauss": objectives.DoubleGauss,
        "aspheric-singlet": simple.AsphericSinglet,
        "aspheric-singlet-a4": _aspheric_singlet_a4,
        "aspheric-singlet-a4-stop-on-glass": _aspheric_singlet_a4_stop_on_glass,
        "cylinder-singlet": _cylinder_singlet,
        "odd-asphere-singlet": _odd_asphere_singlet,
        # optiland's other objectives and simple lenses (camera-like: object at infinity)
        "field-corrector": objectives.LensWithFieldCorrector,
        "objective-us8879901": objectives.ObjectiveUS008879901,
        "projection-120fov": objectives.ProjectionLens120FOV,
        "projection-160fov": objectives.ProjectionLens160FOV,
        "reverse-telephoto": objectives.ReverseTelephoto,
        "telephoto": objectives.Telephoto,
        "telescope-objective-48in": objectives.TelescopeObjective48Inch,
        "triplet-telescope-objective": objectives.TripletTelescopeObjective,
        "wide-angle-100fov": objectives.WideAngle100FOV,
        "wide-angle-170fov": objectives.WideAngle170FOV,
        "cemented-achromat": simple.CementedAchromat,
        "edmund-49-847": simple.Edmund_49_847,
        "singlet-stop-surf2": simple.SingletStopSurf2,
        "telescope-doublet": simple.TelescopeDoublet,
        # not camera lenses, or outside what we model (see UNSUPPORTED_SAMPLES)
        "infrared-triplet": infrared.InfraredTriplet,
        "infrared-triplet-f4": infrared.InfraredTripletF4,
        "erfle-eyepiece": eyepieces.EyepieceErfle,
        "microscope-20x": microscopes.Microscope20x,
        "objective-60x": microscopes.Objective60x,
        "uv-reflecting-microscope": microscopes.UVReflectingMicroscope,
        "hubble": telescopes.HubbleTelescope,
        "uv-projection-lens": lithography.UVProjectionLens,
        "navarro-eye": miscellaneous.NavarroWideAngleEye,
    }


SAMPLE_NAMES = [
    "cooke-triplet",
    "tessar",
    "petzval-f1.4",
    "heliar",
    "double-gauss",
    "aspheric-singlet",
    "aspheric-singlet-a4",
    "aspheric-singlet-a4-stop-on-glass",
    "cylinder-singlet",
    "odd-asphere-singlet",
    # 85 degree half field; optiland writes paraxial DIAMs far past the surfaces' rims, which
    # the importer sets to the rims and cuts back where neighbouring edges cross
    "wide-angle-170fov",
]

# The other optiland objectives and simple lenses, and the non-camera samples that still are
# refracting systems with the image in air (an eyepiece, an infinity-corrected microscope
# objective, a UV lithography lens whose finite object distance is noted and not kept):
# first-order data at the d line only, to keep the run short. The full real-ray comparison of
# each was run once (docs/lens-import.md, "optiland samples").
MORE_SAMPLE_NAMES = [
    "field-corrector",
    "objective-us8879901",
    "projection-120fov",
    "projection-160fov",
    "reverse-telephoto",
    "telephoto",
    "telescope-objective-48in",
    "triplet-telescope-objective",
    "wide-angle-100fov",
    "cemented-achromat",
    "edmund-49-847",
    "singlet-stop-surf2",
    "telescope-doublet",
    "erfle-eyepiece",
    "objective-60x",
    "uv-projection-lens",
]

# Samples outside what petzval models: the import must fail at the offending line, saying why.
UNSUPPORTED_SAMPLES = {
    "infrared-triplet": "infrared materials such as germanium are not supported",
    "infrared-triplet-f4": "infrared materials such as germanium are not supported",
    "uv-reflecting-microscope": "mirrors are not supported",
    "hubble": "mirrors are not supported",
    # its image lies 0.196 mm in front of the last surface, inside the last element's glass
    "microscope-20x": "mm in front of the last lens surface",
}


def _set_primary(optic: Optic, wl_nm: float) -> None:
    optic.wavelengths.add(value=wl_nm / 1000.0, is_primary=True)


@functools.cache
def _zemax_file(sample: str, tmpdir: str) -> str:
    """Writes the sample as <tmpdir>/<sample>.zmx, with DIAM (semi-apertures from optiland's
    paraxial marginal + chief ray heights) so the importer has clear apertures."""
    from optiland.fileio import save_zemax_file

    optic = _samples()[sample]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic.updater.update_paraxial()
        path = os.path.join(tmpdir, f"{sample}.zmx")
        save_zemax_file(optic, path)
    return path


@functools.cache
def _our_glass_sources() -> dict[str, str]:
    """Our catalogue: normalised glass name -> its refractiveindex.info file (the "# src=" line
    above each row of renderer/optics/data/glass_catalog.tsv)."""
    out, src = {}, None
    for line in (pz.REPO / "renderer" / "optics" / "data" / "glass_catalog.tsv").read_text().splitlines():
        if line.startswith("# src="):
            src = line[len("# src=") :].split()[0]
        elif line and not line.startswith("#") and src:
            out[re.sub(r"[-_ .]", "", line.split("\t")[0]).upper()] = src
            src = None
    return out


def _use_our_glass_files(optic: Optic) -> None:
    """Where optiland resolves a bare glass name to another maker's file than our catalogue
    does (SF15 and SF4: HIKARI there, Schott here; SF5: optiland picks N-SF5), give the reference
    our file, so both sides trace the same glass and the comparison tests the import and the
    tracer, not the name lookup (the two readings differ by ~1e-6 to 1e-5 in index)."""
    import optiland.database
    from optiland.materials import MaterialFile

    root = os.path.join(os.path.dirname(optiland.database.__file__), "data-nk")
    ours = _our_glass_sources()
    for surf in optic.surfaces.surfaces:
        mat = surf.material_post
        name, filename = getattr(mat, "name", None), getattr(mat, "filename", None)
        src = ours.get(re.sub(r"[-_ .]", "", str(name)).upper()) if name and filename else None
        if src and os.path.realpath(filename) != os.path.realpath(os.path.join(root, src)):
            surf.material_post = MaterialFile(os.path.join(root, src))


def _sample_reference(sample: str, wl_nm: float) -> Optic:
    """optiland's own model of the sample (real glasses), at primary wavelength wl_nm, with the
    stop fixed at the size written to the file (float_by_stop_size) and the same clear
    apertures as DIAM."""
    optic = _samples()[sample]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic.updater.update_paraxial()
        _use_our_glass_files(optic)
    stop = optic.surfaces.surfaces[optic.surfaces.stop_index]
    stop_semi = float(_f(stop.semi_aperture))
    _set_primary(optic, wl_nm)
    optic.set_aperture(aperture_type="float_by_stop_size", value=2.0 * stop_semi)
    for k in range(1, optic.surfaces.num_surfaces - 1):
        surf = optic.surfaces.surfaces[k]
        surf.aperture = RadialAperture(r_max=float(_f(surf.semi_aperture)))
        if hasattr(surf.geometry, "tol"):
            # the samples use the surface factory's default Newton tolerance, 1e-6 (mm of sag
            # residual), which alone moves image intercepts by ~1e-6 mm at 40 degrees
            surf.geometry.tol = NEWTON_TOL
            surf.geometry.max_iter = 200
    return optic


@pytest.fixture(scope="module")
def zemax_dir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("zemax"))


def _optiland_indices(optic: Optic, wl_nm: float) -> list[float]:
    n = np.asarray(be.to_numpy(optic.surfaces.n(wl_nm / 1000.0)), dtype=float).ravel()
    return [float(v) for v in n[1:-1]]  # after each lens surface


def _index_profiles(exp: dict, optic: Optic, wl_nm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Index along the axis, n(z), on both sides, sampled at the middle of every gap between
    vertices (so an importer may add or merge surfaces, e.g. a separate plane stop)."""
    ours_z = np.array([s["z_mm"] for s in exp["surfaces"]])
    ours_n = np.array([s["index_after"] for s in exp["surfaces"]])
    pos = np.asarray(be.to_numpy(optic.surfaces.positions), dtype=float).ravel()[1:-1]
    ref_z = pos - pos[0]
    ref_n = np.array(_optiland_indices(optic, wl_nm))
    zs = np.unique(np.concatenate([ours_z, ref_z]))
    mids = 0.5 * (zs[:-1] + zs[1:])
    mids = mids[np.diff(zs) > 1e-9]

    def n_at(z_v, n_v, z):
        i = np.searchsorted(z_v, z, side="right") - 1
        return np.where(i < 0, 1.0, n_v[np.clip(i, 0, len(n_v) - 1)])

    return mids, n_at(ours_z, ours_n, mids), n_at(ref_z, ref_n, mids)


def _glass_names(optic: Optic) -> list[str]:
    names = []
    for surf in optic.surfaces.surfaces[1:-1]:
        m = surf.material_post
        nm = getattr(m, "name", None)
        ref = getattr(m, "reference", None)
        names.append(f"{nm}" + (f" ({ref})" if ref else "") if nm else type(m).__name__)
    return names


@pytest.mark.parametrize("wavelength_nm", [D_NM, F_NM], ids=["d", "F"])
def test_zemax_sample_paraxial(petzval_bin, zemax_dir, sample, wavelength_nm, deviation_log):
    check_zemax_paraxial(sample, zemax_dir, wavelength_nm, deviation_log)


def test_zemax_more_samples_paraxial(petzval_bin, zemax_dir, more_sample, deviation_log):
    """The other optiland samples: imported, first-order data as optiland's at the d line."""
    check_zemax_paraxial(more_sample, zemax_dir, D_NM, deviation_log)


@pytest.mark.parametrize("unsupported", sorted(UNSUPPORTED_SAMPLES))
def test_zemax_unsupported_samples_fail_clearly(petzval_bin, zemax_dir, unsupported):
    """Mirrors, infrared materials and images inside a medium: `lens info` fails with the
    file, the line of the offending keyword and the reason (no panic, no silent lens)."""
    path = _zemax_file(unsupported, zemax_dir)
    with pytest.raises(pz.PetzvalError) as err:
        pz.lens_info(path, wavelength=D_NM)
    msg = str(err.value)
    want = UNSUPPORTED_SAMPLES[unsupported]
    # the same for `lens trace` and `render` goes through the same import; one call suffices
    assert "panicked" not in msg, msg
    assert re.search(re.escape(path) + r":\d+: ", msg), f"{unsupported}: error does not name file:line:\n{msg}"
    assert want in msg, f"{unsupported}: expected {want!r} in:\n{msg}"


def test_zemax_eye_model_images_inside_the_eye(petzval_bin, zemax_dir, deviation_log):
    """optiland's Navarro wide-angle eye: the image lies in the vitreous (n' = 1.3377), which
    our lenses support. Our EFL is 1/power; optiland's f2 is the image-side focal length
    n'/power. The retina's curvature is not kept (the sensor is flat), with a note."""
    path = _zemax_file("navarro-eye", zemax_dir)
    ref = _sample_reference("navarro-eye", D_NM)
    exp = pz.lens_export(path, wavelength=D_NM)
    info = pz.lens_info(path, wavelength=D_NM)
    n_img = exp["surfaces"][-1]["index_after"]
    assert abs(n_img - 1.3377) < 1e-12, n_img
    f2 = _f(ref.paraxial.f2())
    dev = abs(info["efl_mm"] * n_img - f2) / f2
    deviation_log.add("zemax 587.562", "navarro-eye", "|n' efl - f2| / f2", dev)
    assert dev < PARAXIAL_REL, f"n' x EFL {info['efl_mm'] * n_img} vs optiland f2 {f2}"
    toml = pz.run(["lens", "export", path])
    assert "curvature (SURF 6 CURV, radius -12.0000 mm) is not kept" in toml, f"curved retina not noted:\n{toml[:600]}"


def check_zemax_paraxial(sample: str, zemax_dir: str, wavelength_nm: float, deviation_log) -> None:
    """Imported sample against optiland's own model: track, glass indices, first-order data."""
    path = _zemax_file(sample, zemax_dir)
    ref_optic = _sample_reference(sample, wavelength_nm)
    exp = pz.lens_export(path, wavelength=wavelength_nm)
    info = pz.lens_info(path, wavelength=wavelength_nm)
    check_export_consistency(exp)
    ref_track = _f(ref_optic.total_track)
    ours_track = exp["surfaces"][-1]["z_mm"] + exp["image_distance_mm"]
    assert abs(ours_track - ref_track) <= 1e-9 * ref_track, f"{sample}: track {ours_track} vs optiland {ref_track}"

    # Glass: do both sides use the same index at this wavelength (n(z) along the axis)?
    _, n_ours, n_ref = _index_profiles(exp, ref_optic, wavelength_nm)
    dn = float(np.max(np.abs(n_ours - n_ref)))
    deviation_log.add(f"zemax {wavelength_nm:g}", sample, "max |n_petzval - n_optiland|", dn)
    glass_same = dn <= 1e-9
    rel = 1e-6 if glass_same else 1e-5

    last_z = exp["surfaces"][-1]["z_mm"]
    ref = optiland_paraxial(ref_optic, last_z, exp["image_distance_mm"])
    # The sensor (total track) sits at the focus for the lens's primary wavelength (the file's
    # PWAV), whatever --wavelength says.
    primary_nm = pz.lens_export(path)["wavelength_nm"]
    ref["total_track_mm"] = optiland_paraxial(_sample_reference(sample, primary_nm), last_z, exp["image_distance_mm"])[
        "back_focal_z_mm"
    ]
    ours = ours_paraxial(info)
    fails, devs = compare_values(ours, ref, rel, PARAXIAL_ABS_MM if glass_same else 1e-6)
    for k, v in devs.items():
        deviation_log.add(f"zemax {wavelength_nm:g}", sample, k, v)
    glass_note = (
        ""
        if glass_same
        else f"\n  (glass indices differ by up to {dn:.2e}: petzval {n_ours.tolist()} vs optiland {n_ref.tolist()}, "
        f"glasses {_glass_names(ref_optic)})"
    )
    assert not fails, (
        f"{sample} @ {wavelength_nm} nm: imported lens disagrees with optiland:\n  " + "\n  ".join(fails) + glass_note
    )


@pytest.mark.parametrize("wavelength_nm", [D_NM, F_NM], ids=["d", "F"])
def test_zemax_sample_real_rays(petzval_bin, zemax_dir, sample, wavelength_nm, deviation_log):
    path = _zemax_file(sample, zemax_dir)
    ref_optic = _sample_reference(sample, wavelength_nm)
    exp = pz.lens_export(path, wavelength=wavelength_nm)
    info = pz.lens_info(path, wavelength=wavelength_nm)
    _, n_ours, n_ref = _index_profiles(exp, ref_optic, wavelength_nm)
    dn = float(np.max(np.abs(n_ours - n_ref)))
    if dn > 1e-9:
        pytest.skip(
            f"glass indices differ by {dn:.2e} (petzval {n_ours.tolist()} vs optiland {n_ref.tolist()}): "
            "real-ray intercepts cannot agree to 1e-6 mm"
        )
    max_field = max(float(_f(f.y)) for f in ref_optic.fields.fields)
    angles = field_angles(info["efl_mm"], False, max_deg=max_field if max_field > 0 else None)
    rays, labels = build_rays(exp, info, ref_optic, angles, wavelength_nm / 1000.0)
    cmp = compare_rays(path, exp, ref_optic, rays, labels, wavelength_nm)
    tag = f"zemax {wavelength_nm:g}"
    deviation_log.add(tag, sample, "max image intercept dev (mm)", cmp.max_intercept_dev_mm)
    deviation_log.add(tag, sample, "rays total/both ok/both vignetted/edge-disagree",
                      f"{cmp.n_rays}/{cmp.n_ok_both}/{cmp.n_vignetted_both}/{cmp.n_edge_disagree}")
    deviation_log.add(tag, sample, "reverse: max position off incoming ray (mm)", cmp.max_reverse_pos_mm)
    deviation_log.add(tag, sample, "reverse: max direction dev", cmp.max_reverse_dir)
    problems = cmp.failures + cmp.reverse_failures
    assert not problems, f"{sample} @ {wavelength_nm} nm: {len(problems)} real-ray problems:\n  " + "\n  ".join(
        problems
    )
    assert cmp.n_ok_both > 0, f"{sample}: no ray got through both tracers"


def test_zemax_files_use_known_glasses(petzval_bin, zemax_dir):
    """Every glass name optiland writes is one our catalogue resolves (import must not fail)."""
    problems = []
    for sample in SAMPLE_NAMES + MORE_SAMPLE_NAMES:
        path = _zemax_file(sample, zemax_dir)
        try:
            pz.lens_export(path, wavelength=D_NM)
        except pz.PetzvalError as e:
            with open(path) as fh:
                glas = [ln.split()[1] for ln in fh if ln.strip().startswith("GLAS")]
            msg = next((ln for ln in str(e).splitlines() if ln.startswith("error")), str(e))
            problems.append(f"{sample} (glasses {glas}): {msg}")
    assert not problems, "importing optiland-written Zemax files failed:\n  " + "\n  ".join(problems)
