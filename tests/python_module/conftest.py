"""The `petzval` Python package (native module) used directly, without Blender.

A session fixture builds the wheel with maturin (``blender_addon/build.py``'s ``build_wheel``;
a no-op when it is up to date), unpacks it under tests/out/python_module and imports it from
there, so the suite tests this checkout's module whatever else is installed in the venv.
"""

from __future__ import annotations

import importlib
import shutil
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "optics"))
OUT = REPO / "tests" / "out" / "python_module"


@pytest.fixture(scope="session")
def petzval():
    sys.path.insert(0, str(REPO / "blender_addon"))
    try:
        import build  # blender_addon/build.py
    finally:
        sys.path.pop(0)
    wheel = build.build_wheel()
    target = OUT / "site"
    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    with zipfile.ZipFile(wheel) as z:
        z.extractall(target)
    for name in [m for m in sys.modules if m == "petzval" or m.startswith("petzval.")]:
        del sys.modules[name]
    sys.path.insert(0, str(target))
    module = importlib.import_module("petzval")
    assert Path(module.__file__).resolve().is_relative_to(target), module.__file__
    return module
