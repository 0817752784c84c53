"""Petzval's settings: ``Camera.petzval`` (the lens, its model and the sensor tilt) and
``Scene.petzval`` (render settings)."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import native

# Enum identifiers of the lens choices that are not library lenses.
LENS_THIN = "THIN"
LENS_PINHOLE = "PINHOLE"
LENS_FILE = "FILE"

# Blender 5 wants path properties that accept "//" (relative to the .blend) to say so
PATH_OPTIONS = {"PATH_SUPPORTS_BLEND_RELATIVE"} if bpy.app.version >= (5, 0, 0) else set()

# Identifiers, lowercased, are the one name of each model everywhere (`--lens-model`, petzval.Camera
# lens_model, the EXR `lensModel` metadata, Rust `LensModel`/`Camera` variants).
LENS_MODELS = (
    ("AUTO", "Automatic", "The cheapest model within the tolerance (pinhole, thin, thick, lens table, exact)", 0),
    ("EXACT", "Exact", "Trace every ray through every surface of the lens", 1),
    ("LRTF", "LRTF", "A precomputed lens ray transfer table (LRTF, a lens table), exact near vignetting boundaries", 2),
    ("THICK", "Thick Lens", "The lens's thick-lens approximation (focal length, principal planes, pupils)", 3),
    ("THIN", "Thin Lens", "The lens's thin-lens approximation", 4),
    ("PINHOLE", "Pinhole", "No lens: everything in focus", 5),
)


def _lens_items() -> list[tuple]:
    """Enum items for the lens: Blender's camera, pinhole, every library lens, a file. Numbers are
    stable across library versions (see native.stable_enum_number)."""
    items = [
        (
            LENS_THIN,
            "Thin Lens (Blender Camera)",
            "Blender's own camera model: focal length, f-stop and focus from the camera settings",
            0,
        ),
        (LENS_PINHOLE, "Pinhole", "An ideal pinhole: no depth of field", 1),
    ]
    taken = {0, 1, 2}
    for entry in native.library_lenses():
        name = entry["name"]
        desc = (
            f"{entry.get('description') or name}: f = {entry.get('focal_length_mm', 0):.1f} mm, "
            f"f/{entry.get('f_number', 0):.2f}. {entry.get('source', '')}"
        )
        items.append((name, name, desc, native.stable_enum_number(name, taken)))
    items.append((LENS_FILE, "Lens File…", "A lens file: our .toml, pbrt .dat, Zemax .zmx or lentil .json#ID", 2))
    return items


class PetzvalCameraSettings(bpy.types.PropertyGroup):
    # `lens` is added in register() once the library list is known (a static item list keeps
    # Blender's enum strings alive; dynamic item callbacks are fragile).
    lens_file: StringProperty(
        name="Lens File",
        description="Lens prescription: Petzval .toml, pbrt .dat, Zemax .zmx, or lentil FILE.json#ID",
        subtype="FILE_PATH",
        options=PATH_OPTIONS,
    )
    lens_model: EnumProperty(name="Lens Model", items=LENS_MODELS, default="AUTO",
                             description="How rays are traced through a real lens")
    tolerance_px: FloatProperty(
        name="Tolerance",
        description="Largest image error (pixels) the automatic model choice accepts",
        default=0.25, min=0.001, soft_max=5.0, precision=3,
    )
    tilt_x: FloatProperty(
        name="Tilt X",
        description="Sensor tilt about the horizontal axis (Scheimpflug): positive tilts the plane of "
                    "focus towards the ground",
        subtype="ANGLE",
        default=0.0,
        min=-0.6,
        max=0.6,
        precision=2,
        step=10,
    )
    tilt_y: FloatProperty(
        name="Tilt Y",
        description="Sensor tilt about the vertical axis: positive moves the image's right side away from the lens",
        subtype="ANGLE", default=0.0, min=-0.6, max=0.6, precision=2, step=10,
    )
    aperture_image: StringProperty(
        name="Aperture Image",
        description="A mask image (PNG or EXR) for the shape of the aperture stop; empty uses Blender's blades",
        subtype="FILE_PATH",
        options=PATH_OPTIONS,
    )


# The depth-of-field methods of the viewport preview: the identifiers, lower-cased, are
# `petzval render --method` values (docs/dof-methods.md measures them against each other).
VIEWPORT_METHODS = [
    ("MC", "Monte Carlo", "Trace every lens ray through the scene (exact; noisy while it converges)", 0),
    ("IBRT", "Layered Ray Tracing",
     "Shade the view once into depth-peeled layers, then trace the lens rays against them (smooth blur "
     "sooner; misses what the layers do not hold)", 1),
    ("SPREAD", "PSF Spreading", "Spread each layer texel's lens blur onto the image", 2),
    ("MULTIVIEW", "Multi-View", "Accumulate pinhole views through points of the pupil", 3),
]


class PetzvalRenderSettings(bpy.types.PropertyGroup):
    samples: IntProperty(name="Samples", description="Samples per pixel", default=64, min=1, soft_max=4096)
    use_adaptive_sampling: BoolProperty(
        name="Noise Threshold",
        description="Adaptive sampling, as Cycles': pixels stop taking samples once their noise is below the "
        "threshold (Samples becomes the most a pixel takes); final renders only",
        default=False,
    )
    adaptive_threshold: FloatProperty(
        name="Noise Threshold",
        description="Cycles' noise threshold (the same test and scale): lower is cleaner and slower",
        default=0.01, min=0.0, max=1.0, soft_min=0.001, precision=4,
    )
    adaptive_min_samples: IntProperty(
        name="Min Samples",
        description="Samples every pixel takes before it may stop (0: automatic, as Cycles)",
        default=0, min=0, soft_max=4096,
    )
    viewport_samples: IntProperty(
        name="Viewport Samples",
        description="Samples per pixel of the viewport's Rendered shading",
        default=16,
        min=1,
        soft_max=1024,
    )
    viewport_method: EnumProperty(
        name="Viewport Depth of Field",
        description="How the viewport's Rendered shading makes depth of field (final renders always trace "
        "every lens ray)",
        items=VIEWPORT_METHODS,
        default="MC",
    )
    viewport_divisor: IntProperty(
        name="Viewport Resolution Divisor",
        description="The viewport preview renders at the viewport's size divided by this",
        default=4, min=1, max=16,
    )
    seed: IntProperty(name="Seed", description="Seed of the sample pattern", default=0, min=0)
    use_animated_seed: BoolProperty(
        name="Animated Seed",
        description="Add the frame number to the seed so the noise changes per frame",
        default=False,
    )
    max_bounces: IntProperty(
        name="Max Bounces",
        description="Bounces after the first hit, as Cycles' Max Bounces (Petzval's depth is this + 1)",
        default=8, min=0, max=1024,
    )
    filter_width: FloatProperty(
        name="Filter Width",
        description="Pixel filter width (Blackman-Harris), as Cycles' filter width",
        default=1.5, min=0.01, max=10.0, subtype="PIXEL",
    )
    natural_vignetting: BoolProperty(
        name="Natural Vignetting",
        description="Include the cos^4 falloff for the thin lens and pinhole (Cycles has none; "
                    "real lenses always have their own)",
        default=False,
    )
    spectral: BoolProperty(
        name="Spectral",
        description="Trace one wavelength per camera ray through lenses with dispersive glass "
                    "(lateral and axial colour)",
        default=False,
    )


_classes = (PetzvalCameraSettings, PetzvalRenderSettings)


def register() -> None:
    PetzvalCameraSettings.__annotations__["lens"] = EnumProperty(
        name="Lens",
        description="The lens the camera renders through",
        items=_lens_items(),
        default=LENS_THIN,
    )
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.Camera.petzval = PointerProperty(type=PetzvalCameraSettings, name="Petzval")
    bpy.types.Scene.petzval = PointerProperty(type=PetzvalRenderSettings, name="Petzval")


def unregister() -> None:
    del bpy.types.Scene.petzval
    del bpy.types.Camera.petzval
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
