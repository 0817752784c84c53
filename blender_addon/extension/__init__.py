"""Petzval for Blender: a render engine that renders the scene through real camera lenses
(exact ray tracing through lens prescriptions), with depth of field, bokeh and tilt-shift.

Pick "Petzval" as the render engine; the lens and sensor tilt are in Properties > Camera >
Petzval Lens, sampling in Properties > Render. The native renderer is the ``petzval`` Python
module, installed from the wheel bundled with this extension.
"""

from __future__ import annotations

if "bpy" in locals():  # script reload (F8 / Reload Scripts)
    import importlib

    # the export package's modules before the package itself, which imports from them
    for _m in (notes, native, properties, camera, export.nodes, export.images, export.materials,  # noqa: F821
               export.mesh, export.lights, export.world, export, engine, ui):  # noqa: F821
        importlib.reload(_m)

import bpy

# in dependency order, as the reload list above
from . import notes, native, properties, camera, export, engine, ui  # noqa: F401  # isort: skip


def register() -> None:
    native.library_lenses()  # read the lens library once (empty if the native module is missing)
    properties.register()
    for cls in engine.classes:
        bpy.utils.register_class(cls)
    ui.register()


def unregister() -> None:
    ui.unregister()
    for cls in reversed(engine.classes):
        bpy.utils.unregister_class(cls)
    properties.unregister()
