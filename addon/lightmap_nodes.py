"""The "Hemishadow Lightmap" node group: the HL2 maps combined with a normal map the way the
Source engine does (lightmappedgeneric_ps2_3_x.h): w_i = saturate(dot(n, b_i))^2,
lightmap = sum w_i map_i / sum w_i, n the tangent-space normal decoded from the normal map's
colour (2 c - 1). Its output is in the maps' units (irradiance / pi): times the albedo it is
the diffuse radiance. Made on demand; nothing else in the file changes.
"""

import bpy

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
    from hemishadow.lightmap import HL2  # the engine only once needed (registering never loads it)

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


FRAME_NAME = "Hemishadow Lightmap"


MAPS = ("flat", "b0", "b1", "b2")


def _images_named(prefix):
    return {name: bpy.data.images[f"{prefix}_{name}"] for name in MAPS if f"{prefix}_{name}" in bpy.data.images}


def _newest(images):
    from .lightmaps import BAKED_KEY

    return max((i.get(BAKED_KEY, 0) for i in images.values()), default=-1)


def lightmap_of(obj, uv_name):
    """(images by map name, the UV map reading them, the objects sharing them) of the object's
    newest bake: its own images `hemishadow_<object>_<map>` through `uv_name`, or those of an
    atlas holding it through `hemishadow_lightmap`; ({}, uv_name, []) when not baked."""
    from .lightmap_atlas import ATLAS_UV, OBJECTS_KEY
    from .lightmaps import IMAGE_PREFIX

    best = (_images_named(f"{IMAGE_PREFIX}{obj.name}"), uv_name, [obj.name])
    for image in bpy.data.images:
        members = list(image.get(OBJECTS_KEY, []))
        if obj.name in members and image.name.endswith("_flat"):
            atlas = _images_named(image.name[:-len("_flat")])
            if _newest(atlas) > _newest(best[0]):
                best = (atlas, ATLAS_UV, members)
    return best


def baked_images(obj):
    """The object's baked images by map name ('b0'.., 'flat'), its own or its atlas's; {} when
    not baked."""
    return lightmap_of(obj, None)[0]


def _feeding(socket):
    return socket.links[0].from_socket if socket.is_linked else None


def _normal_colour(bsdf):
    """The colour feeding the Principled BSDF's Normal Map node, or None."""
    normal = bsdf.inputs.get("Normal") if bsdf is not None else None
    source = _feeding(normal) if normal is not None else None
    if source is not None and source.node.type == "NORMAL_MAP":
        return _feeding(source.node.inputs["Color"])
    return None


def add_to_material(mat, obj, uv_name, images=None):
    """Adds, in a frame, the object's baked maps (`images`, by default `baked_images`) on UV map
    `uv_name` combined by the group, times the Base Color (its texture when one feeds it), as an
    Emission into a NEW Material Output made active. Nothing of the material is removed or
    relinked: making the old output active again restores it. Returns False when the frame is
    there already."""
    images = images or baked_images(obj)
    if not images:
        raise ValueError(f"{obj.name}: no baked lightmap images (hemishadow_{obj.name}_*): bake it first")
    if mat.node_tree is None:  # Blender before 5.0: materials without nodes
        mat.use_nodes = True
    tree = mat.node_tree
    if tree.nodes.get(FRAME_NAME) is not None:
        return False
    nodes, links = tree.nodes, tree.links
    frame = nodes.new("NodeFrame")
    frame.name = frame.label = FRAME_NAME
    x0 = max((n.location.x for n in nodes), default=0.0) + 400.0
    made = []

    def new(kind, x, y):
        node = nodes.new(kind)
        node.location = (x0 + x, y)
        made.append(node)
        return node

    uv = new("ShaderNodeUVMap", 0, 0)
    uv.uv_map = uv_name
    textures = {}
    for i, name in enumerate(n for n in ("b0", "b1", "b2", "flat") if n in images):
        texture = new("ShaderNodeTexImage", 250, -300 * i)
        texture.image, texture.interpolation = images[name], "Linear"
        links.new(uv.outputs["UV"], texture.inputs["Vector"])
        textures[name] = texture
    bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
    group = colour = None
    if all(f"b{i}" in textures for i in range(3)):
        group = new("ShaderNodeGroup", 550, 0)
        group.node_tree = lightmap_group()
        for i in range(3):
            links.new(textures[f"b{i}"].outputs["Color"], group.inputs[f"b{i}"])
        colour = _normal_colour(bsdf)
        if colour is not None:
            links.new(colour, group.inputs["Normal Color"])
    # Without a normal map `flat` is exact for the interpolated normal, where the HL2
    # combination is not (0.789 of it under a uniform sky: the b_i are clipped at the
    # surface); the group stays wired to the b_i maps, ready for a normal map.
    light = group.outputs["Lightmap"] if colour is not None else textures["flat"].outputs["Color"]
    times = new("ShaderNodeMix", 800, 0)
    times.data_type, times.blend_type = "RGBA", "MULTIPLY"
    times.inputs["Factor"].default_value = 1.0
    a, b = (next(s for s in times.inputs if s.identifier == f"{k}_Color") for k in "AB")  # the colour sockets
    links.new(light, a)
    base = bsdf.inputs["Base Color"] if bsdf is not None else None
    if base is not None and base.is_linked:
        links.new(_feeding(base), b)
    else:
        b.default_value = tuple(base.default_value) if base is not None else (0.8, 0.8, 0.8, 1.0)
    emission = new("ShaderNodeEmission", 1050, 0)
    result = next(s for s in times.outputs if s.identifier == "Result_Color")
    links.new(result, emission.inputs["Color"])
    output = new("ShaderNodeOutputMaterial", 1300, 0)
    output.name = output.label = "Hemishadow Lightmap Output"
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    for node in made:
        node.parent = frame
    output.is_active_output = True
    return True


def add_to_objects(scene, objects, uv_name):
    """add_to_material for every material of the objects; returns (materials changed,
    warnings). A material used by an object that does not read the same images (one baked
    apart, or not baked) is skipped with a warning: objects of one atlas share materials
    freely. An object without a material gets a new one. Raises ValueError naming an object
    that was not baked (before any change)."""
    for obj in objects:
        if not baked_images(obj):
            raise ValueError(f"{obj.name}: no baked lightmap images (hemishadow_{obj.name}_*): bake it first")
    users = {}
    for other in scene.objects:
        for slot in getattr(other, "material_slots", ()):
            if slot.material is not None:
                users.setdefault(slot.material.name, set()).add(other.name)
    added, warnings = [], []
    for obj in objects:
        if not any(slot.material for slot in obj.material_slots):
            mat = bpy.data.materials.new(f"hemishadow_lightmap_{obj.name}")
            obj.data.materials.append(mat)
            users[mat.name] = {obj.name}
        images, uv, sharing = lightmap_of(obj, uv_name)
        for mat in {slot.material for slot in obj.material_slots if slot.material is not None}:
            others = sorted(users.get(mat.name, set()) - set(sharing))
            if others:
                warnings.append(f"{obj.name}: material '{mat.name}' is shared with {', '.join(others)}: left as it "
                                "is (give the object its own copy of the material)")
            elif add_to_material(mat, obj, uv, images):
                added.append(mat.name)
    return added, warnings
