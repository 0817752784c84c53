#!/usr/bin/env python3
"""Generate renderer/optics/data/glass_catalog.tsv from the refractiveindex.info database.

The data come from the refractiveindex.info database (CC0 1.0, Mikhail Polyanskiy), as
shipped inside the `optiland` PyPI package (optiland/database/data-nk/glass/<maker>/<glass>.yml).
The YAML files are read directly; nothing is fitted or edited: coefficients are copied as
written, only re-arranged into one of the two formulas the renderer knows:

* ``sellmeier``  n^2 = 1 + sum B_i l^2 / (l^2 - C_i)    (l in um, C_i in um^2)
    - refractiveindex.info "formula 2" (C given in um^2): copied as is; a non-zero constant
      term c0 becomes an extra pair (c0, 0), since B l^2/(l^2 - 0) = B.
    - refractiveindex.info "formula 1" (denominator l^2 - C^2): C is squared.
* ``schott``     n^2 = A0 + A1 l^2 + A2 l^-2 + A3 l^-4 + A4 l^-6 + A5 l^-8
    - refractiveindex.info "formula 3" (polynomial) whose exponents are a subset of
      {2, -2, -4, -6, -8} (any other exponent with a zero coefficient is dropped).
* ``polynomial`` n^2 = A0 + sum c_i l^e_i
    - any other "formula 3" (e.g. HIKARI's, with an l^4 term): copied as is, A0 c1 e1 c2 e2 ...

Usage (from the repository root):

    /work/main/.venv/bin/python tests/optics/gen_glass_catalog.py            # writes the TSV
    /work/main/.venv/bin/python tests/optics/gen_glass_catalog.py --check    # only diff

The per-glass comment line ``# src=glass/<maker>/<file>.yml ...`` above each row is used by
tests/optics/test_glass.py to find the source file again; keep its format.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
OUT = REPO / "renderer" / "optics" / "data" / "glass_catalog.tsv"


def database_root() -> Path:
    import optiland.database  # imported here: only needed to locate the data files

    return Path(os.path.dirname(optiland.database.__file__)) / "data-nk"


# Visible range the renderer supports (um).
VIS_MIN, VIS_MAX = 0.380, 0.780
# A range that starts at most this far above 380 nm is accepted (with a note) for any glass.
SMALL_GAP_MIN = 0.405  # mercury h line, 404.66 nm

# ---------------------------------------------------------------------------------------------
# Selection: (catalogue directory, file stem as the manufacturer spells it, why).
# "lentil"  = used by /work/shared/lenses/lentil-lenses.json
# "optiland" = used by optiland's sample lenses (optiland/samples/*.py), same file optiland
#              resolves to. Glasses that only exist with a data range shorter than 380-780 nm
#              are accepted only when they carry one of these two tags.
# ---------------------------------------------------------------------------------------------
LENTIL = "lentil"
OPTILAND = "optiland"
COMMON = "common"

SELECTION: list[tuple[str, str, str]] = []


def _add(cat: str, names: str, why: str) -> None:
    for n in names.split():
        SELECTION.append((cat, n, why))


# 1. lentil-lenses.json: LAK9 SF5 BAF10 SF15 SK16 SLAH59 SBAH10 STIM1 STIH53 SLAH64 STIH6.
#    Old Schott types: SF5 and SF15 are still in the Schott folder. LAK9, BAF10 and SK16 are
#    not; the same names are still listed by HIKARI (LAK9, SK16; data 0.4-0.7 um only) and
#    HOYA (BAF10; data 0.365-1.014 um, preferred over HIKARI BAF10 which covers 0.4-0.7 um).
#    The N- successors are listed too (they are different glasses with other names).
_add("hikari", "LAK9 SK16", LENTIL)
_add("hoya", "BAF10", LENTIL)
_add("schott", "SF5 SF15", LENTIL)
_add("schott", "N-LAK9 N-SF5 N-BAF10 N-SF15 N-SK16", LENTIL)
_add("ohara", "S-LAH59 S-BAH10 S-TIM1 S-TIH53 S-LAH64 S-TIH6", LENTIL)

# 2. optiland sample lenses (file optiland resolves each name to).
_add(
    "schott",
    "F2 F5 FK3 K10 LF5 SF1 SF2 SF4 LITHOTEC-CAF2 N-BAK1 N-BAK2 N-BASF2 N-BK7 N-F2 N-FK51 "
    "N-K5 N-KZFS4 N-LAF32 N-LAF33 N-LAK7 N-LAK12 N-LAK21 N-PSK3 N-SF11 N-SK2 N-SK4 N-SK5 "
    "N-SK10 N-SK11 N-SK15 N-SSK2 N-ZK7",
    OPTILAND,
)
_add("ohara", "L-BSL7 S-FSL5 S-LAL18", OPTILAND)
_add("hoya", "LAC9 M-TAF1", OPTILAND)
_add("cdgm", "H-LAK52 H-ZLAF52A", OPTILAND)
# HIKARI SK16 is listed above; SF15 and SF4 are also used by optiland from HIKARI but the
# names are taken by the Schott originals (the lookup is by name only).
_add("hikari", "BASF2 SK15 E-LLF6 E-SF1", OPTILAND)
# HIKARI J- and Q- glasses of ObjectiveUS008879901 and Objective60x (formula 3 with an l^4
# term: the "polynomial" formula).
_add("hikari", "J-LASF015 Q-LAFPH1S J-LLF2", OPTILAND)
# Calcium fluoride crystal of the TelescopeObjective48Inch sample (not a catalogue glass).
MAIN_EXTRA = [("main/CaF2/Daimon-20.yml", "CaF2", "daimon", OPTILAND)]

# 3. Common catalogue glasses.
_add(
    "schott",
    "N-BK10 N-KF9 N-BAK4 N-BALF4 N-BAF4 N-BAF52 N-BASF64 N-SSK8 N-FK5 N-FK51A N-PK51 "
    "N-PK52A N-LAK8 N-LAK14 N-LAK22 N-LAF2 N-LAF34 N-LASF9 N-LASF40 N-LASF43 N-LASF44 "
    "N-LASF46A N-KZFS8 N-KZFS11 N-SF1 N-SF2 N-SF6 N-SF8 N-SF10 N-SF57 N-SF66 LLF1 SF6 "
    "SF10 SF11 SF57 LITHOSIL-Q",
    COMMON,
)
_add(
    "ohara",
    "S-BSL7 S-BSM2 S-BSM14 S-BAL42 S-BAH11 S-LAL8 S-LAL10 S-LAL14 S-LAH55V S-LAH58 "
    "S-LAH60 S-LAH65V S-LAH66 S-TIM2 S-TIM25 S-TIM35 S-TIH1 S-TIH10 S-TIH11 S-TIH14 "
    "S-NPH2 S-NBH5 S-FPL51 S-FPL53 S-FPM2 S-PHM52",
    COMMON,
)
_add(
    "hoya",
    "BSC7 E-F5 E-FD1 E-FD5 E-FD10 E-FD15 E-FDS1 FCD1 FCD100 BACD5 LAC8 LAC14 NBF1 TAF1 "
    "TAF3 TAFD5F TAFD25",
    COMMON,
)
_add(
    "cdgm",
    "H-K9L H-QK3L H-K51 H-BAK7 H-ZK3 H-ZK9B H-FK61 H-F4 H-ZF1 H-ZF2 H-ZF4A H-ZF6 H-ZF7LA "
    "H-ZF13 H-ZF52 H-ZBAF52 H-LAK50A H-LAK51A H-LAF3B H-ZLAF50E H-ZLAF55D",
    COMMON,
)

# Extra comments for glasses whose source range is short (0.4-0.7 um HIKARI data, from
# NIKON's 2017 Zemax catalogue). Checked by comparing with a related glass that has full-range
# data: the difference between the two moves by at most ~1e-4 between 400->380 nm and
# 700->780 nm, i.e. the extrapolation error is of the order of 1e-4.
EXTRA_NOTES = {
    "glass/hikari/LAK9.yml": "old Schott LAK9 (691547) is not in the database; this is HIKARI's LAK9"
    " (691548). Extrapolation vs HIKARI J-LAK9: diff changes by -5e-5 (380 nm), +8e-5 (780 nm)",
    "glass/hikari/SK16.yml": "old Schott SK16 (620603) is not in the database; this is HIKARI's SK16"
    " (optiland's Cooke triplet uses it). Extrapolation vs J-SK16: +6e-5 (380), +1e-5 (780)",
    "glass/hoya/BAF10.yml": "old Schott BAF10 (670471) is not in the database; this is HOYA's BAF10"
    " (discontinued; HIKARI BAF10 exists too but only 400-700 nm data)",
    "glass/hikari/BASF2.yml": "extrapolation vs Schott N-BASF2: -9e-5 (380 nm), +9e-5 (780 nm)",
    "glass/hikari/SK15.yml": "extrapolation vs HIKARI J-SK15: +3e-5 (380 nm), 0 (780 nm)",
    "glass/hikari/E-LLF6.yml": "extrapolation vs HIKARI J-LLF6: < 1e-5 at 380 and 780 nm",
    "glass/hikari/E-SF1.yml": "extrapolation vs HIKARI J-SF1: +2e-5 (380 nm), -1e-5 (780 nm)",
    "main/CaF2/Daimon-20.yml": "crystal, not a catalogue glass: M. Daimon & A. Masumura,"
    " Appl. Opt. 41, 5275 (2002), 20 C in nitrogen",
}


HEADER = """\
# Petzval embedded optical glass catalogue.
# GENERATED by tests/optics/gen_glass_catalog.py -- do not edit by hand; re-run the script.
#
# Source: refractiveindex.info database (https://refractiveindex.info, CC0 1.0 Universal,
# Mikhail Polyanskiy), as shipped inside the optiland PyPI package ({optiland}),
# files optiland/database/data-nk/<path>; each glass's file is named in the "# src=" line above it.
# The coefficients are the manufacturers' catalogue data as republished there, copied unchanged
# (formula 1 C^2 and formula 2/3 re-arrangement only; see the generator).
#
# Columns (tab separated): name  catalogue  formula  coefficients...
#   sellmeier: B1 C1 B2 C2 ... ; n^2 = 1 + sum B_i l^2/(l^2 - C_i), l in um, C_i in um^2
#   schott:    A0 A1 A2 A3 A4 A5 ; n^2 = A0 + A1 l^2 + A2 l^-2 + A3 l^-4 + A4 l^-6 + A5 l^-8
#   polynomial: A0 c1 e1 c2 e2 ... ; n^2 = A0 + sum c_i l^e_i (refractiveindex.info formula 3)
# Indices are relative to air, as in the manufacturers' catalogues.
# Names are the manufacturers' spelling; lookup ignores case, '-', '_', ' ' and '.'.
# range_um is the validity range stated in the source file; a NOTE says when it does not
# cover the renderer's 380-780 nm (the formula is then extrapolated there).
"""

SCHOTT_EXPONENTS = [0.0, 2.0, -2.0, -4.0, -6.0, -8.0]


def load(path: Path) -> dict:
    with open(path, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def convert(block: dict) -> tuple[str, list[str], str]:
    """Return (formula, coefficient strings, conversion note) for one DATA formula block."""
    ftype = block["type"].strip()
    tokens = str(block["coefficients"]).split()
    vals = [float(t) for t in tokens]
    if ftype in ("formula 1", "formula 2"):
        if len(vals) % 2 != 1:
            raise ValueError(f"{ftype} with {len(vals)} coefficients")
        out: list[str] = []
        note = ""
        for i in range(1, len(vals), 2):
            b_tok, c_tok = tokens[i], tokens[i + 1]
            if ftype == "formula 1":
                c_tok = repr(vals[i + 1] * vals[i + 1])
                note = "formula 1: C squared"
            out += [b_tok, c_tok]
        if vals[0] != 0.0:
            out += [tokens[0], "0"]
            note = (note + "; " if note else "") + "constant term as pair (c0, 0)"
        return "sellmeier", out, note
    if ftype == "formula 3":
        slots = ["0"] * 6
        seen = set()
        slots[0] = tokens[0]
        seen.add(0.0)
        for i in range(1, len(vals), 2):
            coef_tok, exp = tokens[i], vals[i + 1]
            if exp in SCHOTT_EXPONENTS and exp not in seen:
                slots[SCHOTT_EXPONENTS.index(exp)] = coef_tok
                seen.add(exp)
            elif vals[i] != 0.0:
                # a term the Schott form lacks: keep the general polynomial, copied as written
                return "polynomial", tokens, ""
        return "schott", slots, ""
    raise ValueError(f"{ftype} not expressible as sellmeier/schott")


def index(formula: str, coefs: list[float], wl_um: float) -> float:
    l2 = wl_um * wl_um
    if formula == "sellmeier":
        n2 = 1.0
        for b, c in zip(coefs[0::2], coefs[1::2], strict=False):
            n2 += b * l2 / (l2 - c)
    elif formula == "polynomial":
        n2 = coefs[0] + sum(c * wl_um**e for c, e in zip(coefs[1::2], coefs[2::2], strict=True))
    else:
        a = coefs
        n2 = a[0] + a[1] * l2 + a[2] / l2 + a[3] / l2**2 + a[4] / l2**3 + a[5] / l2**4
    return math.sqrt(n2)


def normalize(name: str) -> str:
    return "".join(ch for ch in name if ch not in "-_ .").upper()


def build() -> tuple[str, list[str]]:
    root = database_root()
    entries = [(f"glass/{cat}/{stem}.yml", stem, cat, why) for cat, stem, why in SELECTION]
    entries += MAIN_EXTRA
    lines = []
    report = []
    seen_paths: set[str] = set()
    seen_names: dict[str, str] = {}
    for rel, name, cat, why in entries:
        if rel in seen_paths:
            continue
        seen_paths.add(rel)
        key = normalize(name)
        if key in seen_names:
            raise SystemExit(f"{rel}: name {name} collides with {seen_names[key]}")
        seen_names[key] = rel
        path = root / rel
        data = load(path)
        blocks = [b for b in data.get("DATA", []) if b["type"].strip().startswith("formula")]
        if len(blocks) != 1:
            raise SystemExit(f"{rel}: {len(blocks)} formula blocks")
        block = blocks[0]
        try:
            formula, coef_tokens, conv_note = convert(block)
        except ValueError as err:
            raise SystemExit(f"{rel}: {err}") from err
        lo, hi = (float(x) for x in str(block["wavelength_range"]).split()[:2])
        notes = []
        if conv_note:
            notes.append(conv_note)
        if rel in EXTRA_NOTES:
            notes.append(EXTRA_NOTES[rel])
        if lo > VIS_MIN + 1e-9 or hi < VIS_MAX - 1e-9:
            gap = f"NOTE: source range {lo * 1000:g}-{hi * 1000:g} nm does not cover 380-780 nm"
            if lo <= SMALL_GAP_MIN and hi >= VIS_MAX - 1e-9:
                notes.append(gap + f"; 380-{lo * 1000:g} nm extrapolated")
            elif why in (LENTIL, OPTILAND):
                notes.append(gap + "; extrapolated outside it (kept: " + why + " lens glass)")
            else:
                raise SystemExit(f"{rel}: range {lo}-{hi} um too short for a '{why}' glass")
        coefs = [float(t) for t in coef_tokens]
        # Sanity: physical, normally dispersive index over the whole visible range.
        prev = None
        for nm in range(380, 781):
            n = index(formula, coefs, nm * 1e-3)
            if not (1.2 < n < 2.5) or (prev is not None and n >= prev):
                raise SystemExit(f"{rel}: index {n} at {nm} nm is not physical/normal")
            prev = n
        specs = data.get("SPECS") or {}
        nd = index(formula, coefs, 0.5875618)
        nf = index(formula, coefs, 0.4861327)
        nc = index(formula, coefs, 0.6562725)
        vd = (nd - 1) / (nf - nc)
        if "nd" in specs and abs(float(specs["nd"]) - nd) > 5e-5:
            notes.append(f"formula nd {nd:.5f} differs from listed nd {float(specs['nd'])}")
        status = specs.get("glass_status")
        src = f"# src={rel} {block['type'].strip()} range_um={lo:g}-{hi:g}"
        src += f" nd={nd:.5f} vd={vd:.2f} used_by={why}"
        if status:
            src += f" status={status}"
        lines.append(src)
        for note in notes:
            lines.append(f"#   {note}")
        lines.append("\t".join([name, cat, formula, *coef_tokens]))
        report.append(f"{name:12s} {cat:8s} {formula:9s} {lo:g}-{hi:g} {why} {'; '.join(notes)}")
    try:
        from importlib.metadata import version

        opt = f"optiland {version('optiland')}"
    except Exception:  # pragma: no cover
        opt = "optiland"
    text = HEADER.format(optiland=opt) + f"# {len(report)} glasses.\n" + "\n".join(lines) + "\n"
    return text, report


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="fail if the TSV is not up to date")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    text, report = build()
    if args.verbose:
        print("\n".join(report))
    if args.check:
        current = args.out.read_text(encoding="utf-8") if args.out.exists() else ""
        if current != text:
            print(f"{args.out} is out of date; re-run {Path(__file__).name}", file=sys.stderr)
            return 1
        print(f"{args.out} up to date ({len(report)} glasses)")
        return 0
    args.out.write_text(text, encoding="utf-8")
    print(f"wrote {args.out} ({len(report)} glasses)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
