"""Writes Zemax .zmx test fixtures with optiland (PyPI), an independent optics package.

    .venv/bin/python tests/optics/write_optiland_zmx.py renderer/optics/tests/data/zmx

For each sample lens, optiland computes its paraxial data (so the file carries DIAM
semi-apertures) and writes it with ``optiland.fileio.save_zemax_file`` (UTF-8 text).
``cooke_triplet_utf16.zmx`` is the same Cooke triplet re-encoded as UTF-16 LE with a byte-order
mark and CRLF line ends, as OpticStudio writes files. ``expected.json`` records optiland's own
paraxial focal length and back focal length of each sample at the file's primary wavelength,
which the Rust tests compare with the imported lens (renderer/tests/import.rs).

Samples: Cooke triplet (stop on a curved surface with glass in front), Tessar (plane stop),
Petzval f/1.4 (inch design scaled to mm), double Gauss, and even-asphere singlets (EVENASPH):
optiland's own (with an r^2 term, which the importer refuses), one with A4/A6 only and a plane
stop in front, and one with the stop on its plane rear face (glass in front of the stop).
"""

from __future__ import annotations

import json
import os
import sys
import warnings

from optiland.fileio import save_zemax_file
from optiland.samples.objectives import CookeTriplet, DoubleGauss, PetzvalLens, TessarLens
from optiland.samples.simple import AsphericSinglet


def aspheric_singlet_a4():
    """AsphericSinglet with its r^2 coefficient zeroed (A4, A6 remain) and a plane stop in air
    2 mm in front of it."""
    import optiland.backend as be

    optic = AsphericSinglet()
    optic.surfaces.surfaces[1].geometry.coefficients[0] = 0.0
    optic.surfaces.add(index=1, radius=be.inf, thickness=2.0)
    optic.surfaces.stop_index = 1
    return optic


def aspheric_singlet_stop_on_glass():
    """AsphericSinglet (r^2 coefficient zeroed) with the stop on its plane rear face (glass to
    air), which our importer must turn into a separate plane stop in air."""
    optic = AsphericSinglet()
    optic.surfaces.surfaces[1].geometry.coefficients[0] = 0.0
    optic.surfaces.stop_index = 2
    return optic


SAMPLES = {
    "cooke_triplet": CookeTriplet,
    "tessar": TessarLens,
    "petzval": PetzvalLens,
    "double_gauss": DoubleGauss,
    # optiland's own sample: its first coefficient is an r^2 term (Zemax PARM 1), which our
    # format cannot hold: the importer must refuse it at that line.
    "aspheric_singlet": AsphericSinglet,
    "aspheric_singlet_a4": aspheric_singlet_a4,
    "aspheric_singlet_stop_on_glass": aspheric_singlet_stop_on_glass,
}


def _f(value) -> float:
    try:
        return float(value)
    except TypeError:
        return float(value.ravel()[0])


def main(out_dir: str) -> None:
    os.makedirs(out_dir, exist_ok=True)
    expected = {}
    for name, cls in SAMPLES.items():
        optic = cls()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            optic.updater.update_paraxial()
            path = os.path.join(out_dir, f"{name}.zmx")
            save_zemax_file(optic, path)
        expected[name] = {
            "efl_mm": _f(optic.paraxial.f2()),
            "primary_wavelength_um": _f(optic.primary_wavelength),
        }
        print(f"{path}: EFL {expected[name]['efl_mm']:.6f} mm")
    with open(os.path.join(out_dir, "cooke_triplet.zmx"), encoding="utf-8") as fh:
        text = fh.read()
    utf16 = os.path.join(out_dir, "cooke_triplet_utf16.zmx")
    with open(utf16, "wb") as fh:
        fh.write(b"\xff\xfe" + text.replace("\n", "\r\n").encode("utf-16-le"))
    print(f"{utf16}: UTF-16 LE copy")
    with open(os.path.join(out_dir, "expected.json"), "w", encoding="utf-8") as fh:
        json.dump(expected, fh, indent=2, sort_keys=True)
        fh.write("\n")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: write_optiland_zmx.py OUTPUT_DIR")
    main(sys.argv[1])
