"""Shared fixtures for the optics reference tests.

- ``petzval_bin``: the `petzval` binary, located once per session ($PETZVAL_BIN if set, else
  target/release/petzval, built with `cargo build --release` in the repo when missing).
- ``deviation_log``: a session-wide table of measured maximum deviations; the optiland tests
  add rows to it and the table is printed at the end of the run (pytest's terminal summary),
  so a passing run still shows how close the two implementations came.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import petzval_cli  # noqa: E402

_DEVIATIONS: list[tuple[str, str, str, str]] = []


@pytest.fixture(scope="session")
def petzval_bin() -> Path:
    """Path of the `petzval` binary (built once when missing)."""
    try:
        return petzval_cli.ensure_binary()
    except petzval_cli.PetzvalError as e:
        pytest.fail(f"cannot get the petzval binary: {e}", pytrace=False)


class DeviationLog:
    """Rows (test group, lens, quantity, measured value) for the end-of-run table."""

    def add(self, group: str, lens: str, quantity: str, value) -> None:
        if isinstance(value, float):
            text = f"{value:.3e}"
        else:
            text = str(value)
        _DEVIATIONS.append((group, lens, quantity, text))


@pytest.fixture(scope="session")
def deviation_log() -> DeviationLog:
    return DeviationLog()


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _DEVIATIONS:
        return
    tr = terminalreporter
    tr.section("optiland comparison: measured deviations")
    w = [max(len(r[i]) for r in _DEVIATIONS) for i in range(3)]
    for group, lens, quantity, value in _DEVIATIONS:
        tr.write_line(f"{group:<{w[0]}}  {lens:<{w[1]}}  {quantity:<{w[2]}}  {value}")
