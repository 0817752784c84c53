#!/usr/bin/env python3
"""Builds the Petzval Blender extension: one zip to install in Blender (4.2 or later).

    .venv/bin/python blender_addon/build.py

1. builds the native module's wheel with maturin (``maturin build --release -m
   blender_addon/Cargo.toml -o target/wheels``; abi3, Python 3.11+),
2. stages ``blender_addon/extension/`` with the wheel under ``wheels/`` and writes the
   manifest's ``version`` (the wheel's), ``wheels`` and ``platforms``,
3. zips it into ``target/blender/petzval-<version>.zip``,
4. validates the zip with Blender's own extension validator when the ``bpy`` module is
   installed in this Python (``tests/run`` installs it),

and prints the zip's path as the last line. Install it in Blender with Edit > Preferences >
Get Extensions > Install from Disk (or drag the zip into Blender), then pick "Petzval" as the
render engine.

Options: ``--wheel PATH`` packs an existing wheel instead of building one; ``--out DIR``
(default ``target/blender``); ``--wheels-dir DIR`` (default ``target/wheels``). Cargo's usual
``CARGO_TARGET_DIR`` applies to the maturin build.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
EXTENSION = HERE / "extension"
WHEELS = REPO / "target" / "wheels"

# Python wheel platform tag (suffix) -> Blender extension platform
PLATFORMS = (
    (re.compile(r"(many|musl)?linux.*_x86_64$"), "linux-x64"),
    (re.compile(r"(many|musl)?linux.*_aarch64$"), "linux-arm64"),
    (re.compile(r"macosx_.*_(arm64|universal2)$"), "macos-arm64"),
    (re.compile(r"macosx_.*_x86_64$"), "macos-x64"),
    (re.compile(r"win_amd64$"), "windows-x64"),
    (re.compile(r"win_arm64$"), "windows-arm64"),
)


class BuildError(Exception):
    pass


def find_maturin() -> list[str]:
    exe = Path(sys.executable).parent / "maturin"
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("maturin")
    if found:
        return [found]
    raise BuildError(
        "maturin is not installed: `.venv/bin/python -m pip install 'maturin>=1.7,<2'` (tests/run does it)"
    )


def build_wheel(wheels_dir: Path = WHEELS) -> Path:
    """Runs maturin; returns the wheel it built."""
    cmd = [*find_maturin(), "build", "--release", "-m", str(HERE / "Cargo.toml"), "-o", str(wheels_dir)]
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    proc = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    sys.stderr.write(proc.stdout)
    if proc.returncode != 0:
        raise BuildError(f"maturin failed (exit {proc.returncode})")
    built = re.findall(r"(\S+petzval-[^\s/]+\.whl)", proc.stdout)
    if built:
        return Path(built[-1])
    wheels = sorted(wheels_dir.glob("petzval-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        raise BuildError(f"maturin reported success but there is no petzval-*.whl in {wheels_dir}")
    return wheels[-1]


def wheel_version_platform(wheel: Path) -> tuple[str, str]:
    parts = wheel.name[: -len(".whl")].split("-")
    if len(parts) not in (5, 6) or parts[0] != "petzval":
        raise BuildError(f"{wheel.name} is not a petzval wheel name (petzval-VERSION-PY-ABI-PLATFORM.whl)")
    version, platform_tag = parts[1], parts[-1]
    if platform_tag == "any":
        return version, ""
    for tag in platform_tag.split("."):
        for pattern, blender in PLATFORMS:
            if pattern.search(tag):
                return version, blender
    raise BuildError(f"{wheel.name}: platform tag '{platform_tag}' has no Blender platform")


def blender_version(version: str) -> str:
    """Blender wants a semantic version X.Y.Z (a PEP 440 suffix like 'a1' or '.dev0' is kept as a
    pre-release label)."""
    m = re.match(r"^(\d+)(?:\.(\d+))?(?:\.(\d+))?(.*)$", version)
    if not m:
        raise BuildError(f"version '{version}' is not numeric")
    core = ".".join(x or "0" for x in m.group(1, 2, 3))
    rest = re.sub(r"[^0-9A-Za-z.]", "", m.group(4)).strip(".")
    return f"{core}-{rest}" if rest else core


def write_manifest(src: Path, dst: Path, version: str, wheel_rel: str, platform: str) -> None:
    text = src.read_text()
    subs = (
        (r'(?m)^version = ".*"$', f'version = "{version}"'),
        (r"(?m)^wheels = \[.*\]$", f'wheels = ["{wheel_rel}"]'),
    )
    if platform:  # a pure-Python wheel ("any") keeps the source manifest's platforms
        subs += ((r"(?m)^platforms = \[.*\]$", f'platforms = ["{platform}"]'),)
    for pattern, repl in subs:
        text, n = re.subn(pattern, repl, text)
        if n != 1:
            raise BuildError(f"{src}: expected one line matching {pattern!r}")
    dst.write_text(text)


def stage(wheel: Path, out_dir: Path) -> tuple[Path, str]:
    version, platform = wheel_version_platform(wheel)
    bversion = blender_version(version)
    staging = out_dir / "staging" / "petzval"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    for path in sorted(EXTENSION.rglob("*")):
        rel = path.relative_to(EXTENSION)
        if "__pycache__" in rel.parts or path.suffix in (".pyc", ".blend1") or path.name == "blender_manifest.toml":
            continue
        if path.is_dir():
            (staging / rel).mkdir(parents=True, exist_ok=True)
        else:
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, staging / rel)
    (staging / "wheels").mkdir(exist_ok=True)
    shutil.copy2(wheel, staging / "wheels" / wheel.name)
    write_manifest(
        EXTENSION / "blender_manifest.toml",
        staging / "blender_manifest.toml",
        bversion,
        f"./wheels/{wheel.name}",
        platform,
    )
    return staging, bversion


def pack(staging: Path, zip_path: Path) -> None:
    tmp = zip_path.with_suffix(".zip.tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for path in sorted(staging.rglob("*")):
            if path.is_file():
                z.write(path, path.relative_to(staging).as_posix())
    os.replace(tmp, zip_path)


def blender_validator() -> Path | None:
    """Blender's extension command line tool (blender_ext.py) from the installed bpy module."""
    try:
        import importlib.util

        spec = importlib.util.find_spec("bpy")
    except Exception:
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        for cand in Path(root).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"):
            return cand
    return None


def validate(zip_path: Path) -> str | None:
    """Runs Blender's validator on the zip; returns its output (None when unavailable)."""
    tool = blender_validator()
    if tool is None:
        return None
    proc = subprocess.run([sys.executable, str(tool), "validate", str(zip_path)], capture_output=True, text=True)
    out = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0 or "error" in out.lower():
        raise BuildError(f"Blender's extension validator rejected {zip_path}:\n{out}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--wheel", type=Path, help="pack this wheel instead of building one with maturin")
    ap.add_argument(
        "--out", type=Path, default=REPO / "target" / "blender", help="output directory (default target/blender)"
    )
    ap.add_argument(
        "--wheels-dir", type=Path, default=WHEELS, help="where maturin writes the wheel (default target/wheels)"
    )
    args = ap.parse_args(argv)
    try:
        wheel = args.wheel.resolve() if args.wheel else build_wheel(args.wheels_dir.resolve())
        if not wheel.is_file():
            raise BuildError(f"no wheel at {wheel}")
        args.out.mkdir(parents=True, exist_ok=True)
        staging, version = stage(wheel, args.out)
        zip_path = (args.out / f"petzval-{version}.zip").resolve()
        pack(staging, zip_path)
        checked = validate(zip_path)
        print(
            f"wheel {wheel.name}; "
            + (
                "validated by Blender's extension tool" if checked is not None else "not validated (no bpy module here)"
            ),
            file=sys.stderr,
        )
    except BuildError as e:
        print(f"build.py: error: {e}", file=sys.stderr)
        return 1
    print(zip_path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
