"""Fixtures for the Blender add-on suite (bpy 5.0.1 as a Python module, in this process).

- ``addon_zip``: the extension zip, from ``$PETZVAL_BLENDER_ADDON_ZIP`` or built now with
  ``blender_addon/build.py`` (maturin wheel + zip), once per session.
- ``addon``: the zip installed the way a user installs it
  (``bpy.ops.extensions.package_install_files`` into the "user_default" repository), with
  Blender's user directories pointed at ``tests/out/blender_addon/user`` (``BLENDER_USER_RESOURCES``)
  so nothing is written to the home directory. Yields the add-on's Python package
  (``bl_ext.user_default.petzval``). Reset Blender with :func:`addon_helpers.reset_blender`, which
  re-enables the add-on (a factory reset disables user add-ons).
- ``report``: result lines, written to ``tests/out/blender_addon/report.md`` and shown in the
  terminal summary.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from suite_report import SuiteReport

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
for p in (HERE, REPO / "tests" / "blender", REPO / "tests" / "optics"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

OUT = REPO / "tests" / "out" / "blender_addon"
ADDON_MODULE = "bl_ext.user_default.petzval"

_SUITE_REPORT = SuiteReport("Blender add-on (tests/blender_addon)", OUT)


@pytest.fixture(scope="session")
def report() -> SuiteReport:
    return _SUITE_REPORT


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    _SUITE_REPORT.terminal_summary(terminalreporter, config)


@pytest.fixture(scope="session")
def addon_zip() -> Path:
    given = os.environ.get("PETZVAL_BLENDER_ADDON_ZIP")
    if given:
        path = Path(given)
        if not path.is_file():
            pytest.fail(f"PETZVAL_BLENDER_ADDON_ZIP={given} does not exist", pytrace=False)
        return path
    cmd = [sys.executable, str(REPO / "blender_addon" / "build.py")]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=3600)
    if proc.returncode != 0:
        pytest.fail(f"`{' '.join(cmd)}` failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}", pytrace=False)
    path = Path(proc.stdout.strip().splitlines()[-1])
    if not path.is_file():
        pytest.fail(f"build.py printed {path}, which does not exist", pytrace=False)
    return path


def _use_the_extensions_wheel(user: Path):
    """Makes the add-on use the ``petzval`` module of the wheel it installed, and returns the
    add-on's package.

    Blender appends the extensions' wheel directory to the END of sys.path; in real Blender
    nothing else provides ``petzval``, but bpy-as-a-module shares this venv, where a ``petzval``
    (pip/maturin-installed for the Python-side tests) would shadow the wheel under test. So the
    wheel directory is moved to the front and the add-on is re-enabled with a fresh import."""
    import addon_utils

    site = (
        user / "extensions" / ".local" / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"
    )
    assert (site / "petzval").is_dir(), f"the extension's wheel was not installed into {site}"
    import petzval

    if Path(petzval.__file__).resolve().is_relative_to(site.resolve()):
        return importlib.import_module(ADDON_MODULE)
    addon_utils.disable(ADDON_MODULE, default_set=True)
    while str(site) in sys.path:
        sys.path.remove(str(site))
    sys.path.insert(0, str(site))
    for name in list(sys.modules):
        if (
            name == "petzval"
            or name.startswith("petzval.")
            or name == ADDON_MODULE
            or name.startswith(ADDON_MODULE + ".")
        ):
            del sys.modules[name]
    if addon_utils.enable(ADDON_MODULE, default_set=True) is None:
        pytest.fail(f"re-enabling {ADDON_MODULE} with the extension's own wheel failed", pytrace=False)
    import petzval as pz

    assert Path(pz.__file__).resolve().is_relative_to(site.resolve()), pz.__file__
    return importlib.import_module(ADDON_MODULE)


@pytest.fixture(scope="session")
def addon(addon_zip, report):
    import bpy  # test modules skip before this when bpy cannot be imported

    import addon_helpers as H

    # tests/conftest.py pointed BLENDER_USER_RESOURCES at a fresh directory before bpy was imported
    user = Path(bpy.utils.user_resource("EXTENSIONS")).parent
    env = os.environ.get("BLENDER_USER_RESOURCES")
    if not env or Path(env).resolve() != user.resolve():
        pytest.fail(f"Blender's user directory is {user}: set BLENDER_USER_RESOURCES before bpy is imported "
                    "(tests/conftest.py does) so the extension is not installed into the home directory", pytrace=False)
    try:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        with H.quiet(OUT / "blender.log"):
            result = bpy.ops.extensions.package_install_files(
                filepath=str(addon_zip), repo="user_default", enable_on_install=True
            )
        assert result == {"FINISHED"}, result
        enabled = [a.module for a in bpy.context.preferences.addons]
        assert ADDON_MODULE in enabled, f"{ADDON_MODULE} not enabled after installing {addon_zip.name}: {enabled}"
        module = _use_the_extensions_wheel(user)
        import petzval

        try:
            shown = user.relative_to(REPO)
        except ValueError:
            shown = user
        report.line(f"add-on {addon_zip.name} installed into {shown} (Blender {bpy.app.version_string}); "
                    f"native module {petzval.__file__}")
        yield module
    finally:
        try:
            import addon_utils

            addon_utils.disable(ADDON_MODULE, default_set=True)
        except Exception:
            pass
