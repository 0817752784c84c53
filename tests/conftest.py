"""Session set-up shared by every suite under tests/.

Blender's Python module (bpy, used by tests/blender and tests/blender_addon) reads its user
directories (preferences, installed extensions, their wheels) from ``BLENDER_USER_RESOURCES``
when it is first imported, and some of them (the ``bl_ext`` extension packages) cannot be moved
afterwards. So, before any suite imports bpy, point them at a fresh directory under tests/out
(unless the caller set one): the add-on suite installs its extension there, and nothing is written
to the home directory.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

BLENDER_USER = Path(__file__).resolve().parent / "out" / "blender_user"

if "BLENDER_USER_RESOURCES" not in os.environ:
    if BLENDER_USER.exists():
        shutil.rmtree(BLENDER_USER)
    BLENDER_USER.mkdir(parents=True)
    os.environ["BLENDER_USER_RESOURCES"] = str(BLENDER_USER)
