"""Which depsgraph the lighting is read from.

In the viewport, Blender copies animated values back onto the original datablocks, so reading
`scene.world` or a lamp object gives this frame's values. During an animation render it does
not: frame_change_post receives the render's depsgraph, and only its evaluated copies hold the
frame's lamp transforms, energies and World inputs. The handlers therefore wrap their work in
`using(depsgraph)`, and the lighting code reads through `of(data)`.
"""

import contextlib

_depsgraph = None


@contextlib.contextmanager
def using(depsgraph):
    global _depsgraph
    previous, _depsgraph = _depsgraph, depsgraph
    try:
        yield
    finally:
        _depsgraph = previous


def depsgraph():
    """The handler's depsgraph, or the context's evaluated one outside handlers."""
    if _depsgraph is not None:
        return _depsgraph
    import bpy

    return bpy.context.evaluated_depsgraph_get()


def of(data):
    """The evaluated copy of an ID in the current depsgraph, or the ID itself outside handlers."""
    if _depsgraph is None or data is None:
        return data
    try:
        return data.evaluated_get(_depsgraph)
    except (RuntimeError, ReferenceError, TypeError):
        return data
