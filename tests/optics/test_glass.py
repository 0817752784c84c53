"""Cross-check renderer/optics/data/glass_catalog.tsv against optiland's own refractive indices.

For every catalogue row, the index is computed with a tiny pure-Python copy of the renderer's
two formulas (renderer/optics/src/glass.rs, `Dispersion::index`) and compared with the index
optiland computes for the same glass, at 400, 486.1327 (F), 587.5618 (d), 656.2725 (C) and
760 nm. The optiland material is created through its catalogue API,
``optiland.materials.Material(name, catalog=<maker>)``, when that resolves to the very file the
row was generated from (the ``# src=`` comment above the row); where optiland's fuzzy name
resolution picks another file (e.g. "SF5" in the Schott folder resolves to N-SF5), the source
YAML file is loaded directly with ``optiland.materials.MaterialFile``.

Run:  /work/main/.venv/bin/python -m pytest /work/main/tests/optics/test_glass.py -q
"""

from __future__ import annotations

import importlib.util
import math
import os
import warnings
from pathlib import Path

import numpy as np
import optiland.database
import pytest
from optiland.materials import Material, MaterialFile
from optiland.materials.material_spec import MatchPolicy

REPO = Path(__file__).resolve().parents[2]
TSV = REPO / "renderer" / "optics" / "data" / "glass_catalog.tsv"
GENERATOR = Path(__file__).resolve().parent / "gen_glass_catalog.py"
DATA_NK = Path(os.path.dirname(optiland.database.__file__)) / "data-nk"

WAVELENGTHS_NM = [400.0, 486.1327, 587.5618, 656.2725, 760.0]
TOLERANCE = 1e-6


def parse_tsv(text: str) -> list[dict]:
    """Rows as the renderer's parse_catalog sees them, plus the `# src=` file above each."""
    rows = []
    src = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if line.startswith("# src="):
                src = line[len("# src=") :].split()[0]
            continue
        cols = line.split("\t")
        assert len(cols) >= 4, f"short row: {raw!r}"
        rows.append(
            {
                "name": cols[0],
                "catalogue": cols[1],
                "formula": cols[2],
                "coefs": [float(c) for c in cols[3:]],
                "src": src,
            }
        )
        src = None
    return rows


def index(formula: str, coefs: list[float], wavelength_nm: float) -> float:
    """Pure-Python copy of the renderer's Dispersion::index (wavelength in nm)."""
    l_um = wavelength_nm * 1e-3
    l2 = l_um * l_um
    if formula == "sellmeier":
        assert len(coefs) % 2 == 0
        n2 = 1.0
        for b, c in zip(coefs[0::2], coefs[1::2], strict=True):
            n2 += b * l2 / (l2 - c)
        return math.sqrt(n2)
    if formula == "schott":
        assert len(coefs) == 6
        a = coefs
        il2 = 1.0 / l2
        return math.sqrt(a[0] + a[1] * l2 + il2 * (a[2] + il2 * (a[3] + il2 * (a[4] + il2 * a[5]))))
    if formula == "polynomial":
        assert len(coefs) % 2 == 1
        return math.sqrt(coefs[0] + sum(c * l_um**e for c, e in zip(coefs[1::2], coefs[2::2], strict=True)))
    raise AssertionError(f"unknown formula {formula}")


def normalize(name: str) -> str:
    """The renderer's lookup key: case, '-', '_', ' ' and '.' ignored."""
    return "".join(ch for ch in name if ch not in "-_ .").upper()


ROWS = parse_tsv(TSV.read_text(encoding="utf-8"))


def _catalog_dir(src: str) -> str:
    parts = src.split("/")
    return parts[1] if parts[0] == "glass" else parts[-2]


def optiland_material(row: dict):
    """(material, how): optiland's catalogue lookup if it finds the source file, else the file."""
    src_path = (DATA_NK / row["src"]).resolve()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            mat = Material(
                row["name"], catalog=_catalog_dir(row["src"]), match_policy=MatchPolicy.BEST
            )
            if Path(mat.filename).resolve() == src_path:
                return mat, "Material"
        except ValueError:
            pass
        return MaterialFile(str(src_path)), "MaterialFile"


def optiland_n(mat, wavelength_nm: float) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return float(np.ravel(np.asarray(mat.n(wavelength_nm * 1e-3)))[0])


def test_catalogue_is_not_empty_and_every_row_names_its_source():
    assert len(ROWS) >= 80
    for row in ROWS:
        assert row["src"], f"{row['name']}: no '# src=' comment above the row"
        assert (DATA_NK / row["src"]).is_file(), row["src"]
        assert row["formula"] in ("sellmeier", "schott", "polynomial")
        assert row["catalogue"] == row["catalogue"].lower()


def test_names_are_unique_under_the_renderer_lookup():
    seen: dict[str, str] = {}
    for row in ROWS:
        key = normalize(row["name"])
        assert key not in seen, f"{row['name']} collides with {seen[key]}"
        seen[key] = row["name"]


@pytest.mark.parametrize(
    "name",
    [
        # lentil-lenses.json glasses, as written there
        "LAK9", "SF5", "BAF10", "SF15", "SK16",
        "SLAH59", "SBAH10", "STIM1", "STIH53", "SLAH64", "STIH6",
        # plus the requested common ones (spot check)
        "N-BK7", "N-SF6", "N-LASF9", "S-BSL7", "S-FPL53", "E-FD1", "FCD1", "TAF1",
        "H-K9L", "H-ZF7LA", "H-LAK52", "H-ZLAF52A",
    ],
)  # fmt: skip
def test_requested_glass_is_present(name):
    keys = {normalize(r["name"]) for r in ROWS}
    assert normalize(name) in keys


def test_generator_reproduces_the_file():
    spec = importlib.util.spec_from_file_location("gen_glass_catalog", GENERATOR)
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    text, _ = gen.build()
    assert text == TSV.read_text(encoding="utf-8"), "re-run tests/optics/gen_glass_catalog.py"


MAX_DEVIATION = {"value": 0.0, "where": None, "via": {}}


@pytest.mark.parametrize("row", ROWS, ids=[f"{r['catalogue']}:{r['name']}" for r in ROWS])
def test_index_matches_optiland(row):
    mat, how = optiland_material(row)
    MAX_DEVIATION["via"][how] = MAX_DEVIATION["via"].get(how, 0) + 1
    for wl in WAVELENGTHS_NM:
        ours = index(row["formula"], row["coefs"], wl)
        theirs = optiland_n(mat, wl)
        dev = abs(ours - theirs)
        if dev > MAX_DEVIATION["value"]:
            MAX_DEVIATION["value"] = dev
            MAX_DEVIATION["where"] = (row["name"], wl)
        assert dev <= TOLERANCE, (
            f"{row['name']} ({row['src']}, via {how}) at {wl} nm: ours {ours!r}, "
            f"optiland {theirs!r}, diff {dev:.3e}"
        )


def test_zz_report_max_deviation(capsys):
    """Runs last (file order): prints the largest deviation seen above (use -s to see it)."""
    with capsys.disabled():
        print(
            f"\nglass catalogue: {len(ROWS)} rows, max |n_ours - n_optiland| = "
            f"{MAX_DEVIATION['value']:.3e} at {MAX_DEVIATION['where']}; "
            f"optiland objects: {MAX_DEVIATION['via']}"
        )
    assert MAX_DEVIATION["value"] <= TOLERANCE
