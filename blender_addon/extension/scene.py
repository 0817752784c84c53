"""The evaluated depsgraph as a ``petzval.Scene``: meshes, materials, textures, lights, world.

Everything is passed in memory (numpy buffers), in petzval's conventions (see ``_native.pyi``):
glTF axes (Blender (x, y, z) -> (x, z, -y), applied through each object's transform), UVs
(u, 1 - v), image rows top first, linear colour.

Meshes: one vertex per face corner (loop), so split normals and UV seams come out right with no
welding; triangles from ``loop_triangles``; the evaluated mesh (modifiers applied) is converted
once per evaluated data-block and reused by every instance of it.

Materials: the Principled BSDF (base colour, metallic, roughness, IOR, Specular IOR Level,
alpha, emission, normal map) with Image Texture nodes where glTF can take them; Diffuse BSDF and
Emission shaders. Anything else falls back to the material's viewport display colour and is
listed (once) in the render's warning report.

Lights: point and spot as punctual lights (intensity = power / 4 pi, as Blender's glTF exporter),
sun as a directional light, area lights as one-sided emissive quads/discs with Cycles' radiance
power / (area * pi) (being geometry, they also block light behind them, which Cycles' lights do
not). World: Background colour x strength, or an Environment Texture image.
"""

from __future__ import annotations

import math

import numpy as np

from .camera import to_gltf

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
UNSUPPORTED_TYPES = {"CURVES": "hair curves", "POINTCLOUD": "point clouds", "VOLUME": "volumes",
                     "GREASEPENCIL": "Grease Pencil", "GPENCIL": "Grease Pencil"}

DEFAULT_COLOUR = (0.8, 0.8, 0.8, 1.0)
MISSING_TEXTURE = (1.0, 0.0, 1.0, 1.0)  # magenta: a missing image shows

LINEAR_SPACES = {"Linear Rec.709", "Linear", "Non-Color", "Raw", "Linear CIE-XYZ E", "Linear Rec.2020", "ACEScg", "ACES2065-1"}


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4).astype(np.float32)


# ------------------------------------------------------------------------------------------
# node helpers


def node_tree_of(idblock):
    """The node tree Blender renders with: always the tree from Blender 5 on (``use_nodes`` is
    deprecated there), else only with ``use_nodes``."""
    import bpy

    if bpy.app.version >= (5, 0, 0):
        return idblock.node_tree
    return idblock.node_tree if idblock.use_nodes else None


def source(socket):
    """(node, output socket) linked into `socket`, through reroutes; None if unlinked."""
    if socket is None or not socket.is_linked:
        return None
    link = socket.links[0]
    while True:
        if link.is_muted:
            return None
        node = link.from_node
        if node.type == "REROUTE":
            if not node.inputs[0].is_linked:
                return None
            link = node.inputs[0].links[0]
            continue
        return node, link.from_socket


def surface_shader(node_tree, output_target="CYCLES"):
    """The shader node feeding the active material/world output's Surface, or None."""
    if node_tree is None:
        return None
    out = node_tree.get_output_node(output_target)
    if out is None:
        return None
    src = source(out.inputs.get("Surface"))
    return src[0] if src else None


def value(node, name, default=None):
    s = node.inputs.get(name)
    if s is None:
        return default
    v = s.default_value
    try:
        return tuple(v)
    except TypeError:
        return float(v)


# ------------------------------------------------------------------------------------------
# images


def image_pixels(img, notes, what: str):
    """(H, W, 4) float32 linear pixels of a Blender image, row 0 at the top; None if it has no
    pixels (missing file). Byte images tagged sRGB are decoded here (``Image.pixels`` gives the
    stored byte values / 255); float images are already scene linear in Blender's memory."""
    try:
        w, h = img.size
    except Exception:
        w = h = 0
    if w == 0 or h == 0:
        notes.warn(f"{what}: image '{img.name}' has no pixels (missing file '{img.filepath}'?), shown magenta")
        return None
    c = img.channels
    buf = np.empty(w * h * c, dtype=np.float32)
    img.pixels.foreach_get(buf)
    px = buf.reshape(h, w, c)[::-1]
    if c == 4:
        out = np.array(px, dtype=np.float32)
    else:
        out = np.ones((h, w, 4), dtype=np.float32)
        if c >= 3:
            out[..., :3] = px[..., :3]
        else:
            out[..., :3] = px[..., :1]
        if c == 2:
            out[..., 3] = px[..., 1]
    if not img.is_float:
        cs = img.colorspace_settings.name
        if cs == "sRGB":
            out[..., :3] = srgb_to_linear(out[..., :3])
        elif cs not in LINEAR_SPACES:
            notes.warn(f"image '{img.name}': colour space '{cs}' decoded as sRGB")
            out[..., :3] = srgb_to_linear(out[..., :3])
    return np.ascontiguousarray(out)


INTERPOLATION = {"Closest": "closest", "Linear": "linear", "Cubic": "linear", "Smart": "linear"}
EXTENSION = {"REPEAT": "repeat", "EXTEND": "clip", "CLIP": "clip", "MIRROR": "mirror"}


class Materials:
    """Blender materials as petzval materials (each converted once)."""

    def __init__(self, pz_scene, notes):
        self.scene = pz_scene
        self.notes = notes
        self.index_of: dict = {}
        self.textures: dict = {}
        self._default = None

    # -- textures

    def texture(self, tex_node, what: str, keep_alpha: bool = True):
        """Texture index for an Image Texture node, or None (missing image: warned)."""
        img = tex_node.image
        if img is None:
            self.notes.warn(f"{what}: Image Texture node without an image")
            return None
        if tex_node.projection != "FLAT":
            self.notes.warn(f"{what}: image projection {tex_node.projection} (UV used)")
        vec = source(tex_node.inputs.get("Vector"))
        if vec is not None and not (vec[0].type == "UVMAP" or (vec[0].type == "TEX_COORD" and vec[1].name == "UV")):
            self.notes.warn(f"{what}: texture coordinates from a {vec[0].bl_label} node (the active UV map used)")
        if tex_node.interpolation in ("Cubic", "Smart"):
            self.notes.note(f"{tex_node.interpolation} texture interpolation rendered as Linear")
        if tex_node.extension == "CLIP":
            self.notes.note("image extension Clip rendered as Extend")
        if img.source in ("SEQUENCE", "MOVIE", "TILED"):
            self.notes.warn(f"{what}: image '{img.name}' is a {img.source.lower()} image (its current frame/first tile used)")
        key = (img.name_full, tex_node.interpolation, tex_node.extension, keep_alpha)
        if key not in self.textures:
            px = image_pixels(img, self.notes, what)
            if px is None:
                self.textures[key] = None
            else:
                if not keep_alpha:
                    px[..., 3] = 1.0
                self.textures[key] = self.scene.add_texture(
                    px, name=img.name, interpolation=INTERPOLATION.get(tex_node.interpolation, "linear"),
                    extension=EXTENSION.get(tex_node.extension, "repeat"))
        return self.textures[key]

    def _data_texture(self, key, make):
        if key not in self.textures:
            px = make()
            self.textures[key] = None if px is None else self.scene.add_texture(px, name=key[0])
        return self.textures[key]

    # -- materials

    def default(self) -> int:
        if self._default is None:
            self._default = self.scene.add_material("Default", base_color=DEFAULT_COLOUR, roughness=0.5, specular=1.0)
        return self._default

    def index(self, mat) -> int:
        if mat is None:
            return self.default()
        key = mat.name_full
        if key not in self.index_of:
            self.index_of[key] = self._convert(mat)
        return self.index_of[key]

    def _fallback(self, mat, why: str) -> int:
        self.notes.warn(f"material '{mat.name}': {why}, rendered with its viewport display colour")
        c = tuple(mat.diffuse_color)
        return self.scene.add_material(mat.name, base_color=c, metallic=float(mat.metallic), roughness=float(mat.roughness),
                                       alpha_mode="blend" if c[3] < 1.0 else "opaque")

    def _convert(self, mat) -> int:
        nt = node_tree_of(mat)
        if nt is None:
            c = tuple(mat.diffuse_color)
            return self.scene.add_material(mat.name, base_color=c, metallic=float(mat.metallic), roughness=float(mat.roughness),
                                           specular=2.0 * float(mat.specular_intensity))
        node = surface_shader(nt)
        if node is None:
            # Cycles renders a material with nothing connected as black
            return self.scene.add_material(mat.name, base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0)
        if node.type == "BSDF_PRINCIPLED":
            return self._principled(mat, node)
        if node.type == "BSDF_DIFFUSE":
            kw = self._base_colour(mat, node, "Color")
            if source(node.inputs.get("Normal")) is not None:
                self.notes.warn(f"material '{mat.name}': Diffuse BSDF normal input ignored")
            return self.scene.add_material(mat.name, roughness=1.0, specular=0.0, **kw)
        if node.type == "EMISSION":
            col = value(node, "Color", (1.0, 1.0, 1.0, 1.0))
            strength = value(node, "Strength", 1.0)
            kw = {}
            src = source(node.inputs.get("Color"))
            if src is not None:
                if src[0].type == "TEX_IMAGE":
                    kw["emission_texture"] = self.texture(src[0], f"material '{mat.name}' emission")
                    col = (1.0, 1.0, 1.0)
                else:
                    self.notes.warn(f"material '{mat.name}': emission colour from a {src[0].bl_label} node (its unlinked value used)")
            return self.scene.add_material(mat.name, base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0,
                                           emission=tuple(float(c) * strength for c in col[:3]), **kw)
        return self._fallback(mat, f"{node.bl_label} shader is not supported")

    def _base_colour(self, mat, node, name) -> dict:
        """base_color (+ texture) from a colour input."""
        col = value(node, name, DEFAULT_COLOUR)
        src = source(node.inputs.get(name))
        if src is None:
            return {"base_color": tuple(col)}
        n, out = src
        if n.type == "TEX_IMAGE" and out.name == "Color":
            alpha_src = source(node.inputs.get("Alpha"))
            keep_alpha = alpha_src is not None and alpha_src[0] == n and alpha_src[1].name == "Alpha"
            tex = self.texture(n, f"material '{mat.name}' base colour", keep_alpha=keep_alpha)
            if tex is None:
                return {"base_color": MISSING_TEXTURE}
            return {"base_color": (1.0, 1.0, 1.0, 1.0), "base_color_texture": tex}
        if n.type == "RGB":
            return {"base_color": tuple(out.default_value)}
        self.notes.warn(f"material '{mat.name}': base colour from a {n.bl_label} node, viewport display colour used")
        return {"base_color": tuple(mat.diffuse_color)}

    def _scalar_image(self, mat, node, name, what):
        """(constant or None, Image Texture node or None) of a scalar input."""
        src = source(node.inputs.get(name))
        if src is None:
            return float(value(node, name, 0.0)), None
        n, out = src
        if n.type == "TEX_IMAGE":
            return None, n
        if n.type == "VALUE":
            return float(out.default_value), None
        if n.type in ("SEPARATE_COLOR", "SEPRGB", "SEPARATE_RGB"):
            inner = source(n.inputs[0])
            if inner is not None and inner[0].type == "TEX_IMAGE":
                self.notes.warn(f"material '{mat.name}': {what} from a separated channel of an image (its red channel used)")
                return None, inner[0]
        self.notes.warn(f"material '{mat.name}': {what} from a {n.bl_label} node (its unlinked value used)")
        return float(value(node, name, 0.0)), None

    def _principled(self, mat, node) -> int:
        name = mat.name
        kw = self._base_colour(mat, node, "Base Color")
        alpha = float(value(node, "Alpha", 1.0))
        alpha_src = source(node.inputs.get("Alpha"))
        textured_alpha = "base_color_texture" in kw and alpha_src is not None and alpha_src[0].type == "TEX_IMAGE"
        if alpha_src is not None and not textured_alpha:
            self.notes.warn(f"material '{name}': alpha from a {alpha_src[0].bl_label} node (its unlinked value used)")
        bc = list(kw["base_color"])
        bc = (bc + [1.0])[:4] if len(bc) < 4 else bc
        bc[3] = alpha if not textured_alpha else 1.0
        kw["base_color"] = tuple(bc)
        kw["alpha_mode"] = "blend" if (alpha < 1.0 or textured_alpha) else "opaque"

        metallic, metallic_img = self._scalar_image(mat, node, "Metallic", "metallic")
        roughness, roughness_img = self._scalar_image(mat, node, "Roughness", "roughness")
        kw["metallic"] = 1.0 if metallic_img is not None else metallic
        kw["roughness"] = 1.0 if roughness_img is not None else roughness
        if metallic_img is not None or roughness_img is not None:
            tex = self._metallic_roughness(mat, metallic_img, roughness_img, metallic, roughness)
            if tex is not None:
                kw["metallic_roughness_texture"] = tex
            else:
                kw["metallic"] = metallic if metallic is not None else 0.0
                kw["roughness"] = roughness if roughness is not None else 0.5

        kw["ior"] = float(value(node, "IOR", 1.5))
        kw["specular"] = 2.0 * float(value(node, "Specular IOR Level", 0.5))
        if source(node.inputs.get("Specular IOR Level")) is not None:
            self.notes.warn(f"material '{name}': Specular IOR Level from a node (its unlinked value used)")
        tint = value(node, "Specular Tint", (1.0, 1.0, 1.0, 1.0))
        if isinstance(tint, tuple) and any(abs(t - 1.0) > 1e-6 for t in tint[:3]):
            self.notes.warn(f"material '{name}': Specular Tint")

        # emission
        ecol = value(node, "Emission Color", (0.0, 0.0, 0.0, 1.0))
        estr = float(value(node, "Emission Strength", 0.0))
        esrc = source(node.inputs.get("Emission Color"))
        if esrc is not None and esrc[0].type == "TEX_IMAGE":
            tex = self.texture(esrc[0], f"material '{name}' emission")
            if tex is not None:
                kw["emission_texture"] = tex
                ecol = (1.0, 1.0, 1.0)
        elif esrc is not None:
            self.notes.warn(f"material '{name}': emission colour from a {esrc[0].bl_label} node (its unlinked value used)")
        if source(node.inputs.get("Emission Strength")) is not None:
            self.notes.warn(f"material '{name}': Emission Strength from a node (its unlinked value used)")
        kw["emission"] = tuple(float(c) * estr for c in ecol[:3])

        # normal map
        nsrc = source(node.inputs.get("Normal"))
        if nsrc is not None:
            nn = nsrc[0]
            if nn.type == "NORMAL_MAP" and nn.space == "TANGENT":
                csrc = source(nn.inputs.get("Color"))
                if csrc is not None and csrc[0].type == "TEX_IMAGE":
                    tex = self.texture(csrc[0], f"material '{name}' normal map")
                    if tex is not None:
                        kw["normal_texture"] = tex
                        kw["normal_scale"] = float(value(nn, "Strength", 1.0))
                    if nn.uv_map:
                        self.notes.warn(f"material '{name}': normal map on UV map '{nn.uv_map}' (the active render UV map used)")
                else:
                    self.notes.warn(f"material '{name}': Normal Map node without an Image Texture")
            else:
                self.notes.warn(f"material '{name}': normal from a {nn.bl_label} node{' (' + nn.space.lower() + ' space)' if nn.type == 'NORMAL_MAP' else ''}")

        # lobes glTF/Petzval's BSDF does not have
        for label, inp in (("Transmission", "Transmission Weight"), ("Coat", "Coat Weight"), ("Sheen", "Sheen Weight"),
                           ("Subsurface", "Subsurface Weight"), ("Anisotropy", "Anisotropic"), ("Thin film", "Thin Film Thickness")):
            v = value(node, inp, 0.0)
            if (isinstance(v, float) and v > 0.0) or source(node.inputs.get(inp)) is not None:
                self.notes.warn(f"material '{name}': {label}")
        return self.scene.add_material(name, **kw)

    def _metallic_roughness(self, mat, m_node, r_node, m_const, r_const):
        """glTF's metallicRoughness texture (G roughness, B metallic) from one or two greyscale
        images (red channel), constants filling the other."""
        what = f"material '{mat.name}' metallic/roughness"
        key = (f"{mat.name_full}:metallic_roughness", None)

        def make():
            imgs = {}
            for role, n in (("m", m_node), ("r", r_node)):
                if n is not None:
                    if n.image is None:
                        self.notes.warn(f"{what}: Image Texture node without an image")
                        return None
                    px = image_pixels(n.image, self.notes, what)
                    if px is None:
                        return None
                    imgs[role] = px
            shapes = {p.shape for p in imgs.values()}
            if len(shapes) > 1:
                self.notes.warn(f"{what}: metallic and roughness images of different sizes (constants used)")
                return None
            h, w = next(iter(shapes))[:2]
            out = np.ones((h, w, 4), dtype=np.float32)
            out[..., 0] = 0.0
            out[..., 1] = imgs["r"][..., 0] if "r" in imgs else r_const
            out[..., 2] = imgs["m"][..., 0] if "m" in imgs else m_const
            return out

        return self._data_texture(key, make)


# ------------------------------------------------------------------------------------------
# meshes


class MeshData:
    """Per-corner buffers of one evaluated mesh (petzval conventions, object space)."""

    __slots__ = ("positions", "triangles", "slot_index", "normals", "uvs")

    def __init__(self, positions, triangles, slot_index, normals, uvs):
        self.positions = positions
        self.triangles = triangles
        self.slot_index = slot_index
        self.normals = normals
        self.uvs = uvs


def mesh_data(mesh) -> MeshData | None:
    """One vertex per face corner; triangles from loop_triangles; corner normals; the active
    render UV map as (u, 1 - v)."""
    mesh.calc_loop_triangles()
    nt = len(mesh.loop_triangles)
    if nt == 0:
        return None
    nl = len(mesh.loops)
    tris = np.empty(nt * 3, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("loops", tris)
    slots = np.empty(nt, dtype=np.uint32)
    mesh.loop_triangles.foreach_get("material_index", slots)
    vidx = np.empty(nl, dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", vidx)
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    positions = np.ascontiguousarray(co.reshape(-1, 3)[vidx])
    normals = np.empty(nl * 3, dtype=np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    uvs = None
    layer = next((l for l in mesh.uv_layers if l.active_render), None)
    if layer is not None:
        uvs = np.empty(nl * 2, dtype=np.float32)
        if hasattr(layer, "uv"):
            layer.uv.foreach_get("vector", uvs)
        else:
            layer.data.foreach_get("uv", uvs)
        uvs = uvs.reshape(-1, 2)
        uvs[:, 1] = 1.0 - uvs[:, 1]
    return MeshData(positions, tris.reshape(-1, 3), slots, normals.reshape(-1, 3), uvs)


# ------------------------------------------------------------------------------------------
# lights


def light_colour(light) -> np.ndarray:
    c = np.array(light.color, dtype=np.float64)
    if getattr(light, "use_temperature", False):
        c = c * np.array(light.temperature_color, dtype=np.float64)
    return c * (2.0 ** float(getattr(light, "exposure", 0.0)))


def _light_nodes_do_something(nt) -> bool:
    """True unless the light's node tree is Blender's default (a white Emission of strength 1
    into the Light Output)."""
    for node in nt.nodes:
        if node.type == "OUTPUT_LIGHT":
            continue
        if node.type != "EMISSION":
            return True
        col = value(node, "Color", (1.0, 1.0, 1.0, 1.0))
        if abs(value(node, "Strength", 1.0) - 1.0) > 1e-6 or any(abs(c - 1.0) > 1e-6 for c in col[:3]):
            return True
        if any(s.is_linked for s in node.inputs):
            return True
    return False


def add_light(pz, obj, matrix_world, notes, materials) -> None:
    light = obj.data
    m = to_gltf(matrix_world)
    pos = m[:3, 3]
    axis = -m[:3, 2]
    n = np.linalg.norm(axis)
    direction = axis / n if n > 0 else np.array([0.0, -1.0, 0.0])
    colour = light_colour(light)
    name = obj.name
    lnt = node_tree_of(light) if hasattr(light, "node_tree") else None
    if lnt is not None and _light_nodes_do_something(lnt):
        notes.warn(f"light '{name}': light nodes")
    if light.type in ("POINT", "SPOT"):
        intensity = colour * float(light.energy) / (4.0 * math.pi)
        if light.shadow_soft_size > 0:
            notes.note("point and spot lights are rendered as points (radius ignored)")
        if light.type == "POINT":
            pz.add_point_light(tuple(pos), tuple(intensity), name=name)
        else:
            outer = float(light.spot_size) / 2.0
            inner = outer * (1.0 - float(light.spot_blend))
            if light.use_square:
                notes.warn(f"light '{name}': square spot (a round cone used)")
            pz.add_spot_light(tuple(pos), tuple(direction), tuple(intensity), inner, outer, name=name)
    elif light.type == "SUN":
        if light.angle > 0:
            notes.note("sun lights are rendered as parallel light (angle ignored)")
        pz.add_sun_light(tuple(direction), tuple(colour * float(light.energy)), name=name)
    elif light.type == "AREA":
        add_area_light(pz, obj, m, colour, notes, materials)
    else:
        notes.warn(f"light '{name}': {light.type.lower()} lights")


def area_light_geometry(light):
    """Object-space vertices and triangles of an area light's shape (z = 0), its triangles
    facing -z (the direction the light emits to)."""
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
    if light.shape in ("SQUARE", "RECTANGLE"):
        v = np.array([[-sx / 2, -sy / 2, 0], [sx / 2, -sy / 2, 0], [sx / 2, sy / 2, 0], [-sx / 2, sy / 2, 0]], dtype=np.float64)
        t = np.array([[0, 2, 1], [0, 3, 2]], dtype=np.uint32)
    else:
        k = 48
        a = np.linspace(0, 2 * math.pi, k, endpoint=False)
        # a polygon with the disc's area (so the emitted power is the disc's)
        r_scale = math.sqrt(math.pi / (k / 2 * math.sin(2 * math.pi / k)))
        rim = np.stack([sx / 2 * r_scale * np.cos(a), sy / 2 * r_scale * np.sin(a), np.zeros(k)], axis=1)
        v = np.vstack([[[0.0, 0.0, 0.0]], rim])
        t = np.array([[0, (i + 1) % k + 1, i + 1] for i in range(k)], dtype=np.uint32)
    return v, t


def add_area_light(pz, obj, m, colour, notes, materials) -> None:
    light = obj.data
    v, t = area_light_geometry(light)
    world = (m[:3, :3] @ v.T).T
    e1 = world[t[:, 1]] - world[t[:, 0]]
    e2 = world[t[:, 2]] - world[t[:, 0]]
    area = float(0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum())
    if area <= 0:
        notes.warn(f"light '{obj.name}': area light of zero size")
        return
    if light.spread < math.pi - 1e-4:
        notes.warn(f"light '{obj.name}': area light spread below 180°")
    # Cycles: radiance = power / (area * pi) for a normalized light (one-sided, Lambertian); measured
    # in Cycles 5.0: a 1 m^2 light of 100 W seen head-on reads 31.83 = 100 / pi)
    power = float(light.energy)
    radiance = colour * power / ((area if light.normalize else 1.0) * math.pi)
    mat = pz.add_material(f"{obj.name} (area light)", base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0, roughness=1.0,
                          emission=tuple(radiance), double_sided=False)
    normals = np.tile(np.array([[0.0, 0.0, -1.0]], dtype=np.float32), (len(v), 1))
    pz.add_mesh(v.astype(np.float32), t, material_ids=np.full(len(t), mat, dtype=np.uint32), normals=normals,
                transform=m, name=obj.name)
    if not getattr(obj, "visible_camera", True):
        notes.note("area lights are emissive surfaces here: seen by the camera (Cycles hides lights from camera rays by "
                   "default) and casting shadows (Cycles' lights do not)")
    else:
        notes.note("area lights are emissive surfaces here: they cast shadows (Cycles' lights do not)")


# ------------------------------------------------------------------------------------------
# world


def add_world(pz, world, notes, materials) -> None:
    if world is None:
        pz.set_environment_color((0.0, 0.0, 0.0))
        return
    nt = node_tree_of(world)
    node = surface_shader(nt) if nt is not None else None
    if node is None:
        pz.set_environment_color(tuple(float(c) for c in world.color))
        return
    if node.type != "BACKGROUND":
        notes.warn(f"world '{world.name}': {node.bl_label} shader (the world's viewport colour used)")
        pz.set_environment_color(tuple(float(c) for c in world.color))
        return
    strength = float(value(node, "Strength", 1.0))
    if source(node.inputs.get("Strength")) is not None:
        notes.warn(f"world '{world.name}': strength from a node (its unlinked value used)")
    src = source(node.inputs.get("Color"))
    if src is None:
        col = value(node, "Color", (0.05, 0.05, 0.05, 1.0))
        pz.set_environment_color(tuple(float(c) * strength for c in col[:3]))
        return
    env, out = src
    if env.type == "TEX_ENVIRONMENT" and out.name == "Color" and env.image is not None:
        if env.projection != "EQUIRECTANGULAR":
            notes.warn(f"world '{world.name}': {env.projection.lower()} environment projection (equirectangular used)")
        rotation = 0.0
        vec = source(env.inputs.get("Vector"))
        if vec is not None:
            mapping = vec[0]
            if mapping.type == "MAPPING":
                rot = tuple(value(mapping, "Rotation", (0.0, 0.0, 0.0)))
                loc = tuple(value(mapping, "Location", (0.0, 0.0, 0.0)))
                scl = tuple(value(mapping, "Scale", (1.0, 1.0, 1.0)))
                # petzval's rotation_rad is a Texture-type Mapping Z rotation (the map turns by it);
                # Point/Vector/Normal types rotate the lookup direction instead: the opposite turn
                rotation = float(rot[2]) if mapping.vector_type == "TEXTURE" else -float(rot[2])
                if abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6 or any(abs(x) > 1e-6 for x in loc) or any(abs(s - 1) > 1e-6 for s in scl):
                    notes.warn(f"world '{world.name}': Mapping node other than a Z rotation (only its Z rotation used)")
            else:
                notes.warn(f"world '{world.name}': environment coordinates from a {mapping.bl_label} node (ignored)")
        px = image_pixels(env.image, notes, f"world '{world.name}'")
        if px is None:
            pz.set_environment_color(MISSING_TEXTURE[:3])
            return
        pz.set_environment_map(px, strength=strength, rotation_rad=rotation, name=env.image.name)
        return
    if env.type == "RGB":
        col = tuple(out.default_value)
        pz.set_environment_color(tuple(float(c) * strength for c in col[:3]))
        return
    notes.warn(f"world '{world.name}': background colour from a {env.bl_label} node (its unlinked value used)")
    col = value(node, "Color", (0.05, 0.05, 0.05, 1.0))
    pz.set_environment_color(tuple(float(c) * strength for c in col[:3]))


# ------------------------------------------------------------------------------------------
# the whole scene


def build(petzval, depsgraph, notes, stop=None):
    """A ``petzval.Scene`` from the evaluated depsgraph. `stop()` (optional) is polled between
    objects; returns None when it asks to stop. Also returns counts for the status line."""
    pz = petzval.Scene()
    materials = Materials(pz, notes)
    meshes: dict = {}
    stats = {"objects": 0, "instances": 0, "lights": 0, "meshes_converted": 0}
    for i, inst in enumerate(depsgraph.object_instances):
        if stop is not None and i % 64 == 0 and stop():
            return None, stats
        obj = inst.object
        t = obj.type
        if t == "LIGHT":
            if inst.show_self:
                add_light(pz, obj, inst.matrix_world, notes, materials)
                stats["lights"] += 1
            continue
        if t in UNSUPPORTED_TYPES:
            notes.warn(f"{UNSUPPORTED_TYPES[t]} ('{obj.name}')")
            continue
        if t not in GEOMETRY_TYPES or not inst.show_self:
            continue
        if not getattr(obj, "visible_camera", True) or not getattr(obj, "visible_shadow", True):
            notes.warn(f"object '{obj.name}': ray visibility settings (rendered fully visible)")
        data = obj.data
        key = data.as_pointer() if data is not None else ("object", obj.name_full)
        md = meshes.get(key, False)
        if md is False:
            try:
                mesh = obj.to_mesh()
            except RuntimeError:
                mesh = None
            md = None
            if mesh is not None:
                try:
                    md = mesh_data(mesh)
                finally:
                    obj.to_mesh_clear()
            meshes[key] = md
            stats["meshes_converted"] += 1
        if md is None:
            continue
        slots = obj.material_slots
        if len(slots) == 0:
            table = np.array([materials.default()], dtype=np.uint32)
        else:
            table = np.array([materials.index(s.material) for s in slots], dtype=np.uint32)
        mat_ids = table[np.minimum(md.slot_index, len(table) - 1)]
        pz.add_mesh(md.positions, md.triangles, material_ids=mat_ids, normals=md.normals, uvs=md.uvs,
                    transform=to_gltf(inst.matrix_world), name=obj.name)
        stats["objects" if not inst.is_instance else "instances"] += 1
    return pz, stats
