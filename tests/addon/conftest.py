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


@pytest.fixture
def scene():
    """An empty factory scene with the repository's add-on registered for the test and a
    uniform sky (no HDRI projection: fast and exact)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import addon as package

    bpy.ops.wm.read_factory_settings(use_empty=True)
    package.register()
    scene = bpy.context.scene
    scene.hemishadow.lighting_source = "UNIFORM"
    yield scene
    package.unregister()
