"""The macOS zips, checked statically (no Mac here): the engine's Mach-O binary is for the
zip's architecture, loads only system libraries (Python's symbols are looked up when Blender
loads it, never from a linked libpython), exports PyInit__native, and asks for no newer macOS
than Blender 4.2 does (11.2); the OpenEXR wheels fit the same architecture and Blender's
two Pythons."""

import struct
import zipfile

import pytest

from zips import engine_wheel, platform_zip, wheels_in

CPU = {"macos-arm64": 0x0100000C, "macos-x64": 0x01000007}  # CPU_TYPE_ARM64, CPU_TYPE_X86_64
ARCH = {"macos-arm64": "arm64", "macos-x64": "x86_64"}
LC_LOAD_DYLIB, LC_LOAD_WEAK_DYLIB, LC_SYMTAB, LC_BUILD_VERSION = 0xC, 0x80000018, 0x2, 0x32
SYSTEM_LIBRARIES = ("/usr/lib/", "/System/Library/Frameworks/")


def mach_o(data):
    """Header, linked libraries, minimum macOS and (name, defined) symbols of a 64-bit Mach-O."""
    magic, cpu, _, filetype, ncmds, _, flags, _ = struct.unpack_from("<IiiIIIII", data, 0)
    assert magic == 0xFEEDFACF, f"not a little-endian 64-bit Mach-O: {magic:#x}"
    libraries, minos, symbols, at = [], None, [], 32
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, at)
        if cmd in (LC_LOAD_DYLIB, LC_LOAD_WEAK_DYLIB):
            (offset,) = struct.unpack_from("<I", data, at + 8)
            libraries.append(data[at + offset:at + size].split(b"\0", 1)[0].decode())
        elif cmd == LC_BUILD_VERSION:
            _, version = struct.unpack_from("<II", data, at + 8)
            minos = (version >> 16, (version >> 8) & 0xFF)
        elif cmd == LC_SYMTAB:
            symoff, nsyms, stroff, _ = struct.unpack_from("<IIII", data, at + 8)
            for i in range(nsyms):
                strx, ntype, _, _, _ = struct.unpack_from("<IBBHQ", data, symoff + 16 * i)
                name = data[stroff + strx:].split(b"\0", 1)[0].decode()
                symbols.append((name, (ntype & 0x0E) == 0x0E))  # N_SECT: defined here
        at += size
    return {"cpu": cpu, "filetype": filetype, "flags": flags, "libraries": libraries, "minos": minos,
            "symbols": symbols}


@pytest.mark.parametrize("platform", ["macos-arm64", "macos-x64"])
def test_engine_binary_fits_the_platform(platform, tmp_path):
    wheel = engine_wheel(platform_zip(platform), tmp_path)
    assert wheel.name.endswith(f"_{ARCH[platform]}.whl") and "-abi3-" in wheel.name, wheel.name
    with zipfile.ZipFile(wheel) as archive:
        (name,) = [n for n in archive.namelist() if n.endswith(".so")]
        assert name == "hemishadow/_native.abi3.so", name
        binary = mach_o(archive.read(name))
    assert binary["cpu"] == CPU[platform], hex(binary["cpu"])
    assert binary["filetype"] in (6, 8), binary["filetype"]  # MH_DYLIB or MH_BUNDLE
    assert binary["libraries"], "links no library at all"
    for library in binary["libraries"]:
        assert library.startswith(SYSTEM_LIBRARIES), f"links a non-system library: {library}"
        assert "python" not in library.lower(), f"links libpython: {library}"
    assert "/usr/lib/libSystem.B.dylib" in binary["libraries"], binary["libraries"]
    assert binary["minos"] is not None and binary["minos"] <= (11, 2), binary["minos"]
    defined = {name for name, is_defined in binary["symbols"] if is_defined}
    undefined = {name for name, is_defined in binary["symbols"] if not is_defined}
    assert "_PyInit__native" in defined
    # Python's C API comes from the Blender that loads it (abi3, no libpython linked).
    assert "_PyModule_Create2" in undefined or "_PyModuleDef_Init" in undefined or \
        any(s.startswith("_Py") for s in undefined)


@pytest.mark.parametrize("platform", ["macos-arm64", "macos-x64"])
def test_zip_has_openexr_for_both_pythons(platform):
    wheels = wheels_in(platform_zip(platform))
    openexr = [w for w in wheels if w.startswith("openexr-")]
    assert sorted(w.split("-")[2] for w in openexr) == ["cp311", "cp313"], wheels
    assert all(w.endswith(f"_{ARCH[platform]}.whl") or w.endswith("_universal2.whl") for w in openexr), wheels
    assert len(wheels) == 3, wheels
