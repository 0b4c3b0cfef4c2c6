#!/usr/bin/env bash
# Make the project-local environments and build the Rust engine into the primary one.
#
#   .venv          Python 3.13, requirements.txt (bpy 5.3, the primary test version; Dask's
#                  `distributed` for the farm client and its workers, docs/farm.md), the engine
#                  built in release mode (maturin develop);
#   .venv-X.Y      with --all: one per requirements-X.Y.txt, the second-tier Blender versions
#                  (bpy X.Y on the Python named in that file); the engine comes from the zip.
#
# Safe to run again: each step is skipped when its inputs have not changed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
PRIMARY_PYTHON="3.13"
MIN_RUST="1.89"

say() { echo "setup: $*"; }
die() { echo "setup: error: $*" >&2; exit 1; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

apt_install() {
    command -v apt-get >/dev/null || die "apt-get not found; install $* by hand"
    say "installing $* with apt-get"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q "$@"
}

# A pythonX.Y that really runs (a pyenv shim may exist without the version behind it, and
# pyenv keeps versions that are not selected under its root).
find_python() {  # find_python X.Y
    local want="$1" candidate
    local candidates=("python$want" "/usr/bin/python$want" "/usr/local/bin/python$want")
    if command -v pyenv >/dev/null; then
        candidates+=("$(pyenv root)"/versions/"$want".*/bin/python"$want")
    fi
    for candidate in "${candidates[@]}"; do
        if "$candidate" -c "import sys, venv; assert sys.version_info[:2] == tuple(map(int, '$want'.split('.')))" \
            >/dev/null 2>&1; then
            command -v "$candidate"
            return 0
        fi
    done
    return 1
}

venv_ok() {  # venv_ok DIR X.Y
    [ -x "$1/bin/python" ] &&
        "$1/bin/python" -c "import sys; assert sys.version_info[:2] == tuple(map(int, '$2'.split('.')))" >/dev/null 2>&1
}

make_venv() {  # make_venv DIR X.Y
    local dir="$1" want="$2" py
    if venv_ok "$dir" "$want"; then
        say "python: $("$dir/bin/python" --version) in ${dir#"$ROOT"/}"
        return
    fi
    if ! py="$(find_python "$want")"; then
        if command -v apt-get >/dev/null && apt-cache show "python$want-venv" >/dev/null 2>&1; then
            apt_install "python$want" "python$want-venv"
        fi
        py="$(find_python "$want")" || die "Python $want is needed for ${dir#"$ROOT"/} and was not found \
(not as python$want, nor under pyenv, nor in this system's apt packages): install it, e.g. \
'pyenv install $want', then run this again"
    fi
    say "creating ${dir#"$ROOT"/} with $py"
    rm -rf "$dir"
    "$py" -m venv "$dir"
}

version_at_least() {  # version_at_least HAVE WANT
    [ "$(printf '%s\n%s\n' "$2" "$1" | sort -V | head -n1)" = "$2" ]
}

check_rust() {
    if ! command -v cargo >/dev/null || ! command -v rustc >/dev/null; then
        apt_install cargo rustc
    fi
    local have
    have="$(rustc --version | awk '{print $2}')"
    version_at_least "$have" "$MIN_RUST" ||
        die "rustc $have is too old: the engine needs Rust >= $MIN_RUST (install it with rustup)"
    say "rust: rustc $have"
}

# Headless Chromium for the web viewer's test (tests/test_panorama_web.py: WebGL2 on its SwiftShader).
check_chromium() {
    local found
    found="$(command -v chromium || command -v chromium-browser || true)"
    if [ -z "$found" ] && command -v apt-get >/dev/null; then
        apt_install chromium
        found="$(command -v chromium || true)"
    fi
    if [ -n "$found" ]; then
        say "chromium: $("$found" --version 2>/dev/null | head -n1)"
    else
        say "chromium not found and no apt-get: the web viewer's test skips (and fails with CI=true)"
    fi
}

install_requirements() {  # install_requirements DIR FILE
    local dir="$1" file="$2" stamp="$1/.requirements.sha256" want
    want="$(sha256sum "$file" | cut -d' ' -f1)"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
        say "requirements: ${dir#"$ROOT"/} up to date"
        return
    fi
    say "installing $file into ${dir#"$ROOT"/}"
    "$dir/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip
    # No wheel cache: four bpy wheels would cost ~1.5 GB of disk for nothing on a CI machine.
    "$dir/bin/python" -m pip install -q --disable-pip-version-check --no-cache-dir -r "$file"
    echo "$want" >"$stamp"
}

# The Python a requirements-X.Y.txt names on its `# python: A.B` line.
python_of() {
    sed -n 's/^# python: *\([0-9.]*\).*/\1/p' "$1" | head -n1
}

# The second-tier environments: .venv-X.Y for each requirements-X.Y.txt.
setup_tier2() {
    local file version python
    for file in requirements-[0-9]*.txt; do
        version="${file#requirements-}"
        version="${version%.txt}"
        python="$(python_of "$file")"
        [ -n "$python" ] || die "$file has no '# python: X.Y' line"
        make_venv "$ROOT/.venv-$version" "$python"
        install_requirements "$ROOT/.venv-$version" "$file"
    done
}

# Hash of everything the compiled module is built from.
engine_hash() {
    {
        find native -path native/target -prune -o -type f \
            \( -name '*.rs' -o -name 'Cargo.toml' -o -name 'Cargo.lock' -o -name 'pyproject.toml' \) -print |
            LC_ALL=C sort | xargs sha256sum
        rustc --version
    } | sha256sum | cut -d' ' -f1
}

build_engine() {
    local stamp="$VENV/.engine.sha256" want
    want="$(engine_hash)"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] &&
        "$VENV/bin/python" -c 'import hemishadow._native' >/dev/null 2>&1; then
        say "engine: up to date"
        return
    fi
    say "building the engine (release)"
    # maturin installs into the environment named by VIRTUAL_ENV. It is run from
    # native/ because -m only takes a Cargo.toml, and native/pyproject.toml (which
    # names bindings/Cargo.toml and the python/ sources) is found in the cwd.
    (cd native && VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH" \
        "$VENV/bin/maturin" develop --release)
    "$VENV/bin/python" -c 'import hemishadow._native' ||
        die "the engine was built but 'import hemishadow._native' fails"
    echo "$want" >"$stamp"
}

ALL=0
case "${1:-}" in
    "") ;;
    --all) ALL=1 ;;
    *) die "usage: scripts/setup.sh [--all]   (--all: also the second-tier Blender versions)" ;;
esac

make_venv "$VENV" "$PRIMARY_PYTHON"
check_rust
install_requirements "$VENV" requirements.txt
build_engine
if [ "$ALL" = 1 ]; then   # what only the tests need
    check_chromium
    setup_tier2
fi
say "done"
