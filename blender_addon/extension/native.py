"""The native ``petzval`` module (installed from the extension's wheel), imported once.

Importing it can fail (a wheel for another platform, a broken install); the add-on still
registers so the failure is shown in the UI and reported by the render instead of breaking
Blender's add-on loading.
"""

from __future__ import annotations

import zlib

_module = None
_error: str | None = None
_library: list[dict] | None = None


def get():
    """The ``petzval`` module; raises ImportError with the original reason when unavailable."""
    global _module, _error
    if _module is None and _error is None:
        try:
            import petzval  # the wheel listed in blender_manifest.toml

            _module = petzval
        except Exception as e:  # ImportError, or the native library failing to load
            _error = f"{type(e).__name__}: {e}"
    if _module is None:
        raise ImportError(f"the native petzval module could not be imported ({_error})")
    return _module


def import_error() -> str | None:
    try:
        get()
    except ImportError:
        return _error
    return None


def library_lenses() -> list[dict]:
    """``petzval.library_lenses()``, read once (empty when the module cannot be imported)."""
    global _library
    if _library is None:
        try:
            _library = list(get().library_lenses())
        except Exception:
            _library = []
    return _library


def library_lens(name: str) -> dict | None:
    for entry in library_lenses():
        if entry.get("name") == name:
            return entry
    return None


def stable_enum_number(identifier: str, taken: set[int]) -> int:
    """A number for an enum item that does not depend on the library's order, so a .blend saved
    with one version of the add-on opens with the same lens in another (Blender stores enum
    values as numbers)."""
    n = zlib.crc32(identifier.encode()) & 0x3FFFFFFF
    while n in taken or n < 16:
        n = (n + 7919) & 0x3FFFFFFF
    taken.add(n)
    return n
