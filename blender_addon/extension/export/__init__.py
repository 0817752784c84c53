"""The evaluated depsgraph as a ``petzval.Scene``: meshes, materials, textures, lights, world.

Everything is passed in memory (numpy buffers), in petzval's conventions (see ``_native.pyi``):
glTF axes (Blender (x, y, z) -> (x, z, -y), applied through each object's transform), UVs
(u, 1 - v), image rows top first, linear colour.

One module per concern: ``mesh`` (evaluated meshes as per-corner buffers), ``curves`` (Curves
objects, hair, as tubes), ``materials``
(shaders and their Image Texture nodes), ``images`` (image pixels), ``lights``, ``world``, and
``nodes`` (node-tree helpers); :func:`build` here walks the depsgraph's object instances, and
the engine adds the world with :func:`add_world`.
"""

from __future__ import annotations

import numpy as np

from ..camera import to_gltf
from .curves import curves_data, particle_hair_note
from .lights import add_light
from .materials import Materials
from .mesh import mesh_data
from .world import add_world

__all__ = ["GEOMETRY_TYPES", "UNSUPPORTED_TYPES", "add_world", "build"]

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES"}
UNSUPPORTED_TYPES = {"POINTCLOUD": "point clouds", "VOLUME": "volumes",
                     "GREASEPENCIL": "Grease Pencil", "GPENCIL": "Grease Pencil"}


def _view_layer_flag(obj, method: str, depsgraph) -> bool:
    """The object's holdout / indirect-only state from its collections in the depsgraph's view
    layer (``Object.holdout_get``, ``Object.indirect_only_get``); False where Blender lacks it."""
    get = getattr(getattr(obj, "original", obj), method, None)
    if get is None:
        return False
    try:
        return bool(get(view_layer=depsgraph.view_layer))
    except (TypeError, RuntimeError, ReferenceError):
        return False


def _linking(obj, notes) -> None:
    """Lists an object's (a light's or an emitter's) light and shadow linking, which petzval
    ignores: it lights every object, and every object casts its shadows."""
    linking = getattr(obj, "light_linking", None)
    if linking is None:
        return
    what = "light" if obj.type == "LIGHT" else "object"
    if getattr(linking, "receiver_collection", None) is not None:
        notes.warn(f"{what} '{obj.name}': light linking (it lights every object)")
    if getattr(linking, "blocker_collection", None) is not None:
        notes.warn(f"{what} '{obj.name}': shadow linking (every object casts shadows of its light)")


def build(petzval, depsgraph, notes, stop=None):
    """A ``petzval.Scene`` from the evaluated depsgraph. `stop()` (optional) is polled between
    objects; returns None when it asks to stop. Also returns counts for the status line."""
    pz = petzval.Scene()
    materials = Materials(pz, notes)
    meshes: dict = {}
    # (data-block key, material table) -> petzval mesh id: the mesh is added once and every
    # further instance of it only adds a transform (objects sharing a data-block may still
    # have different object-level material slots, hence the table in the key).
    mesh_ids: dict = {}
    stats = {"objects": 0, "instances": 0, "lights": 0, "meshes_converted": 0}
    for i, inst in enumerate(depsgraph.object_instances):
        if stop is not None and i % 64 == 0 and stop():
            return None, stats
        obj = inst.object
        t = obj.type
        if inst.show_self and (t == "LIGHT" or t in GEOMETRY_TYPES):
            _linking(obj, notes)
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
        hair = particle_hair_note(obj) if t == "MESH" and not inst.is_instance else None
        if hair is not None:
            notes.warn(hair)
        # Camera ray visibility off: the object's materials hidden from camera rays (reflections,
        # bounces and shadows still see it); the other ray types are not separated. The
        # shadow-terminator geometry offset is the object's too.
        visible_to_camera = bool(getattr(obj, "visible_camera", True))
        offset = min(max(float(getattr(obj, "shadow_terminator_geometry_offset", 0.1)), 0.0), 1.0)
        if not all(getattr(obj, f"visible_{ray}", True) for ray in ("shadow", "diffuse", "glossy", "transmission")):
            notes.warn(f"object '{obj.name}': shadow, diffuse, glossy or transmission ray visibility off "
                       "(seen by those rays)")
        if getattr(obj, "is_shadow_catcher", False):
            notes.warn(f"object '{obj.name}': shadow catcher (rendered as an ordinary object)")
        for what, flag in (("holdout", "holdout_get"), ("indirect only", "indirect_only_get")):
            if _view_layer_flag(obj, flag, depsgraph) or (what == "holdout" and getattr(obj, "is_holdout", False)):
                notes.warn(f"object '{obj.name}': {what} (rendered as an ordinary object)")
        slots = obj.material_slots
        if len(slots) == 0:
            table = np.array([materials.default()], dtype=np.uint32)
        else:
            table = np.array([materials.index(s.material) for s in slots], dtype=np.uint32)
        table = np.array([materials.for_object(int(k), visible_to_camera, offset) for k in table], dtype=np.uint32)
        if t == "CURVES":
            _add_curves(pz, obj, inst, table, mesh_ids, meshes, stats)
            continue
        # the colour attribute the object's materials read (one per mesh: the first named)
        wanted = sorted({materials.colour_attribute[int(k)] for k in table if int(k) in materials.colour_attribute})
        if len(wanted) > 1:
            notes.warn(f"object '{obj.name}': materials read different colour attributes ({', '.join(wanted)}); "
                       f"'{wanted[0] or '(default)'}' used for all")
        colour_attribute = wanted[0] if wanted else None
        data = obj.data
        key = data.as_pointer() if data is not None else ("object", obj.name_full)
        md = meshes.get((key, colour_attribute), False)
        if md is False:
            try:
                mesh = obj.to_mesh()
            except RuntimeError:
                mesh = None
            md = None
            if mesh is not None:
                try:
                    md = mesh_data(mesh, colour_attribute, notes.warn)
                finally:
                    obj.to_mesh_clear()
            meshes[(key, colour_attribute)] = md
            stats["meshes_converted"] += 1
        if md is None:
            continue
        xf = to_gltf(inst.matrix_world)
        id_key = (key, tuple(table.tolist()))
        mesh_id = mesh_ids.get(id_key)
        if mesh_id is None:
            mat_ids = table[np.minimum(md.slot_index, len(table) - 1)]
            colours = None
            if md.colours is not None:
                # white on the corners of triangles whose material does not read the colours
                colours = md.colours.copy()
                plain = np.array([int(k) not in materials.colour_attribute for k in mat_ids], dtype=bool)
                colours[md.triangles[plain].ravel()] = 1.0
            mesh_ids[id_key] = pz.add_mesh(md.positions, md.triangles, material_ids=mat_ids, normals=md.normals,
                                           uvs=md.uvs, transform=xf, name=obj.name, colors=colours)
        else:
            pz.add_instance(mesh_id, xf, name=obj.name)
        stats["objects" if not inst.is_instance else "instances"] += 1
    stats["petzval_meshes"] = pz.mesh_count
    stats["petzval_instances"] = pz.instance_count
    return pz, stats


def _add_curves(pz, obj, inst, table, mesh_ids, cache, stats) -> None:
    """A Curves object (hair) as tubes: added once per data-block and material table, placed
    again for every further instance."""
    data = obj.data
    key = ("curves", data.as_pointer() if data is not None else obj.name_full)
    cd = cache.get(key, False)
    if cd is False:
        cd = curves_data(data) if data is not None else None
        cache[key] = cd
        stats["meshes_converted"] += 1
    if cd is None:
        return
    xf = to_gltf(inst.matrix_world)
    id_key = (key, tuple(table.tolist()))
    if id_key not in mesh_ids:
        # every strand with the first slot's material, as Cycles
        mat_ids = np.full(len(cd["counts"]), int(table[0]), dtype=np.int64)
        mesh_ids[id_key] = pz.add_curves(**cd, material_ids=mat_ids, transform=xf, name=obj.name)
    elif mesh_ids[id_key] is not None:
        pz.add_instance(mesh_ids[id_key], xf, name=obj.name)
    if mesh_ids[id_key] is not None:
        stats["objects" if not inst.is_instance else "instances"] += 1
