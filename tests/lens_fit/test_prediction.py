"""Prediction: the lens fitted to six optiland captures (conftest's ``optiland_fit``) predicts three
others it has not seen (other field positions, focus distances and f-numbers) through
``petzval-fit --evaluate``, which fits only each capture's scale, background and sub-pixel shift.
The held-out residuals must be as small as the fitted ones' bound, and the shifts as small: the
lens and camera geometry, not the nuisance, must explain the images.
"""

from __future__ import annotations

import math

from test_optiland_captures import RESIDUAL_MAX, SHIFT_MAX_PX


def test_fit_predicts_held_out_captures(optiland_fit):
    ev = optiland_fit["eval"]
    param = optiland_fit["param"]
    fitted = optiland_fit["fit"]["params"][param]["value"]
    assert ev["params"][param]["value"] == fitted, "--evaluate must keep the earlier fit's lens"
    residuals = [c["residual"] for c in ev["captures"]]
    shifts = [math.hypot(*c["shift_px"]) for c in ev["captures"]]
    print(
        f"\nheld-out optiland captures (3 × 48² px): residuals {', '.join(f'{r:.4f}' for r in residuals)}, "
        f"|shift| ≤ {max(shifts):.3f} px; evaluate {ev['seconds']:.1f} s (wall {optiland_fit['eval_s']:.1f} s)"
    )
    assert len(residuals) == 3
    for i, (r, s) in enumerate(zip(residuals, shifts, strict=True)):
        assert r < RESIDUAL_MAX, f"held-out capture {i + 1}: residual {r}"
        assert s < SHIFT_MAX_PX, f"held-out capture {i + 1}: shift {s} px"
