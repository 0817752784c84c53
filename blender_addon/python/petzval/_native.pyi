"""Petzval's native module (Rust, pyo3). Import it through the ``petzval`` package.

Conventions
-----------
* World space is glTF's: metres, +y up, right-handed. Blender's world (+z up) maps to it by
  ``(x, y, z) -> (x, z, -y)``; the caller converts (the add-on does).
* Cameras look down their local -z with +y up (Blender's and glTF's camera convention).
* Colours are linear Rec.709. Light units are Blender's: watts for point/spot power is turned
  into radiant intensity by the caller (``intensity_w_sr = power_w / (4 pi)``), W/m^2 for sun.
* Textures and images: row 0 is the TOP row; UVs use glTF's convention (v = 0 at the top), so
  Blender UVs are passed as ``(u, 1 - v)`` and Blender image pixels (bottom row first) are
  flipped vertically.
* Every array argument may be any numeric dtype and is copied; C-contiguous float32/float64
  arrays avoid a conversion.
* Errors: a missing file raises ``FileNotFoundError``; everything else raises a subclass of
  :class:`PetzvalError`. No Rust panic crosses into Python (an internal error raises
  ``PetzvalError`` with the message).
"""

from collections.abc import Callable, Sequence
from typing import final

import numpy as np
from numpy.typing import NDArray

__version__: str

class PetzvalError(Exception):
    """Base class of every Petzval error."""

class InvalidLensError(PetzvalError):
    """A lens file or lens name is invalid (message names the file, line and field)."""

class InvalidSceneError(PetzvalError):
    """Scene data is invalid (message names the object/field)."""

class InvalidSettingsError(PetzvalError):
    """Camera or render settings are invalid (message names the field)."""

class CancelledError(PetzvalError):
    """The progress callback asked to stop (raised only when no pass completed)."""

def library_lenses() -> list[dict]:
    """The built-in lens library: ``[{"name", "description", "focal_length_mm", "f_number",
    "source"}]`` sorted by name."""

@final
class Lens:
    """A lens: a library name (``"double-gauss-50mm"``) or a path to a lens file
    (``.toml``, pbrt ``.dat``, Zemax ``.zmx``, lentil ``.json``)."""

    def __new__(cls, name_or_path: str) -> Lens: ...
    @property
    def name(self) -> str: ...
    @property
    def focal_length_mm(self) -> float: ...
    @property
    def f_number(self) -> float: ...
    def info(self) -> dict:
        """Paraxial and physical data, the same keys as ``petzval lens info --json``."""
    def trace(
        self,
        origins: NDArray[np.float64],
        directions: NDArray[np.float64],
        wavelength_nm: float = 587.5618,
        direction: str = "film_to_scene",
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Traces N rays (``(N, 3)`` arrays, lens coordinates in mm as ``petzval lens trace``)
        through every surface. ``direction`` is ``"film_to_scene"`` or ``"scene_to_film"``.
        Returns (origins, unit directions, passed); rows that did not pass are NaN."""

@final
class Scene:
    """A scene assembled from buffers. Build it, then pass it to :func:`render`."""

    def __init__(self) -> None: ...
    def add_texture(
        self,
        pixels: NDArray[np.float32],
        name: str = "",
        interpolation: str = "linear",
        extension: str = "repeat",
        srgb_encoded: bool = False,
    ) -> int:
        """Adds a texture from ``(H, W, 4)`` (or ``(H, W, 3)``) LINEAR values, row 0 at the
        top. ``interpolation``: ``"linear"`` or ``"closest"``; ``extension``: ``"repeat"``,
        ``"clip"`` (clamp to edge) or ``"mirror"``. With ``srgb_encoded`` the RGB values are
        sRGB-encoded (an 8-bit sRGB image), filtered and then decoded, as Cycles does with byte
        images. Returns its index."""
    def add_material(
        self,
        name: str,
        base_color: Sequence[float] = (0.8, 0.8, 0.8, 1.0),
        metallic: float = 0.0,
        roughness: float = 0.5,
        ior: float = 1.5,
        specular: float = 1.0,
        emission: Sequence[float] = (0.0, 0.0, 0.0),
        alpha_mode: str = "opaque",
        alpha_cutoff: float = 0.5,
        base_color_texture: int | None = None,
        metallic_roughness_texture: int | None = None,
        normal_texture: int | None = None,
        normal_scale: float = 1.0,
        emission_texture: int | None = None,
        double_sided: bool = True,
        light_emitter: bool = False,
        visible_to_camera: bool = True,
        transmission: float = 0.0,
        coat_weight: float = 0.0,
        coat_roughness: float = 0.03,
        coat_ior: float = 1.5,
        coat_tint: Sequence[float] = (1.0, 1.0, 1.0),
        scatter_tint: Sequence[float] = (1.0, 1.0, 1.0),
        metal_fresnel: str = "f82",
        edge_tint: Sequence[float] = (1.0, 1.0, 1.0),
        translucent: bool = False,
        mix_material: int | None = None,
        mix_weight: float = 0.0,
        mix_weight_texture: int | None = None,
        mix_weight_angle: tuple[str, float] | None = None,
        uv_transforms: dict[str, Sequence[Sequence[float]]] | None = None,
        specular_tint: Sequence[float] = (1.0, 1.0, 1.0),
    ) -> int:
        """Adds a glTF metallic-roughness material and returns its index.

        ``specular`` is glTF's specularFactor (1 = F0 0.04 at ior 1.5; Blender's Specular IOR
        Level 0.5 is 1, level 0 is 0). ``emission`` is emitted radiance (Blender: emission
        colour x strength). ``alpha_mode``: ``"opaque"``, ``"blend"`` (stochastic) or
        ``"mask"`` (cut at ``alpha_cutoff``); alpha is ``base_color[3]`` x texture alpha.
        ``metallic_roughness_texture`` reads roughness from G and metallic from B (glTF).
        ``light_emitter`` marks a light's emitting surface (an area light, as Cycles' lights):
        it casts no shadow and is seen only from its front. ``visible_to_camera`` False hides
        the surface from camera rays (Blender's Ray Visibility > Camera, off for lights in
        Blender 5): they go on through it, while reflections, bounces and shadows still see it.
        ``transmission`` (Blender's Transmission Weight, glTF's transmissionFactor) makes that
        share of the dielectric part glass, refracting by ``ior`` and tinted by the base colour.
        ``coat_weight``, ``coat_roughness``, ``coat_ior`` and ``coat_tint`` are the Principled
        BSDF's Coat: a glossy layer over everything else, which dims what lies under it by its
        reflectance and tints it by ``coat_tint`` (linear RGB, head-on) along the refracted
        view ray, as Cycles does. ``scatter_tint`` (linear RGB) multiplies everything the
        surface scatters, every lobe, reflected and refracted, but not its emission: the colour
        of Blender's Glass and Refraction BSDFs. ``metal_fresnel`` is the metallic part's
        Fresnel reflectance: ``"f82"`` (Schlick's from the base colour, less Cycles' F82 term
        that makes it ``edge_tint`` (linear RGB in [0, 1]) times Schlick's near 82°: the
        Specular Tint of a metallic Principled BSDF, the Metallic BSDF's Edge Tint) or
        ``"constant"`` (the base colour at every angle: the Glossy BSDF). ``translucent`` makes
        the surface scatter through itself instead of back (every direction mirrored to the far
        side: with roughness 1 and specular 0, Blender's Translucent BSDF). ``mix_material`` and
        ``mix_weight`` are a Mix Shader: with probability ``mix_weight`` (in [0, 1]) a
        scattering event uses material ``mix_material`` (added before this one, and it may mix
        further) instead of this one, an unbiased estimate of the weighted sum of the two BSDFs;
        emission, alpha and the normal map stay this material's. ``mix_weight_texture`` masks
        the weight: where the surface is hit, the probability is ``mix_weight`` times the
        texture's red channel (clamped to [0, 1]; a Mix Shader factor from an image).
        ``mix_weight_angle`` multiplies it by a factor of the viewing angle, as Cycles' nodes
        compute it: ``("fresnel", ior)`` (the Fresnel node), ``("layer_fresnel", blend)`` or
        ``("layer_facing", blend)`` (the Layer Weight node's outputs). ``uv_transforms`` maps a
        texture field (``"base_color_texture"``, ``"metallic_roughness_texture"``,
        ``"normal_texture"``, ``"emission_texture"``, ``"mix_weight_texture"``) to a 2 x 3
        affine map of the texture coordinates, rows ``[[a, b, c], [d, e, f]]``: the lookup is at
        ``(a u + b v + c, d u + e v + f)``, in the coordinates ``add_mesh`` takes (v down;
        Blender's Mapping node, with v flipped). ``specular_tint`` (linear RGB, non-negative) is
        the Principled BSDF's Specular Tint on its dielectric part, as Cycles renders it: the
        specular layer reflects F0 x tint head-on and still 1 at grazing, and the base under
        it is dimmed by the layer's brightest channel. Texture indices come from
        :meth:`add_texture`."""
    def material_variant(self, material: int, visible_to_camera: bool = True, terminator_offset: float = 0.1) -> int:
        """Adds a copy of material ``material`` with an object's settings and returns its index:
        ``visible_to_camera`` (its Ray Visibility > Camera) and ``terminator_offset`` (its
        Shadow Terminator > Geometry Offset, Blender's default 0.1: near the terminator of a
        smooth-shaded mesh, shadow rays leave from the smooth surface its normals describe; 0
        leaves them on the flat triangles). An index out of range or an offset outside [0, 1]
        raises InvalidSceneError."""
    def add_mesh(
        self,
        positions: NDArray[np.float32],
        triangles: NDArray[np.uint32],
        material_ids: NDArray[np.uint32] | None = None,
        normals: NDArray[np.float32] | None = None,
        uvs: NDArray[np.float32] | None = None,
        tangents: NDArray[np.float32] | None = None,
        transform: NDArray[np.float64] | None = None,
        name: str = "",
        colors: NDArray[np.float32] | None = None,
    ) -> int:
        """Adds a triangle mesh, stored once in object space, placed once by ``transform``;
        returns its mesh id for :meth:`add_instance` / :meth:`add_instances`.
        ``positions (N, 3)``, ``triangles (M, 3)`` vertex indices,
        ``material_ids (M,)`` indices into the scene's materials (default: all 0; a scene
        without materials gets a grey default), optional per-vertex ``normals (N, 3)``
        (computed from faces when absent), ``uvs (N, 2)`` (glTF convention), ``tangents
        (N, 4)`` (xyz + handedness w), and ``transform`` a ``(4, 4)`` object-to-world matrix
        (column vectors, i.e. Blender's ``matrix_world`` layout, already in glTF axes), and
        optional ``colors (N, 3)`` or ``(N, 4)``: linear RGB(A) vertex colours multiplying the
        base colour and alpha of the triangles' materials (glTF's ``COLOR_0``; negative values
        read as 0).
        Indices out of range, non-finite values or a singular transform raise
        InvalidSceneError naming ``name``."""
    def add_curves(
        self,
        positions: NDArray[np.float64],
        radii: NDArray[np.float64],
        counts: NDArray[np.int64],
        curve_types: NDArray[np.int64] | None = None,
        material_ids: NDArray[np.int64] | None = None,
        transform: NDArray[np.float64] | None = None,
        name: str = "",
    ) -> int | None:
        """Adds curves (a Blender Curves object: hair) as round tubes of triangles, as Cycles
        renders them (8 sides, 4 rings per cubic span, smooth normals, mitred joints, open ends),
        one mesh placed by ``transform`` as in :meth:`add_mesh`; returns its mesh id, or None
        when no curve makes a tube. ``positions (N, 3)`` control points (object space),
        ``radii (N,)`` tube radius per point (evaluated with the curve's basis), ``counts (C,)``
        points per curve, ``curve_types (C,)`` Blender's ``curve_type``: 1 (poly) straight
        spans; 0 (Catmull-Rom, the default), 2 (Bézier) and 3 (NURBS) a Catmull-Rom curve
        through the points pinned to its end points (Cycles ignores handles, weights and
        knots), ``material_ids (C,)`` per curve (default 0). A curve with too few points (one)
        is skipped with a warning; bad shapes, negative or non-finite values, counts not adding
        up to N, an unknown type or material raise InvalidSceneError naming ``name``."""
    def add_instance(self, mesh_id: int, transform: NDArray[np.float64], name: str = "") -> None:
        """Places mesh ``mesh_id`` (from :meth:`add_mesh`) once more with a ``(4, 4)``
        object-to-world matrix (as ``add_mesh``'s ``transform``); the mesh data is not copied.
        An unknown id or a singular, non-finite or projective matrix raises InvalidSceneError."""
    def add_instances(self, mesh_id: int, transforms: NDArray[np.float64], name: str = "") -> int:
        """Places mesh ``mesh_id`` once per matrix of a ``(N, 4, 4)`` array (scatters, particle
        and point instancers); returns N. All are validated before any is added."""
    @property
    def mesh_count(self) -> int:
        """Meshes added (each stored once)."""
    @property
    def instance_count(self) -> int:
        """Placements of meshes (``add_mesh`` counts one)."""
    def add_point_light(
        self,
        position: Sequence[float],
        intensity_w_sr: Sequence[float],
        name: str = "",
        radius_m: float = 0.0,
        sphere: bool = False,
    ) -> None:
        """A point light: radiant intensity per RGB channel in W/sr; ``radius_m`` > 0 (Blender's
        Radius) emits from a disc of that radius facing each shading point, as Cycles' Soft
        Falloff does (soft shadows), or from a sphere with ``sphere`` (Soft Falloff off)."""
    def add_spot_light(
        self,
        position: Sequence[float],
        direction: Sequence[float],
        intensity_w_sr: Sequence[float],
        inner_cone_rad: float,
        outer_cone_rad: float,
        name: str = "",
        falloff: str = "gltf",
        radius_m: float = 0.0,
        sphere: bool = False,
    ) -> None:
        """A spot light pointing along ``direction``; full intensity inside the inner cone
        half-angle, zero outside the outer. In between ``falloff`` "gltf" ramps as glTF does,
        "blender" as Cycles' Spot Blend does (blend = 1 - inner/outer). ``radius_m`` and
        ``sphere`` as the point light's."""
    def add_sun_light(
        self, direction: Sequence[float], irradiance_w_m2: Sequence[float], name: str = "", angle_rad: float = 0.0
    ) -> None:
        """A directional light travelling along ``direction``; ``angle_rad`` > 0 (Blender's
        Angle, the disc's angular diameter) spreads its directions over that cone (soft shadows)
        with the same irradiance."""
    def set_environment_color(self, rgb: Sequence[float]) -> None:
        """A uniform environment radiance."""
    def set_environment_map(
        self, pixels: NDArray[np.float32], strength: float = 1.0, rotation_rad: float = 0.0, name: str = ""
    ) -> None:
        """An equirectangular environment ``(H, W, 3|4)``, row 0 at the top, mapped as
        Blender's Environment Texture node maps it (see the renderer's environment docs).
        ``rotation_rad`` turns the map about the world's up axis as a Blender Mapping node of
        type *Texture* with that Z rotation does (a *Point* mapping turns the other way: pass
        the negated angle)."""
    transparent_background: bool
    """Film > Transparent (default False): camera rays that meet no surface carry no radiance
    (RGB 0 with alpha 0, premultiplied as Blender expects); the environment still lights the
    scene and shows in reflections and refractions."""
    @property
    def triangle_count(self) -> int:
        """Triangles over all instances (a mesh counted once per placement)."""
    @property
    def warnings(self) -> list[str]: ...

_ProgressCallback = Callable[[float, int, NDArray[np.float32] | None], bool]

@final
class Camera:
    """One camera description for :func:`render`, with Blender's camera data semantics.
    Validated when constructed: an invalid value raises InvalidSettingsError naming the
    argument (a missing aperture image FileNotFoundError), an unknown keyword TypeError.

    ``camera_to_world`` is a ``(4, 4)`` camera-to-world matrix (glTF axes, column vectors; scale
    is removed). ``lens`` ``"thin"`` or ``"pinhole"`` use ``focal_length_mm``; a library name or
    lens file brings its own focal length and f-number (``fstop`` stops it down).
    ``sensor_fit`` is Blender's ``"auto"`` (``sensor_width_mm`` spans the larger image side),
    ``"horizontal"`` or ``"vertical"`` (``sensor_height_mm`` spans the height), or USD's
    ``"expand"`` (the apertures grown to the image's aspect). ``shift_x``/``shift_y`` are
    Blender's shifts, in units of the fitted sensor side. ``fstop None`` means no depth of field
    for thin (pinhole) and the lens's own f-number for real lenses. ``focus_distance_m`` None
    or inf is infinity (NaN is an error). ``aperture_blades`` 0 is a circle;
    ``aperture_rotation_rad`` and ``aperture_ratio`` are Blender's; ``aperture_image`` (a mask
    image) replaces the blades. ``lens_model`` ``"auto"`` picks the cheapest model within
    ``tolerance_px`` (pinhole, thin, thick, LRTF, exact) and :func:`render` says why in
    ``lens_model_reason``; or ``"exact"``, ``"lrtf"``, ``"lrtf:RES"``, ``"thick"``, ``"thin"``,
    ``"pinhole"``. ``clip_start_m``/``clip_end_m`` are planes perpendicular to the view axis,
    as in Cycles; beyond them the world shows. ``natural_vignetting`` adds the cos^4 falloff
    of thin and pinhole cameras (off, as in Cycles). ``ortho_scale_m`` makes the camera
    orthographic (Blender's Orthographic Scale: the metres the fitted sensor side spans; the
    lens must be thin or pinhole; ``fstop`` gives Cycles' orthographic depth of field, an
    aperture of radius 1/(2·fstop) m, focused ``focus_distance_m`` from the window)."""

    def __new__(
        cls,
        camera_to_world: NDArray[np.float64],
        *,
        lens: str = "thin",
        lens_model: str = "auto",
        tolerance_px: float = 0.25,
        focal_length_mm: float = 50.0,
        sensor_width_mm: float = 36.0,
        sensor_height_mm: float = 24.0,
        sensor_fit: str = "auto",
        shift_x: float = 0.0,
        shift_y: float = 0.0,
        tilt_x_deg: float = 0.0,
        tilt_y_deg: float = 0.0,
        fstop: float | None = None,
        focus_distance_m: float | None = None,
        aperture_blades: int = 0,
        aperture_rotation_rad: float = 0.0,
        aperture_ratio: float = 1.0,
        aperture_image: str | None = None,
        clip_start_m: float = 0.0,
        clip_end_m: float = float("inf"),
        natural_vignetting: bool = False,
        ortho_scale_m: float | None = None,
    ) -> Camera: ...
    @property
    def lens(self) -> str:
        """The lens argument."""
    @property
    def lens_model(self) -> str:
        """The lens model asked for."""

def render(
    scene: Scene,
    camera: Camera,
    width: int,
    height: int,
    *,
    crop: tuple[int, int, int, int] | None = None,
    spp: int = 64,
    seed: int = 0,
    max_depth: int = 8,
    filter_width_px: float = 1.5,
    spectral: bool = False,
    threads: int = 0,
    progress: _ProgressCallback | None = None,
    progress_interval_s: float = 0.1,
    method: str = "mc",
    layers: int = 4,
    layer_spp: int = 4,
    bokeh_paths: float | None = None,
    adaptive_threshold: float = 0.0,
    adaptive_min_samples: int = 0,
) -> dict:
    """Renders ``scene`` through ``camera`` and returns ``{"rgba": (H, W, 4) float32,
    "depth": (H, W) float32, "spp": int, "complete": bool, "seconds": float, "lens_model": str,
    "lens_model_reason": str, "warnings": list[str], "camera_rays": int, "dropped_samples":
    int}``. Row 0 of the images is the TOP row (flip for Blender's render result, whose row 0
    is the bottom). Depth is the first hit's distance along the camera's view axis (planar, as
    Cycles' Z pass), averaged over the pixel's samples that hit, ``inf`` where nothing was hit.
    ``lens_model`` is the model rendered (the one name of :class:`Camera`'s ``lens_model``).

    ``crop = (x0, y0, x1, y1)`` in pixels of the full ``width x height`` frame, row 0 at the
    top, renders only that window (Blender's border with "crop to border"); the returned
    arrays are the window's size, and every pixel is the same as in the full frame (samples
    are keyed by absolute pixel).

    ``progress(fraction, spp_done, rgba_or_None)`` (``spp_done``: samples per pixel finished so
    far) is called from the calling thread about every ``progress_interval_s`` seconds and
    once per finished pass with the image so far (``rgba`` as above, else None); return
    ``False`` to cancel (``None`` or ``True`` continue). An exception raised by the callback
    cancels and is re-raised. A cancelled render returns what converged with ``complete
    False`` (raises CancelledError if not even one pass finished). ``threads`` 0 uses all
    cores. The GIL is released while rendering.

    ``method`` is the depth-of-field method, as ``petzval render --method``: ``"mc"`` (Monte
    Carlo through the lens, the reference), ``"ibrt"`` (camera rays traced against ``layers``
    depth-peeled layers shaded with ``layer_spp`` samples per texel), ``"spread"`` or
    ``"multiview"``; ``spp`` stays the camera rays per pixel.

    ``bokeh_paths`` (``"mc"`` with the exact lens model) traces that many light paths per pixel
    per sample from emissive surfaces through the lens onto the film, combined with the camera
    paths by multiple importance sampling, as ``petzval render --bokeh-paths``: small bright
    defocused emitters converge several times faster; 0 turns them off, and ``None`` (auto)
    traces one where the camera can (a real lens, exact or LRTF model, ``"mc"``) and the scene
    has emissive surfaces.

    ``adaptive_threshold`` > 0 turns on adaptive sampling (``"mc"`` only), as ``petzval render
    --adaptive-threshold`` and Cycles' Noise Threshold (the same test and scale): a pixel stops
    once its error estimate over its 3x3 neighbourhood passes, tested every 16 samples from just
    past ``adaptive_min_samples`` (0: Cycles' automatic choice, 64 at 0.01); ``spp`` becomes
    the most a pixel takes, and ``camera_rays`` / pixels is the mean."""
