#!/usr/bin/env bash
# Fills the optional, git-ignored build context of compose/Dockerfile from this machine, so an
# image builds in minutes and without a package index:
#   compose/.wheels/  the llama-cpp-python wheel that scripts/setup.sh built once for this CPU
#                     (~/.cache/oricf/wheels/<key>/, scripts/llama-wheel.sh), plus every other wheel the image
#                     installs (pip download), for building with PIP_OPTIONS=--no-index
#   compose/.models/  the models named in MODELS, copied from the local model store
#                     (the image build still checks each file's sha256)
#
#   compose/prepare-build.sh                     the edge image: asr,llm and its five models
#   compose/prepare-build.sh EXTRAS [MODEL ...]  e.g. `ros` (the gateway image: no models)
#
# The llama.cpp wheel is compiled for this machine's CPU: an image made with it runs on CPUs
# of the same kind. Leave compose/.wheels empty to compile inside the build instead.
# Wheels are for the Python of .venv: use them only with a base image of the same version.
# ORICF_ARCH (Debian's name, e.g. arm64) prepares an image of another architecture: the
# llama-cpp-python wheel built for it without a CPU's extensions (scripts/arm64-setup.sh
# makes the arm64 one) and that architecture's wheels of everything else.
set -euo pipefail
cd "$(dirname "$0")/.."
if (($#)); then
    EXTRAS="$1"; shift
    MODELS=("$@")
else
    EXTRAS="asr,llm"
    MODELS=(yolox-nano whisper-tiny-en gemma3-270m piper-joe-medium pybullet-hopper)
fi
PY="${ORICF_VENV:-.venv}/bin/python"
CACHE="${ORICF_CACHE:-$HOME/.cache/oricf}"
HOST_ARCH=$(dpkg --print-architecture)
ARCH="${ORICF_ARCH:-$HOST_ARCH}"
# For another architecture, the options scripts/llama-wheel.sh picks for it (it reads
# ORICF_ARCH too) with no CPU to read: no extension of one CPU in an image for all.
[[ "$ARCH" != "$HOST_ARCH" ]] && export ORICF_CPUINFO=/dev/null
# shellcheck source=scripts/llama-wheel.sh
source scripts/llama-wheel.sh     # LLAMA_WHEELS: the folder scripts/setup.sh builds into

mkdir -p compose/.wheels compose/.models
rm -f compose/.wheels/llama_cpp_python-*.whl   # never one built with other options
if ls "$LLAMA_WHEELS"/llama_cpp_python-"$LLAMA_VERSION"-*.whl >/dev/null 2>&1; then
    cp -p "$LLAMA_WHEELS"/llama_cpp_python-"$LLAMA_VERSION"-*.whl compose/.wheels/
fi
PLATFORM=()
if [[ "$ARCH" != "$HOST_ARCH" ]]; then
    # Another architecture's wheels, for .venv's Python: binary only (nothing is built
    # here for it), each manylinux level up to Debian bookworm's glibc 2.36.
    case "$ARCH" in arm64) machine=aarch64 ;; amd64) machine=x86_64 ;; *) machine=$ARCH ;; esac
    for tag in linux manylinux2014 manylinux_2_{17,24,26,27,28,31,34,35,36}; do
        PLATFORM+=(--platform "${tag}_$machine")
    done
    py=$("$PY" -c 'import sys; print("%d%d" % sys.version_info[:2])')
    PLATFORM+=(--only-binary=:all: --python-version "$py" --implementation cp --abi "cp$py")
fi
echo "==> wheels for .[$EXTRAS] ($ARCH) into compose/.wheels"
"$PY" -m pip download -q -d compose/.wheels --find-links compose/.wheels \
    "${PLATFORM[@]+"${PLATFORM[@]}"}" ".[$EXTRAS]" "setuptools>=69" wheel pip
rm -f compose/.wheels/oricf-*     # the project itself is built from source in the image

echo "==> models into compose/.models: ${MODELS[*]:-none}"
STORE=$("$PY" -c 'from oricf.store import ModelStore; print(ModelStore().root)')
for name in "${MODELS[@]+"${MODELS[@]}"}"; do
    "$PY" -c 'import sys; from oricf.store import ModelStore; ModelStore().path(sys.argv[1])' "$name"
    rm -rf "compose/.models/$name"
    # hard links when the store is on the same file system: no copy of 100s of MB
    cp -a -l "$STORE/$name" compose/.models/ 2>/dev/null || cp -a "$STORE/$name" compose/.models/
done
du -sh compose/.wheels compose/.models
