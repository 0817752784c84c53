"""Node-tree helpers shared by the materials, lights and world exporters: the tree Blender renders
with, what is linked into a socket (through reroutes), the shader feeding an output, an input's
unlinked value."""

from __future__ import annotations


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
