"""pytest plugin of the second tier: the add-on tests run on the extension zip, installed.

    python -m pytest -p installed_extension --extension-zip dist/hemishadow-...zip tests/addon/...

(with tests/tier2 on PYTHONPATH; scripts/run_tests.py does this for each .venv-X.Y). Before
any test module is imported, the zip is installed into a temporary Blender user folder the
way a user installs it (`extensions.package_install_files`), which puts the engine and
OpenEXR wheels for this Blender's Python on sys.path: the environment itself has neither.
The installed package `bl_ext.user_default.hemishadow` then stands in for `addon`, the name
the tests import the add-on's source by, and is disabled again so that the tests register
and unregister it themselves, as they do with the source. (tests/addon/test_world.py loads
world.py from the source tree by its path; that file is the same as the zip's.)
"""

import importlib
import os
import pathlib
import shutil
import sys
import tempfile

import pytest

MODULE = "bl_ext.user_default.hemishadow"


def pytest_addoption(parser):
    parser.addoption("--extension-zip", required=True, help="the extension zip to install and test")


def _install(zip_path: pathlib.Path) -> dict:
    """Install and enable the zip in a fresh user folder; what was installed from where."""
    user = pathlib.Path(tempfile.mkdtemp(prefix="hemishadow-tier2-"))
    # Read by bpy when it is imported. The wheels' folder must exist at start-up to come
    # ahead of other site-packages on sys.path (tests/addon/test_package.py says why).
    os.environ["BLENDER_USER_RESOURCES"] = str(user)
    python = f"python{sys.version_info.major}.{sys.version_info.minor}"
    site = user / "extensions" / ".local" / "lib" / python / "site-packages"
    site.mkdir(parents=True)
    if "bpy" in sys.modules:
        raise pytest.UsageError("bpy was imported before the extension could be installed")
    import bpy
    import addon_utils  # comes with bpy

    bpy.ops.extensions.package_install_files(filepath=str(zip_path), repo="user_default", enable_on_install=True)
    if tuple(addon_utils.check(MODULE)) != (True, True):
        raise pytest.UsageError(f"{zip_path.name} did not install and enable {MODULE} in Blender "
                                f"{bpy.app.version_string} (Python {sys.version.split()[0]})")
    package = importlib.import_module(MODULE)
    # Blender deletes an extension's wheels when no enabled extension needs them, which the
    # tests' read_factory_settings and unregister cause: the files Blender installed from the
    # zip for this Python are copied first, and imported from the copy.
    if "hemishadow" in sys.modules or "OpenEXR" in sys.modules:
        raise pytest.UsageError("the engine was imported before its wheels could be copied")
    wheels = sorted(p.name for p in site.glob("*.dist-info"))
    copy = user / "installed-wheels"
    shutil.copytree(site, copy)
    sys.path.insert(0, str(copy))
    import hemishadow
    import OpenEXR

    for module in (hemishadow, OpenEXR):
        if not pathlib.Path(module.__file__).is_relative_to(copy):
            raise pytest.UsageError(f"{module.__name__} was imported from {module.__file__}, not from {copy}")
    addon_utils.disable(MODULE, default_set=True)
    return {"package": package, "blender": bpy.app.version_string, "wheels": wheels, "user": user}


@pytest.hookimpl(tryfirst=True)
def pytest_load_initial_conftests(early_config, parser, args):
    # Before the conftest files, which import bpy (a `-p` plugin gets this hook).
    zip_path = pathlib.Path(early_config.known_args_namespace.extension_zip).resolve()
    if not zip_path.is_file():
        raise pytest.UsageError(f"no extension zip at {zip_path}")
    installed = _install(zip_path)
    os.environ["HEMISHADOW_TEST_ZIP"] = str(zip_path)  # tests/addon/test_package.py installs it too
    for name, module in list(sys.modules.items()):
        if name == MODULE or name.startswith(MODULE + "."):
            sys.modules["addon" + name[len(MODULE):]] = module
    early_config._hemishadow_installed = (zip_path, installed)


def pytest_report_header(config):
    zip_path, installed = config._hemishadow_installed
    return (f"second tier: Blender {installed['blender']} (bpy module, Python {sys.version.split()[0]}), "
            f"installed from {zip_path.name}: {MODULE} and {', '.join(installed['wheels'])}")


def pytest_sessionfinish(session, exitstatus):
    session.config._hemishadow_exitstatus = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    import bpy

    # The temporary user folder (11 MB of wheels per run) goes with the session.
    shutil.rmtree(config._hemishadow_installed[1]["user"], ignore_errors=True)
    if bpy.app.version < (5, 0):
        # The bpy module of 4.2 and 4.5 crashes at interpreter exit once a Python property
        # callback or CLI command was registered, even after unregistering (see
        # tests/addon/test_package.py): pytest is done (its report and junit XML are written),
        # so leave with its exit status, without that teardown.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(getattr(config, "_hemishadow_exitstatus", 1))
