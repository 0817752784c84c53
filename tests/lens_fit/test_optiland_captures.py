"""petzval-fit against an independent forward model: captures of optiland's Cooke triplet made
by optiland's real-ray trace (optiland_captures.py), fitted from the same lens exported to Zemax
with surface 3's radius started 2 % off (issue 10: "state the residual").

What could fail: the fitted images must match optiland's within RESIDUAL_MAX (‖measured − model‖ /
‖measured − background‖ per capture), the radius must come back to within 2 % of its start error
(a 2 % error becomes < 0.04 %), and each capture's fitted sub-pixel shift must stay under SHIFT_MAX_PX, which checks the
geometry conventions (source and sensor placement, image orientation, crop origin) independently
of the fit: a wrong sign or origin puts the model spot elsewhere and the shift has to make up for it.
"""

from __future__ import annotations

import math

RESIDUAL_MAX = 0.03  # optiland's binned images are noiseless; 32 768 model rays sample to ~1-2 %
SHIFT_MAX_PX = 0.3


def test_fit_reproduces_optiland_captures(optiland_fit):
    fit = optiland_fit["fit"]
    p = fit["params"][optiland_fit["param"]]
    truth, start = optiland_fit["truth_radius"], optiland_fit["start_radius"]
    residuals = [c["residual"] for c in fit["captures"]]
    shifts = [math.hypot(*c["shift_px"]) for c in fit["captures"]]
    sigma = "not determined" if p["sigma"] is None else f"{p['sigma']:.2g}"
    print(
        f"\noptiland captures, Cooke triplet, 6 × 48² px: radius {p['value']:.5f} mm ± {sigma} (optiland "
        f"{truth:.5f}, start {start:.5f}: error {100 * (p['value'] / truth - 1):+.3f} %), residuals "
        f"{', '.join(f'{r:.4f}' for r in residuals)}, |shift| ≤ {max(shifts):.3f} px; fit {fit['seconds']:.1f} s "
        f"(wall {optiland_fit['fit_s']:.1f} s), renders {optiland_fit['render_s']:.1f} s"
    )
    assert abs(p["value"] - truth) < 0.02 * abs(start - truth), (p["value"], truth, start)
    for i, (r, s) in enumerate(zip(residuals, shifts, strict=True)):
        assert r < RESIDUAL_MAX, f"capture {i + 1}: residual {r}"
        assert s < SHIFT_MAX_PX, f"capture {i + 1}: shift {s} px"


def test_sharp_off_axis_spots_fit_within_half_a_percent(optiland_fit):
    """Sharp off-axis spots keep their caustics in the model: with the footprint's old 0.25 px
    floor (forward.rs auto_footprint_px) these two came out at 1.9-2.1 %."""
    off_axis = [optiland_fit["fit"]["captures"][k]["residual"] for k in (1, 3)]  # train02, train04
    assert max(off_axis) < 0.005, off_axis
