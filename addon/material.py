"""The one-click material: a node group "Hemishadow Radiance" that reads the attributes.

Attribute nodes read point attributes the same way in EEVEE and Cycles, in Material Preview
and Rendered mode, and after Subdivision interpolates them, so one group serves all of them.
Group outputs: "Shader" (emission of radiance x Base Color: the self-shadowed result, not lit
again by the scene), "Color" (the same color) and "AO".
"""

import bpy

from .mesh_io import AO, RADIANCE

GROUP_NAME = "Hemishadow Radiance"
MATERIAL_NAME = "Hemishadow"


def _socket(tree, name, in_out, kind):
    return tree.interface.new_socket(name, in_out=in_out, socket_type=kind)


def node_group():
    """The shared node group, created on first use (rebuilt if a user emptied it)."""
    group = bpy.data.node_groups.get(GROUP_NAME)
    if group is not None and group.bl_idname == "ShaderNodeTree" and len(group.nodes):
        return group
    group = group or bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
    base = _socket(group, "Base Color", "INPUT", "NodeSocketColor")
    base.default_value = (1.0, 1.0, 1.0, 1.0)
    strength = _socket(group, "Strength", "INPUT", "NodeSocketFloat")
    strength.default_value = 1.0
    for name, kind in (("Shader", "NodeSocketShader"), ("Color", "NodeSocketColor"), ("AO", "NodeSocketFloat")):
        _socket(group, name, "OUTPUT", kind)

    nodes, links = group.nodes, group.links
    inputs, outputs = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    radiance, ao = nodes.new("ShaderNodeAttribute"), nodes.new("ShaderNodeAttribute")
    radiance.attribute_name, ao.attribute_name = RADIANCE, AO
    multiply = nodes.new("ShaderNodeMix")
    multiply.data_type, multiply.blend_type = "RGBA", "MULTIPLY"
    multiply.inputs["Factor"].default_value = 1.0
    emission = nodes.new("ShaderNodeEmission")
    links.new(radiance.outputs["Color"], multiply.inputs["A"])
    links.new(inputs.outputs["Base Color"], multiply.inputs["B"])
    links.new(multiply.outputs["Result"], emission.inputs["Color"])
    links.new(inputs.outputs["Strength"], emission.inputs["Strength"])
    links.new(emission.outputs["Emission"], outputs.inputs["Shader"])
    links.new(multiply.outputs["Result"], outputs.inputs["Color"])
    links.new(ao.outputs["Fac"], outputs.inputs["AO"])
    for x, node in enumerate((inputs, radiance, multiply, emission, outputs)):
        node.location = (x * 220 - 440, 0)
    ao.location = (-220, -220)
    return group


def _group_node(tree):
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = node_group()
    node.label = GROUP_NAME
    return node


def _output_node(tree):
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeOutputMaterial" and node.is_active_output:
            return node
    return tree.nodes.new("ShaderNodeOutputMaterial")


def emission_material():
    """The material "Hemishadow": the radiance attribute as emission, nothing else."""
    material = bpy.data.materials.get(MATERIAL_NAME)
    if material is None:
        material = bpy.data.materials.new(MATERIAL_NAME)
        _ensure_nodes(material)
        tree = material.node_tree
        for node in list(tree.nodes):
            tree.nodes.remove(node)
        output, group = tree.nodes.new("ShaderNodeOutputMaterial"), _group_node(tree)
        group.location, output.location = (-200, 0), (100, 0)
        tree.links.new(group.outputs["Shader"], output.inputs["Surface"])
    return material


def assign_emission(obj):
    """Show the radiance as is: every material slot of the object gets "Hemishadow" (the old
    materials stay in the file)."""
    material = emission_material()
    if not obj.material_slots:
        obj.data.materials.append(material)
    for slot in obj.material_slots:
        slot.material = material
    return material


def _ensure_nodes(material):
    # Blender 5 materials always have a node tree (and deprecate use_nodes); 4.2 needs it.
    if bpy.app.version < (5, 0, 0) and not material.use_nodes:
        material.use_nodes = True


def _principled(tree):
    return next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"), None)


def multiply_base_color(material):
    """Route the material's Principled Base Color (value or texture link) through the group
    and the group's shader into the output. The BSDF stays in the tree, unlinked, so the
    change is easy to undo by hand. Returns False when the material has no Principled BSDF."""
    _ensure_nodes(material)
    tree = material.node_tree
    bsdf = _principled(tree)
    if bsdf is None:
        return False
    group, output = _group_node(tree), _output_node(tree)
    group.location = (bsdf.location.x, bsdf.location.y + 300)
    base = bsdf.inputs["Base Color"]
    if base.is_linked:
        tree.links.new(base.links[0].from_socket, group.inputs["Base Color"])
    else:
        group.inputs["Base Color"].default_value = base.default_value
    tree.links.new(group.outputs["Shader"], output.inputs["Surface"])
    return True


def assign_multiply(obj):
    """Multiply each material's base color with the radiance; slots without a material (or
    an object without slots) get the emission material. Returns the materials changed."""
    if not obj.material_slots:
        return [assign_emission(obj)]
    changed = []
    for slot in obj.material_slots:
        if slot.material is None or not multiply_base_color(slot.material):
            slot.material = emission_material()
        changed.append(slot.material)
    return changed
