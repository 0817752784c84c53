"""Thin wrapper around the `petzval` command-line tool, for the optics reference tests.

Every function runs the binary once and parses its JSON. The subcommands used (all in the
lens frame: millimetres, z from the first surface vertex, +z towards the film):

- ``petzval lens list``                              -> library names (first column)
- ``petzval lens info LENS --json [...]``            -> first-order data (dict)
- ``petzval lens export LENS --json [...]``          -> resolved prescription at one wavelength
- ``petzval lens trace LENS --direction D [...]``    -> one JSON line per input ray

The binary is located by :func:`binary_path`: ``$PETZVAL_BIN`` if set, else
``<repo>/target/release/petzval``, built with ``cargo build --release`` when missing
(:func:`ensure_binary`).
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
from collections.abc import Iterable, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_BIN = REPO / "target" / "release" / "petzval"


class PetzvalError(RuntimeError):
    """The tool exited non-zero or printed something that is not the expected JSON."""


def binary_path() -> Path:
    """Where the binary is expected: $PETZVAL_BIN, else target/release/petzval."""
    env = os.environ.get("PETZVAL_BIN")
    return Path(env) if env else DEFAULT_BIN


@functools.lru_cache(maxsize=1)
def ensure_binary() -> Path:
    """The binary's path, building it once with `cargo build --release` when it is missing.

    With $PETZVAL_BIN set nothing is built: the file must exist.
    """
    path = binary_path()
    if os.environ.get("PETZVAL_BIN"):
        if not path.is_file():
            raise PetzvalError(f"PETZVAL_BIN={path} does not exist")
        return path
    if not path.is_file():
        proc = subprocess.run(
            ["cargo", "build", "--release"],
            cwd=REPO,
            capture_output=True,
            text=True,
        )
        if proc.returncode != 0 or not path.is_file():
            tail = "\n".join(proc.stderr.splitlines()[-30:])
            raise PetzvalError(f"`cargo build --release` in {REPO} failed (exit {proc.returncode}):\n{tail}")
    return path


def run(args: Sequence[str], stdin: str | None = None, timeout: float = 600.0) -> str:
    """Runs `petzval ARGS...` and returns its standard output; raises PetzvalError on failure."""
    cmd = [str(ensure_binary()), *map(str, args)]
    proc = subprocess.run(cmd, input=stdin, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise PetzvalError(
            f"`{' '.join(cmd)}` exited {proc.returncode}\nstderr:\n{proc.stderr.strip()}\n"
            f"stdout (first 2000 chars):\n{proc.stdout[:2000]}"
        )
    return proc.stdout


def _json(args: Sequence[str]) -> dict:
    out = run(args)
    try:
        return json.loads(out)
    except json.JSONDecodeError as e:
        raise PetzvalError(f"`petzval {' '.join(map(str, args))}` did not print JSON ({e}):\n{out[:2000]}") from e


def _opts(fstop=None, focus=None, wavelength=None) -> list[str]:
    out: list[str] = []
    if fstop is not None:
        out += ["--fstop", repr(float(fstop))]
    if focus is not None:
        out += ["--focus", repr(float(focus))]
    if wavelength is not None:
        out += ["--wavelength", repr(float(wavelength))]
    return out


@functools.cache
def lens_list() -> tuple[str, ...]:
    """Library lens names (first whitespace-separated column of `petzval lens list`)."""
    names = []
    for line in run(["lens", "list"]).splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        names.append(line.split()[0])
    return tuple(names)


def lens_info(lens: str, fstop=None, focus=None, wavelength=None) -> dict:
    """`petzval lens info LENS --json`: first-order data."""
    return _json(["lens", "info", lens, "--json", *_opts(fstop, focus, wavelength)])


def lens_export(lens: str, fstop=None, wavelength=None) -> dict:
    """`petzval lens export LENS --json`: the resolved prescription at one wavelength."""
    return _json(["lens", "export", lens, "--json", *_opts(fstop, None, wavelength)])


def trace(
    lens: str,
    rays: Iterable[Sequence[float]],
    direction: str = "scene-to-film",
    wavelength=None,
    fstop=None,
    open_stop: bool = False,
) -> list[dict]:
    """`petzval lens trace`: one result dict per input ray ``[ox, oy, oz, dx, dy, dz]``.

    Results are ``{"ok": True, "origin": [...], "direction": [...]}`` or
    ``{"ok": False, "absorbed": "..."}``, in input order.
    """
    assert direction in ("scene-to-film", "film-to-scene"), direction
    rays = [list(map(float, r)) for r in rays]
    # repr() of a Python float round-trips exactly, so no precision is lost on the way in.
    stdin = "".join("[" + ", ".join(repr(v) for v in r) + "]\n" for r in rays)
    args = ["lens", "trace", lens, "--direction", direction, *_opts(fstop, None, wavelength)]
    if open_stop:
        args.append("--open-stop")
    out = run(args, stdin=stdin)
    lines = [ln for ln in out.splitlines() if ln.strip()]
    if len(lines) != len(rays):
        raise PetzvalError(f"`petzval {' '.join(args)}`: {len(rays)} rays in, {len(lines)} lines out:\n{out[:2000]}")
    results = []
    for ln in lines:
        try:
            results.append(json.loads(ln))
        except json.JSONDecodeError as e:
            raise PetzvalError(f"`petzval {' '.join(args)}` printed a non-JSON line ({e}): {ln!r}") from e
    return results
