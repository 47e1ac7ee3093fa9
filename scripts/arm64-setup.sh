#!/usr/bin/env bash
# The README's set-up in the emulated arm64 root (scripts/arm64-root.sh setup runs this):
# 1. the root, made once (scripts/arm64-root.sh make);
# 2. the project's files (tracked and untracked, not ignored) copied to /opt/oricf/src there;
# 3. llama-cpp-python for Arm: compiled once with the build options that scripts/setup.sh
#    picks in the root (scripts/llama-wheel.sh), by Debian's aarch64 cross-compiler on this
#    machine (minutes, where the emulated compiler would take hours), into the wheel cache
#    mounted in the root (~/.cache/oricf/wheels/<key>), where setup.sh finds it;
# 4. scripts/setup.sh in the root, its virtual environment in /opt/oricf/venv, the models
#    from the machine's store (mounted, so checked by sha256 and not downloaded).
# Prints how long each step took. Needs what scripts/arm64-root.sh names, and
# g++-aarch64-linux-gnu and cmake (apt-get install -y g++-aarch64-linux-gnu cmake).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(scripts/arm64-root.sh path)
PY="${ORICF_VENV:-.venv}/bin/python"

die() { printf 'scripts/arm64-setup.sh: %s\n' "$*" >&2; exit 1; }
timed() {  # LABEL CMD...: runs CMD, then says how long it took
    local label=$1 start=$SECONDS
    shift
    "$@"
    printf '==> %s: %d s\n' "$label" $((SECONDS - start))
}

copy_project() {
    rm -rf "$ROOT/opt/oricf/src"
    mkdir -p "$ROOT/opt/oricf/src"
    git ls-files -co --exclude-standard -z | tar --null -T - -c | tar -C "$ROOT/opt/oricf/src" -x
}

llama_wheel() {  # cross-compiles the wheel that setup.sh in the root looks for, if missing
    local build version args wheels
    # What setup.sh will compute in the root: its version, options and cache folder.
    # shellcheck disable=SC2016  # expanded in the root
    build=$(scripts/arm64-root.sh run bash -c \
        'CACHE=/root/.cache/oricf; source scripts/llama-wheel.sh; echo "$LLAMA_VERSION|$CMAKE_ARGS|$LLAMA_WHEELS"')
    IFS='|' read -r version args wheels <<<"$build"
    wheels="${ORICF_CACHE:-$HOME/.cache/oricf}${wheels#/root/.cache/oricf}"  # mounted there
    if ls "$wheels"/llama_cpp_python-"$version"-*linux_aarch64.whl >/dev/null 2>&1; then
        echo "llama-cpp-python $version for Arm: cached in $wheels"; return
    fi
    command -v aarch64-linux-gnu-g++ >/dev/null \
        || die "aarch64-linux-gnu-g++ not found: apt-get install -y g++-aarch64-linux-gnu"
    command -v cmake >/dev/null || die "cmake not found: apt-get install -y cmake"
    [[ -x "$PY" ]] || die "no $PY: run scripts/setup.sh first"
    echo "cross-compiling llama-cpp-python $version for aarch64: $args"
    mkdir -p "$wheels"
    # _PYTHON_HOST_PLATFORM names the wheel's platform (linux_aarch64) for the build backend;
    # the library it holds is loaded by ctypes, so no Python of the target is needed to link.
    _PYTHON_HOST_PLATFORM=linux-aarch64 CMAKE_ARGS="$args -DCMAKE_SYSTEM_NAME=Linux \
        -DCMAKE_SYSTEM_PROCESSOR=aarch64 -DCMAKE_C_COMPILER=aarch64-linux-gnu-gcc \
        -DCMAKE_CXX_COMPILER=aarch64-linux-gnu-g++" \
        "$PY" -m pip wheel --disable-pip-version-check -q --no-cache-dir --no-deps \
        -w "$wheels" "llama-cpp-python==$version" || die "the cross-compiled build failed"
}

timed "arm64 root" scripts/arm64-root.sh make
timed "project copied into the root" copy_project
timed "llama-cpp-python for Arm" llama_wheel
timed "scripts/setup.sh in the root" scripts/arm64-root.sh run scripts/setup.sh "$@"
