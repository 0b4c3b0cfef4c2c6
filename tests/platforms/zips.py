"""Helpers of the platform tests (`make test-platforms`): the per-platform zips of
`scripts/build_extension.py --platforms all` and the wheels inside them."""

import pathlib
import tomllib
import zipfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def platform_zip(platform):
    with open(ROOT / "blender_manifest.toml", "rb") as fh:
        manifest = tomllib.load(fh)
    path = ROOT / "dist" / f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"
    if not path.is_file():
        pytest.skip(f"{path.name} is not built: make test-platforms builds it")
    return path


def wheels_in(zip_path):
    with zipfile.ZipFile(zip_path) as archive:
        return sorted(pathlib.PurePosixPath(n).name for n in archive.namelist() if n.endswith(".whl"))


def extract_member(zip_path, suffix_or_name, dest):
    """Extract the one member of zip_path whose name ends with suffix_or_name into dest."""
    with zipfile.ZipFile(zip_path) as archive:
        (name,) = [n for n in archive.namelist() if n.endswith(suffix_or_name)]
        return pathlib.Path(archive.extract(name, dest))


def engine_wheel(zip_path, dest):
    (name,) = [w for w in wheels_in(zip_path) if w.startswith("hemishadow-")]
    return extract_member(zip_path, "/" + name, dest)
