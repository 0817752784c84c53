"""Panels: Petzval's lens and tilt (Properties > Camera), sampling (Properties > Render), passes
(Properties > View Layer); and Blender's own panels made visible for the PETZVAL engine."""

from __future__ import annotations

import math

import bpy

from . import native, properties

ENGINE = "PETZVAL"

# Built-in panels shown for our engine besides every panel that lists 'BLENDER_RENDER' (the
# set Blender keeps for external engines): depth of field, the light settings (type, colour,
# power, size), spot shape, material slots and surface, world surface.
EXTRA_PANELS = (
    "DATA_PT_camera_dof",
    "DATA_PT_camera_dof_aperture",
    "DATA_PT_EEVEE_light",
    "DATA_PT_spot",
    "EEVEE_MATERIAL_PT_context_material",
    "EEVEE_MATERIAL_PT_surface",
    "EEVEE_WORLD_PT_surface",
)
# 'BLENDER_RENDER' panels not shown: the bare light panel (DATA_PT_EEVEE_light draws the same and more).
SKIP_PANELS = {"DATA_PT_light"}

_patched: list[type] = []


def compat_panels() -> list[type]:
    """Built-in panels that should list our engine in COMPAT_ENGINES."""
    out = []
    for name in dir(bpy.types):
        cls = getattr(bpy.types, name, None)
        if not isinstance(cls, type) or not issubclass(cls, bpy.types.Panel):
            continue
        engines = getattr(cls, "COMPAT_ENGINES", None)
        if not isinstance(engines, set):
            continue
        if name in EXTRA_PANELS or ("BLENDER_RENDER" in engines and name not in SKIP_PANELS):
            out.append(cls)
    return out


class PetzvalPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


def _native_problem(layout) -> bool:
    err = native.import_error()
    if err:
        box = layout.box()
        box.alert = True
        box.label(text="The native petzval module is not available", icon="ERROR")
        box.label(text=err[:120])
    return bool(err)


class CameraPanel(PetzvalPanel):
    """A panel in Properties › Camera (object data) for our engine."""

    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.camera is not None and super().poll(context)


class PETZVAL_PT_camera_lens(CameraPanel, bpy.types.Panel):
    bl_label = "Petzval Lens"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        cam = context.camera
        p = cam.petzval
        _native_problem(layout)
        col = layout.column()
        col.prop(p, "lens")
        if p.lens == properties.LENS_FILE:
            col.prop(p, "lens_file")
        entry = native.library_lens(p.lens)
        if entry is not None:
            sub = col.column(align=True)
            sub.label(
                text=f"f = {entry.get('focal_length_mm', 0):.1f} mm, widest f/{entry.get('f_number', 0):.2f}",
                icon="INFO",
            )
        if p.lens not in (properties.LENS_THIN, properties.LENS_PINHOLE):
            col.label(text="The lens brings its own focal length; F-Stop stops it down", icon="INFO")
            if not cam.dof.use_dof:
                col.label(text="Depth of field off: wide open, focused at the focus distance", icon="INFO")
            col.prop(p, "lens_model")
            if p.lens_model == "AUTO":
                col.prop(p, "tolerance_px", text="Tolerance (px)")
        col.prop(p, "aperture_image")
        if cam.type == "PANO":
            layout.label(text="Petzval renders perspective and orthographic cameras", icon="ERROR")
        elif cam.type == "ORTHO":
            layout.label(text="Orthographic: no lens; F-Stop gives an aperture of 1/(2N) m", icon="INFO")


class PETZVAL_PT_camera_tilt(CameraPanel, bpy.types.Panel):
    bl_label = "Tilt (Scheimpflug)"
    bl_parent_id = "PETZVAL_PT_camera_lens"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        p = context.camera.petzval
        col = layout.column(align=True)
        col.prop(p, "tilt_x")
        col.prop(p, "tilt_y")
        if p.tilt_x or p.tilt_y:
            t = math.hypot(p.tilt_x, p.tilt_y)
            layout.label(text="Shift moves the frame; tilt turns the plane of focus about the hinge line")
            entry = native.library_lens(p.lens)
            f_mm = entry["focal_length_mm"] if entry else context.camera.lens
            layout.label(text=f"Hinge line {f_mm / 1000 / math.sin(t):.2f} m from the lens (f / sin tilt)")


class PETZVAL_PT_sampling(PetzvalPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_context = "render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.petzval
        _native_problem(layout)
        col = layout.column()
        row = col.row(heading="Noise Threshold", align=True)
        row.prop(s, "use_adaptive_sampling", text="")
        sub = row.row()
        sub.active = s.use_adaptive_sampling
        sub.prop(s, "adaptive_threshold", text="")
        col.prop(s, "samples", text="Max Samples" if s.use_adaptive_sampling else "Samples")
        sub = col.column()
        sub.active = s.use_adaptive_sampling
        sub.prop(s, "adaptive_min_samples")
        row = col.row(align=True)
        row.prop(s, "seed")
        row.prop(s, "use_animated_seed", text="", icon="TIME")
        col.prop(s, "max_bounces")
        col.prop(s, "filter_width")
        col.prop(s, "natural_vignetting")
        col.prop(s, "spectral")
        col = layout.column(heading="Viewport")
        col.prop(s, "viewport_samples", text="Samples")
        col.prop(s, "viewport_method", text="Depth of Field")
        col.prop(s, "viewport_divisor", text="Resolution Divisor")


class PETZVAL_PT_passes(PetzvalPanel, bpy.types.Panel):
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        vl = context.view_layer
        col = layout.column(heading="Include")
        col.prop(vl, "use_pass_combined")
        col.prop(vl, "use_pass_z")


classes = (PETZVAL_PT_camera_lens, PETZVAL_PT_camera_tilt, PETZVAL_PT_sampling, PETZVAL_PT_passes)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    for cls in compat_panels():
        if ENGINE not in cls.COMPAT_ENGINES:
            cls.COMPAT_ENGINES.add(ENGINE)
            _patched.append(cls)


def unregister() -> None:
    for cls in _patched:
        cls.COMPAT_ENGINES.discard(ENGINE)
    _patched.clear()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
