"""Node-tree helpers shared by the materials, lights and world exporters: the tree Blender renders
with, what is linked into a socket (through reroutes and node groups), the shader feeding an
output, an input's unlinked value (a group node's, for a group's Group Input)."""

from __future__ import annotations


def node_tree_of(idblock):
    """The node tree Blender renders with: always the tree from Blender 5 on (``use_nodes`` is
    deprecated there), else only with ``use_nodes``."""
    import bpy

    if bpy.app.version >= (5, 0, 0):
        return idblock.node_tree
    return idblock.node_tree if idblock.use_nodes else None


# a node group's tree -> the group node last entered through it (its inputs are what the
# group's Group Input node gives; a material is read depth first, so the last one entered is
# the one being read)
_group_of: dict = {}


def forget_groups() -> None:
    """Forgets the group nodes entered (at the start of a scene's conversion)."""
    _group_of.clear()


def _matching(sockets, other):
    """The socket of `sockets` paired with `other` across a group boundary (same identifier,
    else same name)."""
    for s in sockets:
        if s.identifier == other.identifier:
            return s
    return sockets.get(other.name)


def _across(node, out):
    """The socket that feeds `out` of a reroute, of a group node (its Group Output's input,
    entering the group) or of a Group Input (the group node's input); None for other nodes."""
    if node.type == "REROUTE":
        return node.inputs[0]
    if node.type == "GROUP" and node.node_tree is not None:
        gout = next((n for n in node.node_tree.nodes if n.type == "GROUP_OUTPUT" and n.is_active_output), None)
        if gout is None:
            return None
        _group_of[node.node_tree] = node
        return _matching(gout.inputs, out)
    if node.type == "GROUP_INPUT":
        group = _group_of.get(node.id_data)
        return None if group is None else _matching(group.inputs, out)
    return None


def _follow(socket):
    """(node, output socket) of the shading node linked into `socket` through reroutes and node
    groups, else (None, the last unlinked socket on the way: the one whose value counts)."""
    for _ in range(256):
        if socket is None or not socket.is_linked:
            return None, socket
        link = socket.links[0]
        if link.is_muted:
            return None, None
        node, out = link.from_node, link.from_socket
        if node.type not in ("REROUTE", "GROUP", "GROUP_INPUT"):
            return node, out
        nxt = _across(node, out)
        if nxt is None:
            return None, None
        socket = nxt
    return None, None


def source(socket):
    """(node, output socket) linked into `socket`, through reroutes and node groups (into a
    group's output, out through its Group Input); None if unlinked."""
    node, out = _follow(socket)
    return None if node is None else (node, out)


def socket_value(socket, default=None):
    """`socket`'s unlinked value, or the value of the unlinked socket it takes it from through
    reroutes and node groups (a group node's input)."""
    if socket is None:
        return default
    node, last = _follow(socket)
    s = socket if node is not None or last is None or not hasattr(last, "default_value") else last
    if not hasattr(s, "default_value"):
        return default
    v = s.default_value
    try:
        v = tuple(v)
    except TypeError:
        v = float(v)
        # a value socket feeding a colour input (through a group): grey
        if isinstance(default, tuple) and len(default) in (3, 4):
            return (v, v, v, 1.0)[: len(default)]
    return v


def _output_shader(node_tree, socket, output_target):
    """The shader node feeding input `socket` of the active output node, or None."""
    if node_tree is None:
        return None
    out = node_tree.get_output_node(output_target)
    if out is None:
        return None
    src = source(out.inputs.get(socket))
    return src[0] if src else None


def surface_shader(node_tree, output_target="CYCLES"):
    """The shader node feeding the active material/world output's Surface, or None."""
    return _output_shader(node_tree, "Surface", output_target)


def volume_shader(node_tree, output_target="CYCLES"):
    """The shader node feeding the active material output's Volume, or None."""
    return _output_shader(node_tree, "Volume", output_target)


def value(node, name, default=None):
    """The unlinked value of `node`'s input `name` (see `socket_value`), or `default`."""
    return socket_value(node.inputs.get(name), default)
