"""Petzval: render scenes through real camera lenses.

The native module (Rust) does the work; this package re-exports it. See ``_native.pyi`` for
the API and its conventions.
"""

from ._native import (
    Camera,
    CancelledError,
    InvalidLensError,
    InvalidSceneError,
    InvalidSettingsError,
    Lens,
    PetzvalError,
    Scene,
    __version__,
    library_lenses,
    render,
)

__all__ = [
    "Camera",
    "CancelledError",
    "InvalidLensError",
    "InvalidSceneError",
    "InvalidSettingsError",
    "Lens",
    "PetzvalError",
    "Scene",
    "__version__",
    "library_lenses",
    "render",
]
