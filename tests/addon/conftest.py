"""Fixtures shared by the add-on tests that load the add-on from source."""

import pathlib
import sys

import pytest

bpy = pytest.importorskip("bpy")

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def addon():
    """The repository's add-on, registered once for the module (as `addon`)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import addon as package

    registered_here = not hasattr(bpy.types.Object, "hemishadow")
    if registered_here:
        package.register()
    yield package
    if registered_here:
        package.unregister()
