"""A scene of the built-in demo's kind for the Cycles comparison (bpy 5.0.1, built from code).

The built-in demo (renderer/src/scene/demo.rs) is a miniature street on a table top at dusk:
rows of small lamps on posts receding into the distance, a string of lights across the street,
houses with lit windows, a checkered wooden table, a dim sky and a weak moon. Cycles cannot
render the demo itself (it is built in Rust, and its real lens and tilted sensor have no Cycles
equivalent), so this module builds the same street in Blender, with the demo's generator (the
same hash for the houses' sizes and windows, the same lamp rows and garland), and a Blender
camera with Blender's thin lens where the demo has double-gauss-50mm:

* ``StreetCam``: 50 mm on a 36 mm sensor, f/2.1, focus 0.55 m, 7 blades rotated 10°, low over
  the table looking down the street (the demo's eye and target), 240 x 160.
* Materials are Lambert (Principled, Specular IOR Level 0), as in blender_scenes.py: the
  comparison is about light transport, not the two renderers' specular layers, which differ
  by design. Emitters (lamps: strength 60, warm and cool; windows: strength 4) have a black
  base.
* The moon is a sun of 0.35 W/m² (the demo's irradiance (0.25, 0.27, 0.35)), the sky a
  constant world colour (0.035, 0.045, 0.08).

Blender is Z-up; the demo is Y-up: a demo point (x, y, z) is Blender's (x, −z, y).

Run directly (``python tests/blender/street_scene.py OUT_DIR``) it writes ``street.glb`` and
prints the matching ``petzval render`` options.
"""

from __future__ import annotations

import math
from pathlib import Path

import blender_scenes as S

RESOLUTION = (240, 160)
WORLD_RGB = (0.035, 0.045, 0.08)
CAMERA = S.CameraSpec(
    name="StreetCam",
    location=(0.0, -0.55, 0.09),
    target=(0.0, 0.4, 0.02),
    lens_mm=50.0,
    sensor_mm=36.0,
    fstop=2.1,
    focus_m=0.55,
    blades=7,
    rotation_deg=10.0,
)
# Emission (linear RGB radiance, as the demo's materials): colour x strength.
LAMP_WARM = ((1.0, 38.0 / 60.0, 16.0 / 60.0), 60.0)
LAMP_COOL = ((25.0 / 60.0, 35.0 / 60.0, 1.0), 60.0)
WINDOW = ((1.0, 0.65, 0.25), 4.0)
MOON_DIRECTION = (0.3, 0.4, -1.0)  # the demo's (0.3, −1, −0.4), Blender axes
MOON = ((0.25 / 0.35, 0.27 / 0.35, 1.0), 0.35)

_M32 = 0xFFFFFFFF


def _hash_u32(x: int) -> int:
    """renderer/src/sampler.rs hash_u32."""
    x &= _M32
    x ^= x >> 16
    x = (x * 0x7FEB352D) & _M32
    x ^= x >> 15
    x = (x * 0x846CA68B) & _M32
    x ^= x >> 16
    return x


def _rand01(i: int) -> float:
    """demo.rs rand01: the demo's deterministic variety."""
    return (_hash_u32((i * 0x27D4EB2D) & _M32) >> 8) / float(1 << 24)


def _b(p) -> tuple[float, float, float]:
    """A demo (Y-up) point in Blender's axes (Z-up)."""
    return (p[0], -p[2], p[1])


class _Batch:
    """The triangles of one material, gathered into one mesh object."""

    def __init__(self):
        self.verts: list[tuple[float, float, float]] = []
        self.faces: list[tuple[int, ...]] = []
        self.smooth: list[bool] = []
        self.uvs: list[tuple[float, float]] = []  # per face corner, when the batch has UVs

    def add(self, pts, tris, smooth=False, uvs=None):
        base = len(self.verts)
        self.verts.extend(_b(p) for p in pts)
        for t in tris:
            self.faces.append(tuple(base + i for i in t))
            self.smooth.append(smooth)
            if uvs is not None:
                self.uvs.extend(uvs[i] for i in t)

    def box(self, centre, size):
        """An axis-aligned box (demo axes), flat shaded."""
        (cx, cy, cz), (sx, sy, sz) = centre, size
        pts = [
            (cx + dx * sx / 2, cy + dy * sy / 2, cz + dz * sz / 2) for dx in (-1, 1) for dy in (-1, 1) for dz in (-1, 1)
        ]
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        # outward winding in the demo's (right-handed) axes; the axis swap to Blender's keeps it
        self.add(pts, [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])

    def quad(self, corners, uvs=None):
        """A quad (counter-clockwise seen from the front), as two triangles."""
        self.add(corners, [(0, 1, 2), (0, 2, 3)], uvs=uvs)

    def sphere(self, centre, radius, rings, segments):
        """A UV sphere (poles on the demo's y axis), smooth shaded."""
        pts = [(centre[0], centre[1] + radius, centre[2])]
        for i in range(1, rings):
            th = math.pi * i / rings
            for j in range(segments):
                ph = 2 * math.pi * j / segments
                n = (math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph))
                pts.append(tuple(c + radius * k for c, k in zip(centre, n, strict=True)))
        pts.append((centre[0], centre[1] - radius, centre[2]))
        last = len(pts) - 1

        def ring(i, j):
            return 1 + (i - 1) * segments + j % segments

        tris = [(0, ring(1, j + 1), ring(1, j)) for j in range(segments)]
        for i in range(1, rings - 1):
            for j in range(segments):
                a, b = ring(i, j), ring(i, j + 1)
                c, d = ring(i + 1, j), ring(i + 1, j + 1)
                tris += [(a, b, d), (a, d, c)]
        tris += [(last, ring(rings - 1, j), ring(rings - 1, j + 1)) for j in range(segments)]
        self.add(pts, tris, smooth=True)

    def to_object(self, bpy, name, material):
        me = bpy.data.meshes.new(name)
        me.from_pydata(self.verts, [], self.faces)
        if self.uvs:
            layer = me.uv_layers.new(name="UVMap")
            for k, uv in enumerate(self.uvs):
                layer.data[k].uv = uv
        for poly, smooth in zip(me.polygons, self.smooth, strict=True):
            poly.use_smooth = smooth
        me.update()
        obj = bpy.data.objects.new(name, me)
        bpy.context.scene.collection.objects.link(obj)
        obj.data.materials.append(material)
        return obj


def _table_image(bpy, tmpdir: Path):
    """The demo's 256² wood checker (linear texels), as an 8-bit sRGB PNG packed into the file."""
    import numpy as np

    n = 256
    y, x = np.indices((n, n), dtype=np.float64)
    board = ((x // 32 + y // 32) % 2) == 0
    grain = 0.85 + 0.15 * (np.sin(x * 0.31 + np.sin(y * 0.05) * 4.0) * 0.5 + 0.5)
    light, dark = np.array([0.42, 0.25, 0.12]), np.array([0.30, 0.17, 0.08])
    lin = np.where(board[..., None], light, dark) * grain[..., None]
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    rgb8 = np.round(np.clip(srgb, 0, 1) * 255) / 255
    rgba = np.concatenate([rgb8[::-1], np.ones((n, n, 1))], axis=-1).astype(np.float32)  # Blender: row 0 at the bottom
    img = bpy.data.images.new("Table", n, n, alpha=False)
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = str(tmpdir / "table.png")
    img.file_format = "PNG"
    img.save()
    img.pack()
    img.colorspace_settings.name = "sRGB"
    return img


def build_scene(tmpdir: Path) -> S.BuiltScene:
    """Resets Blender and builds the street (see the module docstring)."""
    bpy = S._import_bpy()
    tmpdir.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    S.set_world_colour(bpy, scene, WORLD_RGB)

    # 1. Materials (the demo's colours; Lambert).
    table_mat = S._principled(bpy, "table", image=_table_image(bpy, tmpdir))
    table_mat.node_tree.nodes["Image Texture"].interpolation = "Linear"
    mats = {"table": table_mat, "street": S._principled(bpy, "street", base=(0.08, 0.08, 0.09))}
    houses = [(0.7, 0.62, 0.5), (0.55, 0.2, 0.15), (0.8, 0.78, 0.7), (0.3, 0.4, 0.55), (0.6, 0.5, 0.25)]
    for i, c in enumerate(houses):
        mats[f"house{i}"] = S._principled(bpy, f"house{i}", base=c)
    for name, (rgb, strength) in (("lamp-warm", LAMP_WARM), ("lamp-cool", LAMP_COOL), ("window", WINDOW)):
        mats[name] = S._principled(bpy, name, base=(0.0, 0.0, 0.0), emission=rgb, strength=strength)
    mats["post"] = S._principled(bpy, "post", base=(0.05, 0.05, 0.05))
    batches = {name: _Batch() for name in mats}

    # 2. Table top and the street running away from the camera.
    batches["table"].quad(
        [(-2.0, 0.0, 1.0), (2.0, 0.0, 1.0), (2.0, 0.0, -4.0), (-2.0, 0.0, -4.0)],
        uvs=[(0.0, 1.0 - 10.0), (8.0, 1.0 - 10.0), (8.0, 1.0), (0.0, 1.0)],  # glTF v is Blender's 1 - v
    )
    batches["street"].quad([(-0.06, 0.001, 0.4), (0.06, 0.001, 0.4), (0.06, 0.001, -3.0), (-0.06, 0.001, -3.0)])

    # 3. Houses on both sides, some with a lit window facing the street.
    k = 0
    for side in (-1.0, 1.0):
        z = 0.25
        while z > -3.0:
            k += 1
            w = 0.05 + 0.05 * _rand01(k)
            d = 0.05 + 0.04 * _rand01(k + 100)
            h = 0.04 + 0.10 * _rand01(k + 200)
            x = side * (0.11 + d * 0.5 + 0.02 * _rand01(k + 300))
            batches[f"house{(k % 5)}"].box((x, h * 0.5, z - w * 0.5), (d, h, w))
            if _rand01(k + 400) > 0.35:
                wx, wy, s, zc = x - side * (d * 0.5 + 0.0005), h * 0.55, 0.008, z - w * 0.5
                if side < 0:
                    corners = [(wx, wy - s, zc + s), (wx, wy - s, zc - s), (wx, wy + s, zc - s), (wx, wy + s, zc + s)]
                else:
                    corners = [(wx, wy - s, zc - s), (wx, wy - s, zc + s), (wx, wy + s, zc + s), (wx, wy + s, zc - s)]
                batches["window"].quad(corners)
            z -= w + 0.01 + 0.02 * _rand01(k + 500)

    # 4. Lamps on posts along the street, and a string of lights across it.
    lamp = ("lamp-warm", "lamp-cool")
    i, z = 0, 0.2
    while z > -3.0:
        for side in (-1.0, 1.0):
            x = side * 0.085
            batches["post"].box((x, 0.025, z), (0.003, 0.05, 0.003))
            batches[lamp[i % 2]].sphere((x, 0.053, z), 0.0035, 8, 12)
        i += 1
        z -= 0.12
    for j in range(24):
        x = -0.3 + 0.6 * j / 23.0
        batches[lamp[j % 2]].sphere((x, 0.16 - 0.04 * (1.0 - (x / 0.3) ** 2), -1.2), 0.003, 6, 10)
    for name, batch in batches.items():
        if batch.faces:
            batch.to_object(bpy, name, mats[name])

    # 5. The moon.
    moon = bpy.data.lights.new("Moon", "SUN")
    moon.color, moon.energy, moon.angle = MOON[0], MOON[1], 0.0
    obj = bpy.data.objects.new("Moon", moon)
    scene.collection.objects.link(obj)
    obj.location = (0.0, 0.0, 2.0)
    obj.rotation_mode = "QUATERNION"
    aim = tuple(a + b for a, b in zip(obj.location, MOON_DIRECTION, strict=True))
    obj.rotation_quaternion = S._look_at_quat(obj.location, aim)

    # 6. The camera.
    built = S.BuiltScene(blender_version=bpy.app.version_string)
    S._add_camera(bpy, CAMERA)
    built.cameras[CAMERA.name] = CAMERA
    scene.camera = bpy.data.objects[CAMERA.name]
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    return built


def petzval_args(bokeh_paths: str = "auto") -> list[str]:
    """`petzval render` options for StreetCam (Blender's camera as it is: see
    blender_scenes.petzval_cycles_args) with the street's world and Cycles' bounce limit."""
    return [
        *S.petzval_cycles_args(CAMERA),
        "--environment", ",".join(S._num(c) for c in WORLD_RGB),
        "--max-depth", str(S.PETZVAL_MAX_DEPTH),
        "--resolution", "x".join(map(str, RESOLUTION)),
        "--bokeh-paths", bokeh_paths,
    ]  # fmt: skip


if __name__ == "__main__":
    import sys

    out = Path(sys.argv[1] if len(sys.argv) > 1 else "tests/out/street")
    build_scene(out)
    glb = S.export_glb(out / "street.glb")
    print(glb)
    print(" ".join(petzval_args()))
