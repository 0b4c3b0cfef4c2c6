"""Readers of the attribute layers the add-on writes, shared by the add-on tests."""

import numpy as np


def attribute(obj, name, mesh=None):
    """A color (RGB) or float layer of `mesh` (default: the object's own data) as an array."""
    attr = (mesh or obj.data).attributes[name]
    width = 4 if attr.data_type == "FLOAT_COLOR" else 1
    out = np.empty(len(attr.data) * width, np.float32)
    attr.data.foreach_get("color" if width == 4 else "value", out)
    return out.reshape(-1, width)[:, :3] if width == 4 else out


def sh_layers(obj, prefix):
    """The object's SH coefficient layers (names starting with `prefix`), (N, coeffs, 3)."""
    names = sorted(a.name for a in obj.data.attributes if a.name.startswith(prefix))
    return np.stack([attribute(obj, n) for n in names], axis=1)
