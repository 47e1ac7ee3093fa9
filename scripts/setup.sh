#!/usr/bin/env bash
# Sets up ORICF on a fresh Debian/Ubuntu x86-64 machine: system packages, a virtual
# environment in .venv, the Python packages (llama-cpp-python built once and cached), and
# the models and sample data from the model store. Safe to run again: finished steps are skipped.
#
#   scripts/setup.sh          everything needed to run the demo
#   scripts/setup.sh --dev    plus the test and lint tools
set -euo pipefail

cd "$(dirname "$0")/.."
DEV=0
[[ "${1:-}" == "--dev" ]] && DEV=1
VENV="${ORICF_VENV:-.venv}"
CACHE="${ORICF_CACHE:-$HOME/.cache/oricf}"
LLAMA_VERSION="0.3.36"
MODELS=(yolox-nano yolov8-fall ppocr-text-direction whisper-tiny-en piper-joe-medium gemma3-270m smollm2-135m-instruct vtest-video darknet-images opencv-text-image grpcurl compose-spec)

step() { printf '\n==> %s\n' "$*"; }
die() { printf 'setup: %s\n' "$*" >&2; exit 1; }

step "system packages (espeak-ng: the speech service's phonemes and voice, and the spoken test questions; sox)"
APT_PACKAGES=(espeak-ng sox)
# PortAudio, which the gateway's audio inputs (microphones) capture through.
APT_PACKAGES+=(libportaudio2)
# The tests degrade a link between network namespaces (iptables drops packets at random).
((DEV)) && APT_PACKAGES+=(iptables iproute2)
# The RTSP tests and `oricf bench rtsp` run a camera: FFmpeg encodes, GStreamer serves RTSP.
((DEV)) && APT_PACKAGES+=(ffmpeg python3-gi gir1.2-gst-rtsp-server-1.0 gstreamer1.0-plugins-good
                          gstreamer1.0-plugins-bad)
# The audio-input tests play speech into a PulseAudio null sink and capture its monitor.
((DEV)) && APT_PACKAGES+=(pulseaudio pulseaudio-utils)
# The shell scripts (compose/stack.sh, scripts/*.sh) are checked with shellcheck.
((DEV)) && APT_PACKAGES+=(shellcheck)
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if ((${#missing[@]})); then
    SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
    $SUDO apt-get update -qq || die "apt-get update failed"
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >/dev/null || die "could not install ${missing[*]}"
fi

step "python virtual environment ($VENV)"
PYTHON="${PYTHON:-$(command -v python3.11 || command -v python3)}"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 10))' || die "Python 3.10+ needed"
[[ -x "$VENV/bin/python" ]] || "$PYTHON" -m venv "$VENV"
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check -q)
"${PIP[@]}" install --upgrade pip

step "llama-cpp-python $LLAMA_VERSION (compiled once per CPU type, then reused from $CACHE/wheels)"
# llama.cpp is built for this CPU's instruction sets, named one by one from /proc/cpuinfo
# rather than -march=native: native turns AMX on where the CPU has it, and AMX code crashes
# the process where the kernel does not grant it AMX state (many virtual machines). The
# cache folder is keyed by the build options, so another CPU type builds its own wheel.
CPU_FLAGS=" $(grep -m1 '^flags' /proc/cpuinfo | cut -d: -f2) "
CMAKE_ARGS="-DGGML_NATIVE=OFF"
for pair in avx:AVX avx2:AVX2 fma:FMA f16c:F16C bmi2:BMI2 avx_vnni:AVX_VNNI avx512f:AVX512 \
            avx512vbmi:AVX512_VBMI avx512_vnni:AVX512_VNNI avx512_bf16:AVX512_BF16; do
    [[ "$CPU_FLAGS" == *" ${pair%%:*} "* ]] && CMAKE_ARGS+=" -DGGML_${pair#*:}=ON"
done
export CMAKE_ARGS
CPU_KEY=$(echo "$LLAMA_VERSION $CMAKE_ARGS" | sha256sum | cut -c1-12)
WHEELS="$CACHE/wheels/$CPU_KEY"
mkdir -p "$WHEELS"
if ! ls "$WHEELS"/llama_cpp_python-"$LLAMA_VERSION"-*.whl >/dev/null 2>&1; then
    echo "building llama-cpp-python (about 5-10 minutes on 2 cores): $CMAKE_ARGS"
    "${PIP[@]}" wheel --no-cache-dir --no-deps -w "$WHEELS" "llama-cpp-python==$LLAMA_VERSION" \
        || die "llama-cpp-python did not build (needs gcc, g++ and cmake)"
fi

step "python packages"
EXTRAS="asr,llm,ros,audio"
((DEV)) && EXTRAS="$EXTRAS,openvino,interop,dev"
"${PIP[@]}" install --find-links "$WHEELS" -e ".[$EXTRAS]"
# colcon builds ros/oricf_gateway, the ROS 2 package, with this Python, as on a robot
# (tests/ros; docs/ros.md). colcon-core needs setuptools < 80.
((DEV)) && "${PIP[@]}" install "colcon-core>=0.15,<0.22" "colcon-ros>=0.4,<0.6"

step "models and sample data (checked by sha256)"
"$VENV/bin/oricf" models pull "${MODELS[@]}"
"$VENV/bin/oricf" models list
