"""Fixtures shared by the USD suites."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def petzval() -> Path:
    env = os.environ.get("PETZVAL_BIN")
    p = Path(env) if env else REPO / "target" / "release" / "petzval"
    if not p.is_file():
        r = subprocess.run(["cargo", "build", "--release", "-p", "petzval"], cwd=REPO, capture_output=True, text=True)
        assert r.returncode == 0, r.stderr[-4000:]
    return p
