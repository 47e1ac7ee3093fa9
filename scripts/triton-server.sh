#!/usr/bin/env bash
# NVIDIA Triton Inference Server serving YOLOX-Nano (scripts/triton_yolox.py): the
# tritonserver binary and its Python back end that PyPI's nvidia-pytriton bundles, with
# onnxruntime running the catalog's ONNX file. Triton's environment is its own (about
# 600 MB, in $ORICF_TRITON_DIR, default ~/.cache/oricf/triton), never ORICF's .venv.
#
#   scripts/triton-server.sh --install     # once (needs glibc 2.35+, x86-64 or arm64)
#   scripts/triton-server.sh [--grpc-port 8001] [--http-port 8000] [--restrict-shared-memory]
#                            [--access-token-file FILE]
#
# The model file comes from ORICF's model store: `oricf models pull yolox-nano`.
set -euo pipefail

PYTRITON_VERSION="0.7.0"
DIR="${ORICF_TRITON_DIR:-$HOME/.cache/oricf/triton}"
VENV="$DIR/venv"
STAMP="$DIR/installed-$PYTRITON_VERSION"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
MODEL="${ORICF_MODEL_DIR:-$HOME/.cache/oricf/models}/yolox-nano/model.onnx"

install() {
    # Any Python 3.8-3.13 built with a shared libpython: the back end's stub process links it.
    local python="${ORICF_TRITON_PYTHON:-python3}"
    mkdir -p "$DIR"
    rm -rf "$VENV" "$STAMP"
    "$python" -m venv "$VENV"
    # pytriton 0.7 needs numpy < 2; opencv 4.10 is the last to build against it.
    "$VENV/bin/pip" install --quiet "nvidia-pytriton==$PYTRITON_VERSION" "numpy<2" \
        "opencv-python-headless<4.11" "onnxruntime>=1.17"
    touch "$STAMP"
    echo "Triton installed in $VENV"
}

if [[ "${1:-}" == "--install" ]]; then
    install
    exit 0
fi
if [[ ! -f "$STAMP" ]]; then
    echo "Triton is not installed in $DIR: run scripts/triton-server.sh --install" >&2
    exit 2
fi
if [[ ! -f "$MODEL" ]]; then
    echo "no $MODEL: run oricf models pull yolox-nano" >&2
    exit 2
fi
# The back end's stub loads libpython3.X.so.1.0 by name: point it at the interpreter's own,
# or it may load the system's, another patch release than the standard library it then
# imports (Debian's 3.11.2 under a pyenv 3.11.7 fails in multiprocessing).
LIBDIR="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_config_var("LIBDIR"))')"
export LD_LIBRARY_PATH="$LIBDIR${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
exec "$VENV/bin/python" "$HERE/triton_yolox.py" "$MODEL" "$@"
