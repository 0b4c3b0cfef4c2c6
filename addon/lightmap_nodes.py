"""The "Hemishadow Lightmap" node group: the HL2 maps combined with a normal map the way the
Source engine does (lightmappedgeneric_ps2_3_x.h): w_i = saturate(dot(n, b_i))^2,
lightmap = sum w_i map_i / sum w_i, n the tangent-space normal decoded from the normal map's
colour (2 c - 1). Its output is in the maps' units (irradiance / pi): times the albedo it is
the diffuse radiance. Made on demand; nothing else in the file changes.
"""

import bpy

from hemishadow.lightmap import HL2

GROUP_NAME = "Hemishadow Lightmap"


def _socket(tree, name, in_out, kind, default=None):
    socket = tree.interface.new_socket(name=name, in_out=in_out, socket_type=kind)
    if default is not None:
        socket.default_value = default
    return socket


def _math(tree, operation, a, b=None, kind="ShaderNodeMath", location=(0, 0)):
    node = tree.nodes.new(kind)
    node.operation = operation
    node.location = location
    tree.links.new(a, node.inputs[0])
    if b is not None:
        if isinstance(b, (int, float, tuple)):
            node.inputs[1].default_value = b
        else:
            tree.links.new(b, node.inputs[1])
    return node


def lightmap_group():
    """The node group (made once, then reused)."""
    tree = bpy.data.node_groups.get(GROUP_NAME)
    if tree is not None:
        return tree
    tree = bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
    _socket(tree, "Normal Color", "INPUT", "NodeSocketColor", (0.5, 0.5, 1.0, 1.0))
    for i in range(3):
        _socket(tree, f"b{i}", "INPUT", "NodeSocketColor", (0.0, 0.0, 0.0, 1.0))
    _socket(tree, "Lightmap", "OUTPUT", "NodeSocketColor")
    inputs = tree.nodes.new("NodeGroupInput")
    outputs = tree.nodes.new("NodeGroupOutput")
    decode = tree.nodes.new("ShaderNodeVectorMath")
    decode.operation = "MULTIPLY_ADD"
    tree.links.new(inputs.outputs["Normal Color"], decode.inputs[0])
    decode.inputs[1].default_value = (2.0, 2.0, 2.0)
    decode.inputs[2].default_value = (-1.0, -1.0, -1.0)
    normal = _math(tree, "NORMALIZE", decode.outputs[0], kind="ShaderNodeVectorMath")
    total_weight, total = None, None
    for i in range(3):
        dot = _math(tree, "DOT_PRODUCT", normal.outputs[0], tuple(float(x) for x in HL2[i]), "ShaderNodeVectorMath")
        clamped = _math(tree, "MAXIMUM", dot.outputs["Value"], 0.0)
        weight = _math(tree, "MULTIPLY", clamped.outputs[0], clamped.outputs[0])
        scaled = tree.nodes.new("ShaderNodeVectorMath")
        scaled.operation = "SCALE"
        tree.links.new(inputs.outputs[f"b{i}"], scaled.inputs[0])
        tree.links.new(weight.outputs[0], scaled.inputs["Scale"])
        total = scaled if total is None else _math(tree, "ADD", total.outputs[0], scaled.outputs[0],
                                                   "ShaderNodeVectorMath")
        total_weight = weight if total_weight is None else _math(tree, "ADD", total_weight.outputs[0],
                                                                 weight.outputs[0])
    guarded = _math(tree, "MAXIMUM", total_weight.outputs[0], 1e-6)
    inverse = tree.nodes.new("ShaderNodeMath")
    inverse.operation = "DIVIDE"
    inverse.inputs[0].default_value = 1.0
    tree.links.new(guarded.outputs[0], inverse.inputs[1])
    result = tree.nodes.new("ShaderNodeVectorMath")
    result.operation = "SCALE"
    tree.links.new(total.outputs[0], result.inputs[0])
    tree.links.new(inverse.outputs[0], result.inputs["Scale"])
    tree.links.new(result.outputs[0], outputs.inputs["Lightmap"])
    return tree
