#!/usr/bin/env python3
"""Writes the glTF test fixtures of renderer/tests/gltf.rs into renderer/tests/data/gltf/.

Standard library only (json, struct, base64, zlib for PNG). Deterministic: running it again
rewrites identical files. Usage: python3 tests/scene/make_gltf_fixtures.py
"""

import base64
import json
import math
import struct
import zlib
from pathlib import Path

OUT = Path(__file__).resolve().parents[2] / "renderer" / "tests" / "data" / "gltf"

FLOAT, USHORT, UINT = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
NEAREST, LINEAR = 9728, 9729
REPEAT, CLAMP, MIRROR = 10497, 33071, 33648


def png(width, height, rgba_rows):
    """An 8-bit RGBA PNG from rows of (r, g, b, a) tuples."""

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in rgba_rows)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")


class Builder:
    """Accumulates one binary buffer with views and accessors."""

    def __init__(self):
        self.data = bytearray()
        self.views = []
        self.accessors = []

    def _align(self):
        while len(self.data) % 4:
            self.data.append(0)

    def view(self, blob, target=None):
        self._align()
        v = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(blob)}
        if target:
            v["target"] = target
        self.data += blob
        self.views.append(v)
        return len(self.views) - 1

    def floats(self, rows, type_, minmax=False):
        n = len(rows[0])
        blob = b"".join(struct.pack(f"<{n}f", *r) for r in rows)
        acc = {"bufferView": self.view(blob, ARRAY_BUFFER), "componentType": FLOAT, "count": len(rows), "type": type_}
        if minmax:
            finite = [r for r in rows if all(math.isfinite(x) for x in r)]
            acc["min"] = [min(r[i] for r in finite) for i in range(n)]
            acc["max"] = [max(r[i] for r in finite) for i in range(n)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def indices(self, idx, ctype=USHORT):
        fmt = f"<{len(idx)}H" if ctype == USHORT else f"<{len(idx)}I"
        acc = {"bufferView": self.view(struct.pack(fmt, *idx), ELEMENT_ARRAY_BUFFER), "componentType": ctype,
               "count": len(idx), "type": "SCALAR"}
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def gltf(self, uri, **rest):
        self._align()
        doc = {"asset": {"version": "2.0", "generator": "petzval make_gltf_fixtures.py"}}
        doc.update(rest)
        doc["buffers"] = [{"byteLength": len(self.data)}]
        if uri is not None:
            doc["buffers"][0]["uri"] = uri
        doc["bufferViews"] = self.views
        doc["accessors"] = self.accessors
        return doc


def data_uri(blob, mime="application/octet-stream"):
    return f"data:{mime};base64,{base64.b64encode(bytes(blob)).decode()}"


def write_json(name, doc):
    (OUT / name).write_text(json.dumps(doc, indent=1, allow_nan=True) + "\n")


def glb(doc, bin_blob):
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    bin_blob = bytes(bin_blob) + b"\x00" * (-len(bin_blob) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(bin_blob), 0x004E4942) + bin_blob
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


TRIANGLE = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]


def hierarchy():
    """A rotated + scaled parent with a translated child, a mirrored child, a matrix node and
    an unsupported primitive mode."""
    b = Builder()
    pos = b.floats(TRIANGLE, "VEC3", minmax=True)
    nrm = b.floats([(0.0, 0.0, 1.0)] * 3, "VEC3")
    pos2 = b.floats(TRIANGLE, "VEC3", minmax=True)
    idx = b.indices([0, 1, 2])
    s = math.sin(math.radians(45))
    doc = b.gltf(
        None,
        scene=0,
        scenes=[{"name": "Main", "nodes": [0, 3]}, {"name": "Other", "nodes": [4]}],
        nodes=[
            {"name": "Parent", "translation": [1, 0, 0], "rotation": [0, s, 0, s], "scale": [2, 2, 2],
             "children": [1, 2]},
            {"name": "Child", "translation": [0, 0, 1], "mesh": 0},
            {"name": "Mirror", "scale": [-1, 1, 1], "mesh": 0},
            {"name": "MatrixNode", "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1], "mesh": 1},
            {"name": "NotInDefaultScene", "mesh": 0},
        ],
        meshes=[
            {"name": "Tri", "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm}}]},
            {"name": "NoNormals", "primitives": [
                {"attributes": {"POSITION": pos2}, "indices": idx},
                {"attributes": {"POSITION": pos2}, "mode": 1},
            ]},
        ],
    )
    doc["buffers"][0]["uri"] = data_uri(b.data)
    write_json("hierarchy.gltf", doc)


CHECKER = [
    [(255, 0, 0, 255), (0, 255, 0, 255), (0, 0, 255, 255), (255, 255, 255, 255)],
    [(128, 128, 128, 255), (255, 255, 0, 128), (0, 0, 0, 255), (64, 32, 16, 255)],
]


def quad_geometry(b):
    pos = b.floats([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], "VEC3", minmax=True)
    nrm = b.floats([(0, 0, 1)] * 4, "VEC3")
    tan = b.floats([(1, 0, 0, 1)] * 4, "VEC4")
    uv0 = b.floats([(0, 1), (1, 1), (1, 0), (0, 0)], "VEC2")
    uv1 = b.floats([(0.5, 0.5)] * 4, "VEC2")
    idx = b.indices([0, 1, 2, 0, 2, 3])
    return {"POSITION": pos, "NORMAL": nrm, "TANGENT": tan, "TEXCOORD_0": uv0, "TEXCOORD_1": uv1}, idx


def textured_quad():
    """External .bin and .png files; a full material with the supported extensions."""
    b = Builder()
    attrs, idx = quad_geometry(b)
    (OUT / "checker.png").write_bytes(png(4, 2, CHECKER))
    (OUT / "mr.png").write_bytes(png(1, 1, [[(0, 128, 255, 255)]]))
    doc = b.gltf(
        "quad.bin",
        extensionsUsed=["KHR_materials_emissive_strength", "KHR_materials_specular", "KHR_materials_ior",
                        "KHR_texture_transform", "KHR_materials_clearcoat", "KHR_materials_sheen",
                        "KHR_materials_anisotropy"],
        scenes=[{"nodes": [0]}],
        nodes=[{"name": "Quad", "mesh": 0}],
        meshes=[{"name": "Quad", "primitives": [{"attributes": attrs, "indices": idx, "material": 0}]}],
        materials=[{
            "name": "Checker",
            "pbrMetallicRoughness": {
                "baseColorFactor": [1, 1, 1, 1],
                "baseColorTexture": {"index": 0},
                "metallicFactor": 0.25,
                "roughnessFactor": 0.75,
                "metallicRoughnessTexture": {"index": 1, "texCoord": 1},
            },
            "normalTexture": {"index": 1, "scale": 0.5},
            "emissiveFactor": [1, 0.5, 0.25],
            "emissiveTexture": {
                "index": 0,
                "extensions": {
                    "KHR_texture_transform": {
                        "offset": [0.5, 0.25],
                        "rotation": 1.5707963267948966,
                        "scale": [2, 3],
                        "texCoord": 1,
                    }
                },
            },
            "alphaMode": "MASK",
            "alphaCutoff": 0.3,
            "doubleSided": True,
            "extensions": {
                "KHR_materials_emissive_strength": {"emissiveStrength": 4.0},
                "KHR_materials_specular": {"specularFactor": 0.5},
                "KHR_materials_ior": {"ior": 1.33},
                "KHR_materials_clearcoat": {"clearcoatFactor": 0.75, "clearcoatRoughnessFactor": 0.2,
                                            "clearcoatNormalTexture": {"index": 1}},
                "KHR_materials_sheen": {"sheenColorFactor": [1, 1, 1]},
                "KHR_materials_anisotropy": {"anisotropyStrength": 0.5, "anisotropyRotation": 0.7853981633974483},
            },
        }],
        textures=[{"name": "CheckerTex", "source": 0, "sampler": 0}, {"source": 1, "sampler": 1}],
        images=[{"uri": "checker.png"}, {"uri": "mr.png"}],
        samplers=[{"magFilter": NEAREST, "wrapS": CLAMP, "wrapT": MIRROR}, {"magFilter": LINEAR}],
    )
    (OUT / "quad.bin").write_bytes(bytes(b.data))
    write_json("textured_quad.gltf", doc)


def lights():
    """Point, spot and directional lights with known Blender powers."""
    s = math.sin(math.radians(-45) / 2)  # quaternion of a −45° turn about x
    c = math.cos(math.radians(-45) / 2)
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            # Blender point light of 1000 W: 1000 / (4π) × 683 cd.
            {"name": "Point1000W", "type": "point", "color": [1, 0.5, 0.25], "intensity": 1000 / (4 * math.pi) * 683,
             "range": 20},
            # Blender spot of 500 W, spot_size 1.0 rad, blend 0.6.
            {"name": "Spot500W", "type": "spot", "intensity": 500 / (4 * math.pi) * 683,
             "spot": {"innerConeAngle": 0.5 * (1 - 0.6), "outerConeAngle": 0.5}},
            # Blender sun of 3 W/m².
            {"name": "Sun3", "type": "directional", "color": [1, 1, 0.5], "intensity": 3 * 683},
        ]}},
        "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [
            {"name": "PointNode", "translation": [0, 3, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            # −z rotated by −90° about x points down.
            {"name": "SpotNode", "translation": [1, 2, 3], "rotation": [-math.sqrt(0.5), 0, 0, math.sqrt(0.5)],
             "scale": [5, 5, 5], "extensions": {"KHR_lights_punctual": {"light": 1}}},
            # −z rotated by −45° about x: (0, −sin 45°, −cos 45°).
            {"name": "SunParent", "scale": [0.1, 0.1, 0.1], "children": [3]},
            {"name": "SunNode", "rotation": [s, 0, 0, c], "extensions": {"KHR_lights_punctual": {"light": 2}}},
        ],
    }
    write_json("lights.gltf", doc)


def camera():
    """A perspective camera under a scaled parent, an orthographic one, a camera named only by
    its camera object."""
    a = math.radians(30) / 2
    doc = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0, 2, 3]}],
        "nodes": [
            {"name": "Rig", "scale": [3, 3, 3], "translation": [0, 1, 0], "children": [1]},
            {"name": "MainCam", "camera": 0, "translation": [0, 0, 2], "rotation": [0, math.sin(a), 0, math.cos(a)]},
            {"name": "OrthoNode", "camera": 1},
            {"camera": 2, "translation": [0, 0, 10]},
        ],
        "cameras": [
            {"name": "Lens", "type": "perspective",
             "perspective": {"yfov": 0.6, "aspectRatio": 1.5, "znear": 0.1, "zfar": 100}},
            {"name": "Ortho", "type": "orthographic",
             "orthographic": {"xmag": 1.5, "ymag": -1, "znear": 0, "zfar": 10}},
            {"name": "Unnamed node cam", "type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.01}},
        ],
    }
    write_json("camera.gltf", doc)


def box_glb():
    """A binary glTF: quad geometry and an embedded PNG in the BIN chunk."""
    b = Builder()
    attrs, idx = quad_geometry(b)
    img_view = b.view(png(4, 2, CHECKER))
    doc = b.gltf(
        None,
        scenes=[{"nodes": [0]}],
        nodes=[{"name": "Box", "mesh": 0}],
        meshes=[{"name": "Quad", "primitives": [{"attributes": attrs, "indices": idx, "material": 0}]}],
        materials=[{"name": "Embedded", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        textures=[{"source": 0}],
        images=[{"bufferView": img_view, "mimeType": "image/png", "name": "checker-embedded"}],
    )
    data = glb(doc, b.data)
    (OUT / "box.glb").write_bytes(data)
    (OUT / "truncated.glb").write_bytes(data[: len(data) // 2])


def missing_texture():
    """One image file that does not exist, one data URI that is not an image."""
    b = Builder()
    attrs, idx = quad_geometry(b)
    doc = b.gltf(
        None,
        scenes=[{"nodes": [0]}],
        nodes=[{"mesh": 0}],
        meshes=[{"name": "Quad", "primitives": [{"attributes": attrs, "indices": idx, "material": 0}]}],
        materials=[{"name": "Broken",
                    "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
                    "normalTexture": {"index": 1}}],
        textures=[{"name": "Gone", "source": 0}, {"source": 1}],
        images=[{"uri": "does_not_exist.png"},
                {"uri": data_uri(b"definitely not a PNG", "image/png"), "name": "not-an-image"}],
    )
    doc["buffers"][0]["uri"] = data_uri(b.data)
    write_json("missing_texture.gltf", doc)


def nan_vertices():
    """Three unindexed triangles, the second with a NaN vertex; and a file where all are bad
    (whose POSITION accessor also lacks the min/max the spec asks for: the loader tolerates it)."""
    nan = float("nan")
    rows = [(0, 0, 0), (1, 0, 0), (0, 1, 0),
            (0, 0, 1), (nan, 0, 1), (0, 1, 1),
            (0, 0, 2), (1, 0, 2), (0, 1, 2)]
    b = Builder()
    pos = b.floats(rows, "VEC3", minmax=True)
    doc = b.gltf(None, scenes=[{"nodes": [0]}], nodes=[{"mesh": 0}],
                 meshes=[{"name": "Partly NaN", "primitives": [{"attributes": {"POSITION": pos}}]}])
    doc["buffers"][0]["uri"] = data_uri(b.data)
    write_json("nan_vertices.gltf", doc)

    b = Builder()
    inf = float("inf")
    pos = b.floats([(inf, 0, 0), (1, 0, 0), (0, 1, 0)], "VEC3")
    doc = b.gltf(None, scenes=[{"nodes": [0]}], nodes=[{"mesh": 0}],
                 meshes=[{"name": "All bad", "primitives": [{"attributes": {"POSITION": pos}}]}])
    doc["buffers"][0]["uri"] = data_uri(b.data)
    write_json("all_nan.gltf", doc)


def broken_files():
    """Files that must fail with a clear error."""
    b = Builder()
    pos = b.floats(TRIANGLE, "VEC3", minmax=True)
    idx = b.indices([0, 1, 7])
    doc = b.gltf(None, scenes=[{"nodes": [0]}], nodes=[{"mesh": 0}],
                 meshes=[{"name": "BadMesh", "primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]}])
    doc["buffers"][0]["uri"] = data_uri(b.data)
    write_json("bad_indices.gltf", doc)

    b = Builder()
    pos = b.floats(TRIANGLE, "VEC3", minmax=True)
    doc = b.gltf("missing.bin", scenes=[{"nodes": [0]}], nodes=[{"mesh": 0}],
                 meshes=[{"primitives": [{"attributes": {"POSITION": pos}}]}])
    write_json("missing_buffer.gltf", doc)

    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": "A", "children": [1]}, {"name": "B", "children": [0]}]}
    write_json("cycle.gltf", doc)

    # Deterministic garbage (a linear congruential generator) and a cut-off JSON document.
    x, garbage = 1, bytearray()
    for _ in range(512):
        x = (1103515245 * x + 12345) % (1 << 31)
        garbage.append(x >> 23)
    (OUT / "corrupt.gltf").write_bytes(bytes(garbage))
    text = (OUT / "hierarchy.gltf").read_text()
    (OUT / "truncated.gltf").write_text(text[: len(text) // 3])


def accessors():
    """Interleaved (byteStride) KHR_mesh_quantization attributes, a sparse accessor and
    unsigned-byte indices."""
    SHORT, USHORT_, UBYTE = 5122, 5123, 5121
    verts = [((0, 0, 0), (0, 0)), ((3, 0, 0), (65535, 0)), ((0, 7, 0), (0, 32768))]
    inter = b"".join(struct.pack("<3hxx2H", *p, *uv) for p, uv in verts)
    sparse_idx = struct.pack("<H", 2) + b"\x00\x00"
    sparse_val = struct.pack("<3h", 0, 2, 0) + b"\x00\x00"
    blob = inter + sparse_idx + sparse_val + bytes([0, 1, 2, 0])
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_mesh_quantization"],
        "extensionsRequired": ["KHR_mesh_quantization"],
        "buffers": [{"byteLength": len(blob), "uri": data_uri(blob)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(inter), "byteStride": 12, "target": ARRAY_BUFFER},
            {"buffer": 0, "byteOffset": len(inter), "byteLength": 2},
            {"buffer": 0, "byteOffset": len(inter) + 4, "byteLength": 6},
            {"buffer": 0, "byteOffset": len(inter) + 12, "byteLength": 3, "target": ELEMENT_ARRAY_BUFFER},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": SHORT, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [3, 2, 0],
             "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": USHORT_},
                        "values": {"bufferView": 2}}},
            {"bufferView": 0, "byteOffset": 8, "componentType": USHORT_, "normalized": True, "count": 3,
             "type": "VEC2"},
            {"bufferView": 3, "componentType": UBYTE, "count": 3, "type": "SCALAR"},
        ],
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"name": "Quantized", "primitives": [
            {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}],
    }
    write_json("accessors.gltf", doc)


def vertex_colours():
    """COLOR_0 three ways on one mesh: normalized unsigned bytes (VEC4), floats (VEC3), and a
    primitive without it (white); each primitive a triangle."""
    UBYTE = 5121
    b = Builder()
    tri = b.floats(TRIANGLE, "VEC3", minmax=True)
    rgba = bytes([255, 0, 0, 255, 0, 255, 0, 128, 0, 0, 255, 0])
    acc_bytes = {"bufferView": b.view(rgba, ARRAY_BUFFER), "componentType": UBYTE, "normalized": True,
                 "count": 3, "type": "VEC4"}
    b.accessors.append(acc_bytes)
    c4 = len(b.accessors) - 1
    c3 = b.floats([(0.25, 0.5, 0.75), (2.0, -1.0, 0.5), (0.0, 0.0, 0.0)], "VEC3")
    doc = b.gltf(
        None,
        scenes=[{"nodes": [0]}],
        nodes=[{"mesh": 0}],
        meshes=[{"name": "Painted", "primitives": [
            {"attributes": {"POSITION": tri, "COLOR_0": c4}},
            {"attributes": {"POSITION": tri, "COLOR_0": c3}},
            {"attributes": {"POSITION": tri}},
        ]}],
    )
    doc["buffers"][0]["uri"] = data_uri(b.data)
    write_json("vertex_colours.gltf", doc)


def skinned_rig():
    """skin/rig.gltf: a quad strip of two quads bent by a two-joint skin (the second joint
    animated about x), with one morph target at weight 0.5 animated by a `weights` channel: a
    small seed for the fuzzing of skins and morph targets."""
    b = Builder()
    pos = b.floats([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 1.0, 0.0), (0.0, 2.0, 0.0),
                    (1.0, 2.0, 0.0)], "VEC3", minmax=True)
    idx = b.indices([0, 1, 2, 2, 1, 3, 2, 3, 4, 4, 3, 5])
    weights = b.floats([(1.0, 0.0, 0.0, 0.0)] * 2 + [(0.5, 0.5, 0.0, 0.0)] * 2 + [(0.0, 1.0, 0.0, 0.0)] * 2, "VEC4")
    joints_blob = struct.pack("<24B", *([0, 1, 0, 0] * 6))
    b.accessors.append({"bufferView": b.view(joints_blob, ARRAY_BUFFER), "componentType": 5121, "count": 6,
                        "type": "VEC4"})
    joints = len(b.accessors) - 1
    delta = b.floats([(0.0, 0.0, 0.0)] * 4 + [(0.0, 0.0, 0.5)] * 2, "VEC3")
    ibm_blob = struct.pack("<16f", *[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]) + struct.pack(
        "<16f", *[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -1, 0, 1])
    b.accessors.append({"bufferView": b.view(ibm_blob), "componentType": FLOAT, "count": 2, "type": "MAT4"})
    ibm = len(b.accessors) - 1
    times = b.floats([(0.0,), (1.0,)], "SCALAR", minmax=True)
    rot = b.floats([(0.0, 0.0, 0.0, 1.0), (0.38268343, 0.0, 0.0, 0.92387953)], "VEC4")
    wts = b.floats([(0.0,), (1.0,)], "SCALAR")
    doc = b.gltf(
        None,
        scene=0,
        scenes=[{"nodes": [0, 1, 3]}],
        nodes=[
            {"name": "Strip", "mesh": 0, "skin": 0},
            {"name": "Root", "children": [2]},
            {"name": "Bend", "translation": [0.0, 1.0, 0.0]},
            {"name": "Camera", "camera": 0, "translation": [0.5, 1.0, 4.0]},
        ],
        skins=[{"name": "Rig", "joints": [1, 2], "inverseBindMatrices": ibm}],
        meshes=[{"name": "Strip", "weights": [0.5], "primitives": [
            {"attributes": {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights}, "indices": idx,
             "targets": [{"POSITION": delta}]}]}],
        cameras=[{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
        animations=[{"name": "Bend", "channels": [
            {"sampler": 0, "target": {"node": 2, "path": "rotation"}},
            {"sampler": 1, "target": {"node": 0, "path": "weights"}}],
            "samplers": [{"input": times, "output": rot}, {"input": times, "output": wts}]}],
    )
    doc["buffers"][0]["uri"] = data_uri(b.data)
    (OUT / "skin").mkdir(parents=True, exist_ok=True)
    write_json("skin/rig.gltf", doc)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    skinned_rig()
    vertex_colours()
    hierarchy()
    textured_quad()
    lights()
    camera()
    box_glb()
    missing_texture()
    nan_vertices()
    accessors()
    broken_files()
    print("wrote", len(list(OUT.iterdir())), "files to", OUT)


if __name__ == "__main__":
    main()
