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
# shellcheck source=scripts/llama-wheel.sh
source scripts/llama-wheel.sh     # LLAMA_WHEELS: the folder scripts/setup.sh builds into

mkdir -p compose/.wheels compose/.models
rm -f compose/.wheels/llama_cpp_python-*.whl   # never one built with other options
if ls "$LLAMA_WHEELS"/llama_cpp_python-"$LLAMA_VERSION"-*.whl >/dev/null 2>&1; then
    cp -p "$LLAMA_WHEELS"/llama_cpp_python-"$LLAMA_VERSION"-*.whl compose/.wheels/
fi
echo "==> wheels for .[$EXTRAS] into compose/.wheels"
"$PY" -m pip download -q -d compose/.wheels --find-links compose/.wheels \
    ".[$EXTRAS]" "setuptools>=69" wheel pip
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
