"""Shared fixtures for the optics reference tests.

- ``petzval_bin``: the `petzval` binary, located once per session ($PETZVAL_BIN if set, else
  target/release/petzval, built with `cargo build --release` in the repo when missing).
- ``deviation_log``: a session-wide table of measured maximum deviations; the optiland tests
  add rows to it and the largest per quantity are printed at the end of the run (pytest's
  terminal summary; every row with -v), so a passing run still shows how close the two
  implementations came. Rows logged by tests that then fail or xfail are included too.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import petzval_cli

_DEVIATIONS: list[tuple[str, str, str, str, str]] = []  # (nodeid, group, lens, quantity, value)
_OUTCOMES: dict[str, str] = {}  # nodeid -> passed / failed / xfailed / ...


@pytest.fixture(scope="session")
def petzval_bin() -> Path:
    """Path of the `petzval` binary (built once when missing)."""
    try:
        return petzval_cli.ensure_binary()
    except petzval_cli.PetzvalError as e:
        pytest.fail(f"cannot get the petzval binary: {e}", pytrace=False)


class DeviationLog:
    """Rows (test group, lens, quantity, measured value) for the end-of-run table."""

    def __init__(self, nodeid: str):
        self.nodeid = nodeid

    def add(self, group: str, lens: str, quantity: str, value) -> None:
        text = f"{value:.3e}" if isinstance(value, float) else str(value)
        _DEVIATIONS.append((self.nodeid, group, lens, quantity, text))


@pytest.fixture
def deviation_log(request) -> DeviationLog:
    return DeviationLog(request.node.nodeid)


def pytest_runtest_logreport(report):
    if report.when == "call" or (report.when == "setup" and report.outcome != "passed"):
        outcome = report.outcome
        if hasattr(report, "wasxfail"):
            outcome = "xpassed" if report.outcome == "passed" else "xfailed"
        _OUTCOMES[report.nodeid] = outcome


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Per (group, quantity): the largest deviation over all lenses and which lens it was (ray
    counts are summed); with -v, every row."""
    if not _DEVIATIONS:
        return
    tr = terminalreporter
    tr.section("optiland comparison: largest measured deviations (passing tests)")
    passed = [r[1:] for r in _DEVIATIONS if _OUTCOMES.get(r[0]) == "passed"]
    others = sorted({f"{r[0]} ({_OUTCOMES.get(r[0], '?')})" for r in _DEVIATIONS if _OUTCOMES.get(r[0]) != "passed"})
    agg: dict[tuple[str, str], list] = {}
    for group, lens, quantity, text in passed:
        key = (group, quantity)
        if "/" in text and all(p.strip().isdigit() for p in text.split("/")):
            nums = [int(p) for p in text.split("/")]
            cur = agg.get(key)
            agg[key] = ["sum", [a + b for a, b in zip(cur[1], nums, strict=False)] if cur else nums, ""]
            continue
        try:
            v = float(text)
        except ValueError:
            agg.setdefault(key, ["text", text, lens])
            continue
        cur = agg.get(key)
        if cur is None or (cur[0] == "max" and v > cur[1]):
            agg[key] = ["max", v, lens]
    rows = []
    for (group, quantity), (kind, val, lens) in agg.items():
        if kind == "max":
            rows.append((group, quantity, f"{val:.3e}", lens))
        elif kind == "sum":
            rows.append((group, quantity, "/".join(map(str, val)), "(sum over lenses)"))
        else:
            rows.append((group, quantity, val, lens))
    if rows:
        w = [max(len(r[i]) for r in rows) for i in range(3)]
        for group, quantity, val, lens in rows:
            tr.write_line(f"{group:<{w[0]}}  {quantity:<{w[1]}}  {val:>{w[2]}}  {lens}")
    if others:
        tr.write_line(f"not included: measurements of {len(others)} tests that did not pass:")
        for o in others:
            tr.write_line(f"  {o}")
    if config.option.verbose > 0:
        tr.section("optiland comparison: every measurement")
        w = [max(len(r[i]) for r in _DEVIATIONS) for i in range(1, 4)]
        for nodeid, group, lens, quantity, value in _DEVIATIONS:
            tr.write_line(
                f"{group:<{w[0]}}  {lens:<{w[1]}}  {quantity:<{w[2]}}  {value}  [{_OUTCOMES.get(nodeid, '?')}]"
            )
