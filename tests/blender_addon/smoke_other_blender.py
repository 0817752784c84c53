"""Smoke test of the extension zip in another Blender (not run by tests/run, which uses bpy
5.0.1): installs the zip the way a user would, renders a small scene with a library lens and a
tilted sensor through the PETZVAL engine, and checks the saved EXR.

    python3.11 -m venv /tmp/bpy42 && /tmp/bpy42/bin/pip install "bpy==4.2.0" "numpy<2"
    /tmp/bpy42/bin/python tests/blender_addon/smoke_other_blender.py target/blender/petzval-0.1.0.zip

Last run: Blender 4.2.0 (bpy 4.2.0 from PyPI, Python 3.11), 2026-11-22: installed, rendered
96×64 at 8 spp through double-gauss-50mm in 1.3 s, mean 0.130, every pixel finite.
"""

import os
import sys
import tempfile
import time

ZIP = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else "target/blender/petzval-0.1.0.zip")
USER = tempfile.mkdtemp(prefix="petzval-blender-user-")
os.environ["BLENDER_USER_RESOURCES"] = USER  # before bpy is imported: nothing lands in ~

import bpy  # noqa: E402
import numpy as np  # noqa: E402

print("Blender", bpy.app.version_string)
assert bpy.ops.extensions.package_install_files(filepath=ZIP, repo="user_default", enable_on_install=True) == {
    "FINISHED"
}
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.preferences.addon_enable(module="bl_ext.user_default.petzval")
scene = bpy.context.scene
bpy.ops.mesh.primitive_plane_add(size=10)
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0, 0, 0.5))
bpy.ops.object.light_add(type="SUN", location=(0, 0, 5))
bpy.ops.object.camera_add(location=(0, -4, 1.5), rotation=(1.3, 0, 0))
scene.camera = bpy.context.object
cam = scene.camera.data
cam.dof.use_dof = True
cam.dof.focus_distance = 4.0
cam.dof.aperture_fstop = 2.8
lens_items = cam.petzval.bl_rna.properties["lens"].enum_items
cam.petzval.lens = next(i.identifier for i in lens_items if "double-gauss-50mm" in (i.identifier + i.name))
cam.petzval.tilt_x = 3.0
scene.render.engine = "PETZVAL"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 96, 64, 100
scene.petzval.samples = 8
out = os.path.join(USER, "smoke.exr")
scene.render.filepath = out
scene.render.image_settings.file_format = "OPEN_EXR"
t = time.time()
bpy.ops.render.render(write_still=True)
img = bpy.data.images.load(out)
px = np.array(img.pixels[:]).reshape(64, 96, 4)
print(f"rendered in {time.time() - t:.1f} s; mean {px[..., :3].mean():.3f}; finite {np.isfinite(px).all()}")
assert np.isfinite(px).all() and 0.01 < px[..., :3].mean() < 10
print("ok")
