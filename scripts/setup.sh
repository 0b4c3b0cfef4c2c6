#!/usr/bin/env bash
# Make the project-local environment .venv (Python 3.11, the pinned requirements) and
# build the Rust engine into it in release mode. Safe to run again: each step is
# skipped when its inputs have not changed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
MIN_RUST="1.85"

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

# A python3.11 that really runs (a pyenv shim may exist without the version behind it).
find_python311() {
    local candidate
    for candidate in python3.11 /usr/bin/python3.11 /usr/local/bin/python3.11; do
        if "$candidate" -c 'import sys, venv; assert sys.version_info[:2] == (3, 11)' >/dev/null 2>&1; then
            command -v "$candidate"
            return 0
        fi
    done
    return 1
}

venv_ok() {
    [ -x "$VENV/bin/python" ] &&
        "$VENV/bin/python" -c 'import sys; assert sys.version_info[:2] == (3, 11)' >/dev/null 2>&1
}

make_venv() {
    if venv_ok; then
        say "python: $("$VENV/bin/python" --version) in .venv"
        return
    fi
    local py
    if ! py="$(find_python311)"; then
        apt_install python3.11 python3.11-venv
        py="$(find_python311)" || die "Python 3.11 with venv is still missing after apt-get"
    fi
    say "creating .venv with $py"
    rm -rf "$VENV"
    "$py" -m venv "$VENV"
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

install_requirements() {
    local stamp="$VENV/.requirements.sha256" want
    want="$(sha256sum requirements.txt | cut -d' ' -f1)"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
        say "requirements: up to date"
        return
    fi
    say "installing requirements.txt"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" -m pip install -q -r requirements.txt
    echo "$want" >"$stamp"
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

make_venv
check_rust
install_requirements
build_engine
say "done"
