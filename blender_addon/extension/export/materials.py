"""Blender materials as petzval materials.

Materials: the Principled BSDF (base colour, metallic, roughness, IOR, Specular IOR Level,
Specular Tint of the metallic part, alpha, emission, normal map, Transmission Weight, Coat
Weight, Roughness, IOR and Tint) with Image Texture nodes where glTF can take them, and a base
colour from a Color Attribute node (or an Attribute node naming a geometry attribute): the
mesh's colours, which the renderer multiplies into the base colour as glTF's ``COLOR_0``;
Diffuse, Translucent, Glossy, Metallic, Glass, Refraction (as Glass), Transparent BSDFs and Emission
shaders, joined by Mix and Add Shaders (a weighted sum of closures: transparency becomes
stochastic coverage, emission adds up, and each scattering event picks one BSDF by its weight,
``ShaderMix``). Anything else falls back to the material's viewport display colour and is
listed (once) in the render's warning report.
"""

from __future__ import annotations

import math

import numpy as np

from .bake import Baked, Evaluator, Unsupported
from .images import MISSING_TEXTURE, image_pixels, srgb_byte_image
from .nodes import forget_groups, node_tree_of, socket_value, source, surface_shader, value, volume_shader

DEFAULT_COLOUR = (0.8, 0.8, 0.8, 1.0)

INTERPOLATION = {"Closest": "closest", "Linear": "linear", "Cubic": "linear", "Smart": "linear"}
EXTENSION = {"REPEAT": "repeat", "EXTEND": "clip", "CLIP": "clip", "MIRROR": "mirror"}


def _tex_node(n):
    """The Image Texture node of an image input: itself, or the one a baked chain read."""
    return n.tex_node if isinstance(n, Baked) else n


def is_uv(src) -> bool:
    """Whether (node, output) is the UV map: a UV Map node or a Texture Coordinate's UV."""
    node, out = src
    return node.type == "UVMAP" or (node.type == "TEX_COORD" and out.name == "UV")


def mapping_uv_rows(vector_type: str, location, rotation, scale) -> list[list[float]]:
    """A Mapping node (Cycles' ``svm_mapping``: Point R·(S·v) + L, Vector R·(S·v), Texture
    R⁻¹·(v − L)/S; R from XYZ Euler angles) on UV coordinates (z = 0), as the 2 x 3 map of
    ``add_mesh``'s coordinates (v flipped: v' = 1 − v) that ``add_material``'s
    ``uv_transforms`` takes."""
    cx, cy, cz = (math.cos(a) for a in rotation[:3])
    sx, sy, sz = (math.sin(a) for a in rotation[:3])
    r = np.array(
        [
            [cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz],
            [cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz],
            [-sy, cy * sx, cy * cx],
        ]
    )
    s = np.array(scale[:3], dtype=float)
    loc = np.array(location[:3], dtype=float)
    if vector_type == "TEXTURE":
        inv_s = np.divide(1.0, s, out=np.zeros(3), where=s != 0.0)
        a = inv_s[:, None] * r.T
        t = -a @ loc
    else:
        a = r * s[None, :]
        t = loc if vector_type == "POINT" else np.zeros(3)
    # Blender's coordinates b = (u, 1 − v); the lookup at (b'x, 1 − b'y)
    return [
        [float(a[0, 0]), float(-a[0, 1]), float(a[0, 1] + t[0])],
        [float(-a[1, 0]), float(a[1, 1]), float(1.0 - a[1, 1] - t[1])],
    ]


def conductor_fresnel(cos: float, n: float, k: float) -> float:
    """Unpolarised Fresnel reflectance of a conductor of complex index n + ik at `cos`."""
    c2 = cos * cos
    t = n * n + k * k
    two_nc = 2.0 * n * cos
    r_par = (t * c2 - two_nc + 1.0) / (t * c2 + two_nc + 1.0)
    r_perp = (t - two_nc + c2) / (t + two_nc + c2)
    return 0.5 * (r_par + r_perp)


class ShaderMix:
    """A material's closures as a weighted sum (Mix and Add Shaders flattened): BSDFs as
    (weight, add_material arguments), emission, and the weight of transparency."""

    def __init__(self):
        self.bsdfs: list[tuple[float, dict]] = []
        self.emission = (0.0, 0.0, 0.0)
        self.emission_texture = None
        self.emission_uv = None
        self.transparency = 0.0

    def add_emission(self, weight: float, emission, texture, uv=None) -> None:
        """Adds `weight` × `emission` (a texture, with its coordinates' map `uv`, multiplies the
        sum: the first one kept)."""
        self.emission = tuple(a + weight * float(b) for a, b in zip(self.emission, emission[:3], strict=True))
        if texture is not None and self.emission_texture is None:
            self.emission_texture, self.emission_uv = texture, uv


class Materials:
    """Blender materials as petzval materials (each converted once)."""

    def __init__(self, pz_scene, notes):
        forget_groups()
        self.scene = pz_scene
        self.notes = notes
        self.index_of: dict = {}
        self.textures: dict = {}
        self._default = None
        self._variants: dict = {}
        # material index -> the colour attribute its base colour reads ("" = the mesh's default
        # colour attribute), for materials whose base colour is a Color Attribute / Attribute node
        self.colour_attribute: dict[int, str] = {}
        self._reading: str | None = None

    # -- textures

    def texture(self, tex_node, what: str, keep_alpha: bool = True):
        """Texture index for an Image Texture node, or None (missing image: warned)."""
        img = tex_node.image
        if img is None:
            self.notes.warn(f"{what}: Image Texture node without an image")
            return None
        if tex_node.projection != "FLAT":
            self.notes.warn(f"{what}: image projection {tex_node.projection} (UV used)")
        if tex_node.interpolation in ("Cubic", "Smart"):
            self.notes.note(f"{tex_node.interpolation} texture interpolation rendered as Linear")
        if tex_node.extension == "CLIP":
            self.notes.note("image extension Clip rendered as Extend")
        if img.source in ("SEQUENCE", "MOVIE", "TILED"):
            self.notes.warn(
                f"{what}: image '{img.name}' is a {img.source.lower()} image (its current frame/first tile used)"
            )
        key = (img.name_full, tex_node.interpolation, tex_node.extension, keep_alpha)
        if key not in self.textures:
            interpolation = INTERPOLATION.get(tex_node.interpolation, "linear")
            # an 8-bit sRGB image filtered linearly stays encoded: filtered, then decoded (Cycles)
            encoded = interpolation == "linear" and srgb_byte_image(img)
            px = image_pixels(img, self.notes, what, keep_srgb=encoded)
            if px is None:
                self.textures[key] = None
            else:
                if not keep_alpha:
                    px[..., 3] = 1.0
                self.textures[key] = self.scene.add_texture(
                    px,
                    name=img.name,
                    interpolation=interpolation,
                    extension=EXTENSION.get(tex_node.extension, "repeat"),
                    srgb_encoded=encoded,
                )
        return self.textures[key]

    def uv_transform(self, tex_node, what: str):
        """The affine map of texture coordinates (2 x 3 rows, ``add_material``'s
        ``uv_transforms``) that a Mapping node between the UV map and `tex_node` makes, or
        None (the UV map itself; other coordinates are listed and the UV map used)."""
        vec = source(tex_node.inputs.get("Vector"))
        if vec is None or is_uv(vec):
            return None
        node = vec[0]
        if node.type != "MAPPING":
            self.notes.warn(f"{what}: texture coordinates from a {node.bl_label} node (the active UV map used)")
            return None
        inner = source(node.inputs.get("Vector"))
        if inner is not None and not is_uv(inner):
            self.notes.warn(f"{what}: texture coordinates from a {inner[0].bl_label} node (the active UV map used)")
        for name in ("Location", "Rotation", "Scale"):
            src = source(node.inputs.get(name))
            if src is not None:
                self.notes.warn(f"{what}: Mapping {name} from a {src[0].bl_label} node (its unlinked value used)")
        if node.vector_type == "NORMAL":
            self.notes.warn(f"{what}: a Mapping node of type Normal (ignored)")
            return None
        return mapping_uv_rows(
            node.vector_type,
            value(node, "Location", (0.0, 0.0, 0.0)),
            value(node, "Rotation", (0.0, 0.0, 0.0)),
            value(node, "Scale", (1.0, 1.0, 1.0)),
        )

    def _set_texture(self, kw: dict, field: str, tex_node, what: str, **options) -> bool:
        """Sets `kw[field]` to `tex_node`'s texture and its coordinates' map; False (nothing set)
        when the image is missing."""
        tex = self.texture(tex_node, what, **options)
        if tex is None:
            return False
        kw[field] = tex
        uv = self.uv_transform(tex_node, what)
        if uv is not None:
            kw.setdefault("uv_transforms", {})[field] = uv
        return True

    def _scalar(self, mat, socket, what: str, default: float) -> float:
        """A scalar input that must be constant: its value, or that of a chain of value nodes
        (a spatially varying one: its unlinked value, listed)."""
        if source(socket) is None:
            return float(socket_value(socket, default))
        try:
            baked = Evaluator(self.notes, f"material '{mat.name}' {what}").evaluate(socket, "float")
            if baked.constant:
                return float(baked.value[0])
            label = f"an image through {source(socket)[0].bl_label}"
        except Unsupported as e:
            label = f"a {e} node"
        self.notes.warn(f"material '{mat.name}': {what} from {label} (its unlinked value used)")
        return float(socket_value(socket, default)) if socket is not None else default

    def _baked_emission(self, mat, socket, kw: dict, unlinked):
        """The emission colour of a chain of colour nodes: a constant (returned), or a baked
        texture (set in `kw`; white returned); unsupported: `unlinked`, listed."""
        what = f"material '{mat.name}' emission"
        try:
            baked = Evaluator(self.notes, what).evaluate(socket, "color")
        except Unsupported as e:
            self.notes.warn(f"material '{mat.name}': emission colour from a {e} node (its unlinked value used)")
            return unlinked
        if self._set_baked(kw, "emission_texture", baked, what):
            return (1.0, 1.0, 1.0)
        return tuple(float(c) for c in baked.value[:3])

    def _set_baked(self, kw: dict, field: str, baked: Baked, what: str) -> bool:
        """Sets `kw[field]` to a texture of a baked colour (with its image's filtering, extension
        and mapping); False for a constant (nothing set)."""
        if baked.constant:
            return False
        tex_node = baked.tex_node
        h, w = baked.value.shape[:2]
        px = np.ones((h, w, 4), dtype=np.float32)
        px[..., :3] = baked.value
        kw[field] = self.scene.add_texture(
            px,
            name=f"{tex_node.image.name} ({what})",
            interpolation=INTERPOLATION.get(tex_node.interpolation, "linear"),
            extension=EXTENSION.get(tex_node.extension, "repeat"),
        )
        uv = self.uv_transform(tex_node, what)
        if uv is not None:
            kw.setdefault("uv_transforms", {})[field] = uv
        return True

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
            self._reading = None
            try:
                index = self._convert(mat)
            except Exception as e:  # a material the add-on cannot read must not stop the render
                self._reading = None
                index = self._fallback(mat, f"could not be converted ({type(e).__name__}: {e})")
            self.index_of[key] = index
            if self._reading is not None:
                self.colour_attribute[index] = self._reading
        return self.index_of[key]

    def for_object(self, index: int, visible_to_camera: bool, terminator_offset: float) -> int:
        """Material ``index`` with an object's Ray Visibility > Camera and Shadow Terminator >
        Geometry Offset: itself for Blender's defaults (visible, 0.1), else a copy made once."""
        if visible_to_camera and abs(terminator_offset - 0.1) < 1e-6:
            return index
        key = (index, visible_to_camera, round(terminator_offset, 6))
        if key not in self._variants:
            self._variants[key] = self.scene.material_variant(
                index, visible_to_camera=visible_to_camera, terminator_offset=terminator_offset
            )
            if index in self.colour_attribute:
                self.colour_attribute[self._variants[key]] = self.colour_attribute[index]
        return self._variants[key]

    def _fallback(self, mat, why: str) -> int:
        self.notes.warn(f"material '{mat.name}': {why}, rendered with its viewport display colour")
        c = tuple(mat.diffuse_color)
        return self.scene.add_material(
            mat.name,
            base_color=c,
            metallic=float(mat.metallic),
            roughness=float(mat.roughness),
            alpha_mode="blend" if c[3] < 1.0 else "opaque",
        )

    def _convert(self, mat) -> int:
        nt = node_tree_of(mat)
        if nt is None:
            c = tuple(mat.diffuse_color)
            return self.scene.add_material(
                mat.name,
                base_color=c,
                metallic=float(mat.metallic),
                roughness=float(mat.roughness),
                specular=2.0 * float(mat.specular_intensity),
            )
        node = surface_shader(nt)
        volume = volume_shader(nt)
        if volume is not None:
            if node is None:
                # Cycles shows only the volume (no surface): the object is not there for
                # surfaces, so it is rendered fully transparent rather than black
                self.notes.warn(f"material '{mat.name}': volume shader (a volume-only material rendered invisible)")
                return self.scene.add_material(mat.name, base_color=(0.0, 0.0, 0.0, 0.0), specular=0.0,
                                               alpha_mode="blend")
            self.notes.warn(f"material '{mat.name}': volume shader (ignored; the surface rendered)")
        if node is None:
            # Cycles renders a material with nothing connected as black
            return self.scene.add_material(mat.name, base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0)
        if node.type == "BSDF_PRINCIPLED":
            return self.scene.add_material(mat.name, **self._principled(mat, node))
        if node.type == "BSDF_DIFFUSE":
            return self.scene.add_material(mat.name, **self._diffuse(mat, node))
        if node.type == "EMISSION":
            col, strength, kw = self._emission(mat, node)
            return self.scene.add_material(mat.name, base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0,
                                           emission=tuple(float(c) * strength for c in col[:3]), **kw)
        if node.type == "MIX_SHADER":
            masked = self._masked_mix(mat, node)
            if masked is not None:
                return masked
        mix = ShaderMix()
        why = self._gather(mat, node, 1.0, mix, depth=0)
        if why is not None:
            return self._fallback(mat, why)
        return self._add_mix(mat, mix)

    # -- shaders other than a lone Principled, Diffuse or Emission: a weighted sum of closures

    def _gather(self, mat, node, weight: float, mix: ShaderMix, depth: int) -> str | None:
        """Adds shader `node`'s closures, scaled by `weight`, to `mix`; returns why the material
        cannot be rendered (an unsupported shader), else None."""
        name = mat.name
        if depth > 32:
            return "shader nodes nested more than 32 deep"
        if weight <= 0.0:
            return None
        t = node.type
        if t in ("MIX_SHADER", "ADD_SHADER"):
            shaders = [s for s in node.inputs if s.type == "SHADER"]
            if t == "MIX_SHADER":
                # "Factor" (Blender 5), "Fac" before
                fac = min(max(self._scalar(mat, node.inputs[0], "Mix Shader factor", 0.5), 0.0), 1.0)
                weights = (weight * (1.0 - fac), weight * fac)
            else:
                weights = (weight, weight)
            for sock, w in zip(shaders, weights, strict=False):
                src = source(sock)
                # an unconnected shader input adds nothing (black), as in Cycles
                if src is not None:
                    why = self._gather(mat, src[0], w, mix, depth + 1)
                    if why is not None:
                        return why
            return None
        if t == "BSDF_PRINCIPLED":
            kw = self._principled(mat, node)
            emission = kw.pop("emission", (0.0, 0.0, 0.0))
            etex = kw.pop("emission_texture", None)
            euv = kw.get("uv_transforms", {}).pop("emission_texture", None)
            alpha = float(kw["base_color"][3]) if len(kw["base_color"]) > 3 else 1.0
            if kw.get("alpha_mode") == "blend" and alpha >= 1.0:
                self.notes.warn(f"material '{name}': an alpha texture inside a Mix or Add Shader (ignored)")
            kw["base_color"] = (*kw["base_color"][:3], 1.0)
            kw.pop("alpha_mode", None)
            mix.add_emission(weight * alpha, emission, etex, euv)
            mix.transparency += weight * (1.0 - alpha)
            mix.bsdfs.append((weight * alpha, kw))
            return None
        if t == "BSDF_DIFFUSE":
            mix.bsdfs.append((weight, self._diffuse(mat, node)))
            return None
        if t in ("EMISSION", "BACKGROUND"):
            col, strength, kw = self._emission(mat, node)
            mix.add_emission(
                weight,
                tuple(float(c) * strength for c in col[:3]),
                kw.get("emission_texture"),
                kw.get("uv_transforms", {}).get("emission_texture"),
            )
            return None
        if t == "BSDF_TRANSPARENT":
            col = value(node, "Color", (1.0, 1.0, 1.0, 1.0))[:3]
            if max(col) - min(col) > 1e-6 or source(node.inputs.get("Color")) is not None:
                self.notes.warn(
                    f"material '{name}': coloured Transparent BSDF (light passes untinted, in the share of its mean)"
                )
            mix.transparency += weight * sum(col) / 3.0
            return None
        if t in ("BSDF_GLASS", "BSDF_REFRACTION"):
            if t == "BSDF_REFRACTION":
                self.notes.warn(f"material '{name}': Refraction BSDF rendered as a Glass BSDF (with its reflection)")
            kw = self._tinted(mat, node)
            kw.update(metallic=0.0, transmission=1.0, specular=1.0, ior=float(value(node, "IOR", 1.5)))
            mix.bsdfs.append((weight, kw))
            return None
        if t in ("BSDF_GLOSSY", "BSDF_ANISOTROPIC"):
            # no Fresnel: its colour at every angle, its multiple scattering coloured by it
            kw = self._base_colour(mat, node, "Color")
            kw["metal_fresnel"] = "constant"
            self._roughness_into(mat, node, kw, 1.0)
            self._normal(mat, node, kw)
            self._anisotropy(mat, node, kw, "glossy", "Anisotropy", "Rotation")
            mix.bsdfs.append((weight, kw))
            return None
        if t == "BSDF_TRANSLUCENT":
            kw = self._diffuse(mat, node)
            kw["translucent"] = True
            mix.bsdfs.append((weight, kw))
            return None
        if t == "BSDF_METALLIC":
            mix.bsdfs.append((weight, self._metallic(mat, node)))
            return None
        return f"{node.bl_label} shader is not supported"

    def _roughness_into(self, mat, node, kw: dict, metallic: float) -> None:
        """A BSDF node's Roughness (a constant, an image, or a chain of nodes over one) and a
        constant `metallic` into `kw` (an image: glTF's metallicRoughness texture, B = metallic)."""
        if getattr(node, "distribution", "MULTI_GGX") not in ("MULTI_GGX", "GGX"):
            self.notes.note(f"{node.bl_label} distribution {node.distribution.title()} rendered as Multiscatter GGX")
        r, r_img = self._scalar_image(mat, node, "Roughness", "roughness")
        kw["metallic"] = metallic
        kw["roughness"] = min(max(r, 0.0), 1.0) if r_img is None else 1.0
        if r_img is None:
            return
        tex = self._metallic_roughness(mat, None, r_img, metallic, 0.5)
        if tex is None:
            kw["roughness"] = 0.5
            return
        kw["metallic"] = 1.0  # times the texture's B, which is `metallic`
        kw["metallic_roughness_texture"] = tex
        uv = self.uv_transform(_tex_node(r_img), f"material '{mat.name}' roughness")
        if uv is not None:
            kw.setdefault("uv_transforms", {})["metallic_roughness_texture"] = uv

    def _tinted(self, mat, node) -> dict:
        """Glass and Refraction BSDFs: white glass times the node's Color (a constant, or a chain
        of nodes evaluating to one), which scales the whole closure, reflection and refraction;
        a texture or colour attribute goes in as the base colour instead, which tints the
        refracted light only, by its square root at each crossing."""
        kw = self._base_colour(mat, node, "Color")
        src = source(node.inputs.get("Color"))
        # a colour that varies (a texture, a colour attribute) cannot be a tint; a constant one
        # (an RGB node, a chain of them) can
        varies = "base_color_texture" in kw or (src is not None and src[0].type in ("VERTEX_COLOR", "ATTRIBUTE"))
        if varies:
            self.notes.warn(
                f"material '{mat.name}': {node.bl_label} colour from a node (rendered as the base colour: "
                "tints the refracted light only)"
            )
        else:
            kw = {"base_color": (1.0, 1.0, 1.0, 1.0), "scatter_tint": tuple(float(c) for c in kw["base_color"][:3])}
        self._roughness_into(mat, node, kw, 0.0)
        self._normal(mat, node, kw)
        return kw

    def _metallic(self, mat, node) -> dict:
        """The Metallic BSDF: F82 (Base Color, Edge Tint) or a Physical Conductor, rendered as
        the F82 model through its exact reflectance head-on and at 82° (IOR and Extinction)."""
        if getattr(node, "fresnel_type", "F82") == "PHYSICAL_CONDUCTOR":
            n = value(node, "IOR", (2.757, 2.513, 2.231))[:3]
            k = value(node, "Extinction", (3.867, 3.404, 3.009))[:3]
            f0 = tuple(conductor_fresnel(1.0, a, b) for a, b in zip(n, k, strict=True))
            mu = 1.0 / 7.0
            schlick = tuple(f + (1.0 - f) * (1.0 - mu) ** 5 for f in f0)
            f82 = tuple(conductor_fresnel(mu, a, b) for a, b in zip(n, k, strict=True))
            kw = {"base_color": (*f0, 1.0), "edge_tint": tuple(min(max(a / s, 0.0), 1.0) for a, s in
                                                                   zip(f82, schlick, strict=True))}
            self.notes.note("Metallic BSDF Physical Conductor rendered as F82 through its reflectance at 0° and 82°")
        else:
            kw = self._base_colour(mat, node, "Base Color")
            tint = value(node, "Edge Tint", (1.0, 1.0, 1.0, 1.0))
            kw["edge_tint"] = tuple(min(max(float(c), 0.0), 1.0) for c in tint[:3])
            if source(node.inputs.get("Edge Tint")) is not None:
                self.notes.warn(f"material '{mat.name}': Edge Tint from a node (its unlinked value used)")
        self._roughness_into(mat, node, kw, 1.0)
        # the Metallic BSDF's anisotropy is the Principled BSDF's (Cycles' aspect √(1 − 0.9 A))
        self._anisotropy(mat, node, kw, "principled", "Anisotropy", "Rotation")
        self._normal(mat, node, kw)
        return kw

    def _masked_mix(self, mat, node):
        """A Mix Shader whose factor varies over the surface, between two shaders without
        emission or transparency, one of them a single BSDF: that BSDF's material, scattering
        as the other shader's with the factor's probability. The factor is an image (a mask,
        possibly through colour and value nodes: ``mix_weight_texture``) or a Fresnel node or
        Layer Weight output (``mix_weight_angle``, the first shader then a single BSDF). None
        where this does not apply (the factor is then read as a constant, or its unlinked value
        used and listed)."""
        fac = node.inputs[0]
        src = source(fac)
        if src is None:
            return None
        what = f"material '{mat.name}' Mix Shader factor"
        angle = self._angle_factor(mat, *src)
        baked = None
        if angle is None:
            try:
                baked = Evaluator(self.notes, what).evaluate(fac, "float")
            except Unsupported:
                return None
            if baked.constant:
                return None
        parts = []
        for sock in [s for s in node.inputs if s.type == "SHADER"][:2]:
            part, src = ShaderMix(), source(sock)
            if src is not None and self._gather(mat, src[0], 1.0, part, depth=1) is not None:
                return None
            if part.transparency > 0.0 or any(part.emission) or part.emission_texture is not None:
                return None
            parts.append(part)
        first, second = parts
        if len(first.bsdfs) != 1:
            if len(second.bsdfs) != 1 or angle is not None:
                return None
            first, second = second, first
            baked = Baked(1.0 - baked.value, baked.tex_node)
        other = self._add_mix(mat, second, name=f"{mat.name} (varying mix)")
        w, args = first.bsdfs[0]
        args = {**args, "scatter_tint": tuple(float(c) * w for c in args.get("scatter_tint", (1.0, 1.0, 1.0)))}
        args.update(mix_material=other, mix_weight=1.0)
        if angle is not None:
            args["mix_weight_angle"] = angle
        else:
            mask: dict = {}
            self._set_baked(mask, "mix_weight_texture", baked, what)
            args["mix_weight_texture"] = mask["mix_weight_texture"]
            if "uv_transforms" in mask:
                args["uv_transforms"] = {**args.get("uv_transforms", {}), **mask["uv_transforms"]}
        return self.scene.add_material(mat.name, **args)

    def _angle_factor(self, mat, node, out):
        """A Fresnel node or a Layer Weight output (with their own normal) as ``add_material``'s
        ``mix_weight_angle``; None for anything else."""
        if source(node.inputs.get("Normal")) is not None:
            return None
        if node.type == "FRESNEL":
            return ("fresnel", max(self._scalar(mat, node.inputs.get("IOR"), "Fresnel IOR", 1.5), 1e-5))
        if node.type == "LAYER_WEIGHT" and out.name in ("Fresnel", "Facing"):
            blend = min(max(self._scalar(mat, node.inputs.get("Blend"), "Layer Weight blend", 0.5), 0.0), 1.0)
            return ("layer_fresnel" if out.name == "Fresnel" else "layer_facing", blend)
        return None

    def _add_mix(self, mat, mix: ShaderMix, name: str | None = None) -> int:
        """The material for a weighted sum of closures: stochastic coverage of 1 − transparency;
        where covered, emission ÷ coverage, and one BSDF chosen by its share of the total
        weight W (a chain of mix materials), scaled by W ÷ coverage (its scatter tint)."""
        name = mat.name if name is None else name
        coverage = min(max(1.0 - mix.transparency, 0.0), 1.0)
        bsdfs = [(w, kw) for w, kw in mix.bsdfs if w > 0.0]
        total = sum(w for w, _ in bsdfs)
        if coverage <= 1e-6:
            return self.scene.add_material(name, base_color=(0.0, 0.0, 0.0, 0.0), specular=0.0, alpha_mode="blend")
        if not bsdfs:
            bsdfs, total = [(1.0, {"base_color": (0.0, 0.0, 0.0, 1.0), "specular": 0.0})], 0.0
        normals = {kw.get("normal_texture") for _, kw in bsdfs}
        if len(normals) > 1:
            self.notes.warn(f"material '{name}': mixed shaders with different normal maps (the first one's used)")
        scale = total / coverage

        def scaled(kw):
            tint = kw.get("scatter_tint", (1.0, 1.0, 1.0))
            return {**kw, "scatter_tint": tuple(float(c) * scale for c in tint)}

        # the chain, built from its end: each link scatters as the rest with the rest's share
        index, rest = None, 0.0
        for k in range(len(bsdfs) - 1, 0, -1):
            w, kw = bsdfs[k]
            args = scaled(kw)
            if index is not None:
                args.update(mix_material=index, mix_weight=rest / (rest + w))
            index, rest = self.scene.add_material(f"{name} (mix {k})", **args), rest + w
        w, kw = bsdfs[0]
        args = scaled(kw)
        if index is not None:
            args.update(mix_material=index, mix_weight=rest / (rest + w))
        args["emission"] = tuple(c / coverage for c in mix.emission)
        if mix.emission_texture is not None:
            args["emission_texture"] = mix.emission_texture
            if mix.emission_uv is not None:
                args["uv_transforms"] = {**args.get("uv_transforms", {}), "emission_texture": mix.emission_uv}
        args["base_color"] = (*args["base_color"][:3], coverage)
        args["alpha_mode"] = "blend" if coverage < 1.0 else "opaque"
        return self.scene.add_material(name, **args)

    def _diffuse(self, mat, node) -> dict:
        """A Diffuse BSDF: Lambert in its colour."""
        kw = self._base_colour(mat, node, "Color")
        if source(node.inputs.get("Normal")) is not None:
            self.notes.warn(f"material '{mat.name}': Diffuse BSDF normal input ignored")
        return {"roughness": 1.0, "specular": 0.0, **kw}

    def _emission(self, mat, node):
        """(colour, strength, {emission_texture}) of an Emission shader."""
        col = value(node, "Color", (1.0, 1.0, 1.0, 1.0))
        strength = self._scalar(mat, node.inputs.get("Strength"), "emission strength", 1.0)
        kw = {}
        src = source(node.inputs.get("Color"))
        if src is not None:
            if src[0].type == "TEX_IMAGE":
                if self._set_texture(kw, "emission_texture", src[0], f"material '{mat.name}' emission"):
                    col = (1.0, 1.0, 1.0)
            else:
                col = self._baked_emission(mat, node.inputs.get("Color"), kw, col)
        return col, float(strength), kw

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
            kw = {"base_color": (1.0, 1.0, 1.0, 1.0)}
            if not self._set_texture(kw, "base_color_texture", n, f"material '{mat.name}' base colour",
                                     keep_alpha=keep_alpha):
                return {"base_color": MISSING_TEXTURE}
            return kw
        if n.type == "RGB":
            return {"base_color": tuple(out.default_value)}
        geometry_attribute = n.type == "ATTRIBUTE" and n.attribute_type == "GEOMETRY"
        if out.name == "Color" and (n.type == "VERTEX_COLOR" or geometry_attribute):
            # the mesh's colours (added with the mesh) times white
            self._reading = n.layer_name if n.type == "VERTEX_COLOR" else n.attribute_name
            return {"base_color": (1.0, 1.0, 1.0, 1.0)}
        # a chain of colour and value nodes: a constant, or baked over its image
        what = f"material '{mat.name}' base colour"
        try:
            baked = Evaluator(self.notes, what).evaluate(node.inputs.get(name), "color")
        except Unsupported as e:
            self.notes.warn(f"material '{mat.name}': base colour from a {e} node, viewport display colour used")
            return {"base_color": tuple(mat.diffuse_color)}
        kw = {"base_color": (1.0, 1.0, 1.0, 1.0)}
        if not self._set_baked(kw, "base_color_texture", baked, what):
            kw["base_color"] = (*(float(c) for c in baked.value[:3]), 1.0)
        return kw

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
        # a chain of colour and value nodes: a constant, or baked over its image
        try:
            baked = Evaluator(self.notes, f"material '{mat.name}' {what}").evaluate(node.inputs.get(name), "float")
        except Unsupported as e:
            self.notes.warn(f"material '{mat.name}': {what} from a {e} node (its unlinked value used)")
            return float(value(node, name, 0.0)), None
        if baked.constant:
            return float(baked.value[0]), None
        return None, baked

    def _principled(self, mat, node) -> dict:
        """add_material's arguments for a Principled BSDF."""
        name = mat.name
        kw = self._base_colour(mat, node, "Base Color")
        alpha = float(value(node, "Alpha", 1.0))
        alpha_src = source(node.inputs.get("Alpha"))
        textured_alpha = "base_color_texture" in kw and alpha_src is not None and alpha_src[0].type == "TEX_IMAGE"
        if alpha_src is not None and not textured_alpha:
            self.notes.warn(f"material '{name}': alpha from a {alpha_src[0].bl_label} node (its unlinked value used)")
        bc = list(kw["base_color"])
        bc = [*bc, 1.0][:4] if len(bc) < 4 else bc
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
                what = f"material '{name}' metallic/roughness"
                uvs = [self.uv_transform(_tex_node(n), what) for n in (metallic_img, roughness_img) if n is not None]
                if len(uvs) == 2 and uvs[0] != uvs[1]:
                    self.notes.warn(f"{what}: the two images mapped differently (the metallic one's mapping used)")
                if uvs[0] is not None:
                    kw.setdefault("uv_transforms", {})["metallic_roughness_texture"] = uvs[0]
            else:
                kw["metallic"] = metallic if metallic is not None else 0.0
                kw["roughness"] = roughness if roughness is not None else 0.5

        kw["ior"] = float(value(node, "IOR", 1.5))
        kw["specular"] = 2.0 * float(value(node, "Specular IOR Level", 0.5))
        if source(node.inputs.get("Specular IOR Level")) is not None:
            self.notes.warn(f"material '{name}': Specular IOR Level from a node (its unlinked value used)")
        # Specular Tint, as Cycles uses it: the metal's F82 tint, and F0 x tint on the dielectric
        # specular layer (and not on the glass part's reflection, which keeps its own)
        tint = value(node, "Specular Tint", (1.0, 1.0, 1.0, 1.0))
        if isinstance(tint, tuple) and any(abs(t - 1.0) > 1e-6 for t in tint[:3]):
            if kw["metallic"] > 0.0:
                kw["edge_tint"] = tuple(min(max(float(c), 0.0), 1.0) for c in tint[:3])
            if kw["metallic"] < 1.0 or metallic_img is not None:
                kw["specular_tint"] = tuple(max(float(c), 0.0) for c in tint[:3])
                if float(value(node, "Transmission Weight", 0.0)) > 0.0:
                    self.notes.warn(f"material '{name}': Specular Tint on the transmissive part's reflection")
        if source(node.inputs.get("Specular Tint")) is not None:
            self.notes.warn(f"material '{name}': Specular Tint from a node (its unlinked value used)")

        # emission
        ecol = value(node, "Emission Color", (0.0, 0.0, 0.0, 1.0))
        estr = self._scalar(mat, node.inputs.get("Emission Strength"), "Emission Strength", 0.0)
        esrc = source(node.inputs.get("Emission Color"))
        if esrc is not None and esrc[0].type == "TEX_IMAGE":
            if self._set_texture(kw, "emission_texture", esrc[0], f"material '{name}' emission"):
                ecol = (1.0, 1.0, 1.0)
        elif esrc is not None:
            ecol = self._baked_emission(mat, node.inputs.get("Emission Color"), kw, ecol)
        kw["emission"] = tuple(float(c) * estr for c in ecol[:3])

        self._normal(mat, node, kw)

        # transmission: that share of the dielectric part is glass (refracting by IOR)
        kw["transmission"] = min(max(float(value(node, "Transmission Weight", 0.0)), 0.0), 1.0)
        if source(node.inputs.get("Transmission Weight")) is not None:
            self.notes.warn(f"material '{name}': Transmission Weight from a node (its unlinked value used)")

        # the clear coat (Coat Weight, Roughness, IOR, Tint; its own Normal input is not read)
        coat = min(max(float(value(node, "Coat Weight", 0.0)), 0.0), 1.0)
        if coat > 0.0:
            kw["coat_weight"] = coat
            kw["coat_roughness"] = min(max(float(value(node, "Coat Roughness", 0.03)), 0.0), 1.0)
            kw["coat_ior"] = min(max(float(value(node, "Coat IOR", 1.5)), 1.0), 10.0)
            kw["coat_tint"] = tuple(max(float(c), 0.0) for c in value(node, "Coat Tint", (1.0, 1.0, 1.0, 1.0))[:3])
        for inp in ("Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint"):
            if source(node.inputs.get(inp)) is not None:
                self.notes.warn(f"material '{name}': {inp} from a node (its unlinked value used)")
        if coat > 0.0 and source(node.inputs.get("Coat Normal")) is not None:
            self.notes.warn(f"material '{name}': Coat Normal (the coat uses the surface's normal)")

        self._anisotropy(mat, node, kw, "principled", "Anisotropic", "Anisotropic Rotation")

        # lobes glTF/Petzval's BSDF does not have
        for label, inp in (
            ("Sheen", "Sheen Weight"),
            ("Subsurface", "Subsurface Weight"),
            ("Thin film", "Thin Film Thickness"),
        ):
            v = value(node, inp, 0.0)
            if (isinstance(v, float) and v > 0.0) or source(node.inputs.get(inp)) is not None:
                self.notes.warn(f"material '{name}': {label}")
        return kw

    def _anisotropy(self, mat, node, kw: dict, model: str, amount: str, rotation: str) -> None:
        """Anisotropic specular lobes (Cycles' set-up, `model` "principled" or "glossy"): the
        unlinked Anisotropy and Rotation values, and the tangent: unlinked, Cycles' default (the
        radial tangent about the object's Z axis, from its generated coordinates); a Tangent node,
        radial about its axis or along the UV map (the active render one; a named map is listed).
        Anything else on these inputs is listed and its unlinked value used."""
        name = mat.name
        a = value(node, amount, 0.0)
        a = float(a) if isinstance(a, (int, float)) else 0.0
        for inp in (amount, rotation):
            if source(node.inputs.get(inp)) is not None:
                self.notes.warn(f"material '{name}': {inp} from a node (its unlinked value used)")
        if a == 0.0:
            return
        lo = 0.0 if model == "principled" else -1.0
        kw["anisotropic"] = min(max(a, lo), 1.0)
        r = value(node, rotation, 0.0)
        kw["anisotropic_rotation"] = float(r) if isinstance(r, (int, float)) else 0.0
        kw["anisotropy_model"] = model
        tangent = "radial_z"
        tsrc = source(node.inputs.get("Tangent"))
        if tsrc is not None:
            tn = tsrc[0]
            if tn.type == "TANGENT" and tn.direction_type == "RADIAL":
                tangent = "radial_" + tn.axis.lower()
            elif tn.type == "TANGENT" and tn.direction_type == "UV_MAP":
                tangent = "uv_map"
                if tn.uv_map:
                    self.notes.warn(
                        f"material '{name}': Tangent along UV map '{tn.uv_map}' (the active render UV map used)"
                    )
            else:
                self.notes.warn(f"material '{name}': Tangent from a {tn.type} node (the default radial tangent used)")
        kw["anisotropy_tangent"] = tangent

    def _normal(self, mat, node, kw: dict) -> None:
        """A tangent-space Normal Map node with an Image Texture on the shader's Normal input
        (normal_texture, normal_scale in `kw`); anything else there is warned about."""
        name = mat.name
        nsrc = source(node.inputs.get("Normal"))
        if nsrc is not None:
            nn = nsrc[0]
            if nn.type == "NORMAL_MAP" and nn.space == "TANGENT":
                csrc = source(nn.inputs.get("Color"))
                if csrc is not None and csrc[0].type == "TEX_IMAGE":
                    if self._set_texture(kw, "normal_texture", csrc[0], f"material '{name}' normal map"):
                        kw["normal_scale"] = float(value(nn, "Strength", 1.0))
                    if nn.uv_map:
                        self.notes.warn(
                            f"material '{name}': normal map on UV map '{nn.uv_map}' (the active render UV map used)"
                        )
                else:
                    self.notes.warn(f"material '{name}': Normal Map node without an Image Texture")
            else:
                self.notes.warn(
                    f"material '{name}': normal from a {nn.bl_label} "
                    f"node{' (' + nn.space.lower() + ' space)' if nn.type == 'NORMAL_MAP' else ''}"
                )

    def _metallic_roughness(self, mat, m_node, r_node, m_const, r_const):
        """glTF's metallicRoughness texture (G roughness, B metallic) from one or two greyscale
        images (red channel), constants filling the other."""
        what = f"material '{mat.name}' metallic/roughness"

        def make():
            imgs = {}
            for role, n in (("m", m_node), ("r", r_node)):
                if isinstance(n, Baked):
                    imgs[role] = n.value
                elif n is not None:
                    if n.image is None:
                        self.notes.warn(f"{what}: Image Texture node without an image")
                        return None
                    px = image_pixels(n.image, self.notes, what)
                    if px is None:
                        return None
                    imgs[role] = px
            shapes = {p.shape[:2] for p in imgs.values()}
            if len(shapes) > 1:
                self.notes.warn(f"{what}: metallic and roughness images of different sizes (constants used)")
                return None
            h, w = next(iter(shapes))
            out = np.ones((h, w, 4), dtype=np.float32)
            out[..., 0] = 0.0
            out[..., 1] = imgs["r"][..., 0] if "r" in imgs else r_const
            out[..., 2] = imgs["m"][..., 0] if "m" in imgs else m_const
            return out

        # not shared: each BSDF of a material has its own (a material is converted once)
        px = make()
        return None if px is None else self.scene.add_texture(px, name=f"{mat.name} metallic/roughness")
