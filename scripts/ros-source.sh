#!/usr/bin/env bash
# Which ROS 2 the set-up gives the environment (run by scripts/setup.sh; prints, changes
# nothing). Prints two lines: `SOURCE PYTHON EXTRA VERSION` (VERSION: the Python's, e.g.
# 3.12), then one sentence for the user;
# or says what to do on stderr and exits 1 for a case the set-up cannot handle.
#   system  ROS 2 is sourced and its Python imports rclpy: a venv of that Python with the
#           system's packages (its rclpy and message packages), no PyPI ROS wheels
#   wheels  the PyPI wheels of ORICF_ROS_DISTRO exist for this machine: the EXTRA extra
#   none    neither: no ROS; the gateway runs pipelines without ROS topics
# Reads ROS_DISTRO (set by sourcing ROS 2), ORICF_ROS_DISTRO (jazzy by default), PYTHON
# (else python3, or python3.11 where there is one and no ROS is sourced), ORICF_ARCH.
set -euo pipefail

DISTROS=(jazzy kilted)                # PyPI has ros-DISTRO-* wheels for these
WHEEL_ARCHES=(x86_64)                 # ...built for these machines (manylinux_2_28)
WHEEL_PYTHONS=(3.10 3.11 3.12 3.13 3.14)   # ...and these Pythons (cp310 to cp314)
NO_ROS="the gateway runs without ROS: pipelines without ROS topics, e.g. \`oricf gateway --config people_video\` (docs/gateway.md)"

refuse() { printf 'setup: %s\n' "$*" >&2; exit 1; }
among() { local item=$1; shift; [[ " $* " == *" $item "* ]]; }

# `MAJOR.MINOR 0|1`: the Python's version and whether it imports rclpy (its C extension
# included: a sourced ROS 2 of another Python's version is found but does not load).
probe() {
    "$1" -c 'import sys
try:
    import rclpy  # noqa: F401
    found = 1
except Exception:
    found = 0
print("%d.%d" % sys.version_info[:2], found)' 2>/dev/null \
        || refuse "$1 does not run: set PYTHON to a Python 3.10 or newer"
}

too_old() {  # MAJOR.MINOR: below 3.10?
    local minor=${1#*.}
    [[ ${1%%.*} -lt 3 || ( ${1%%.*} -eq 3 && $minor -lt 10 ) ]]
}

from_sourced_ros() {
    local python=${PYTHON:-python3} probed version rclpy
    if [[ -n "${ORICF_ROS_DISTRO:-}" && "$ORICF_ROS_DISTRO" != "$ROS_DISTRO" ]]; then
        refuse "ROS 2 $ROS_DISTRO is sourced but ORICF_ROS_DISTRO=$ORICF_ROS_DISTRO: unset ORICF_ROS_DISTRO to use the sourced $ROS_DISTRO, or run from a shell without ROS 2 sourced to install the $ORICF_ROS_DISTRO wheels"
    fi
    command -v "$python" >/dev/null || refuse "ROS 2 $ROS_DISTRO is sourced but $python is not found: set PYTHON to the Python ROS 2 was built for"
    python=$(command -v "$python")
    probed=$(probe "$python")
    read -r version rclpy <<<"$probed"
    too_old "$version" && refuse "ROS 2 $ROS_DISTRO runs on Python $version ($python); ORICF needs Python 3.10 or newer (ROS 2 Humble or newer)"
    ((rclpy)) || refuse "ROS_DISTRO=$ROS_DISTRO is set but $python (Python $version) cannot import rclpy: source /opt/ros/$ROS_DISTRO/setup.bash in this shell, or set PYTHON to the Python ROS 2 was built for"
    echo "system $python - $version"
    echo "ROS 2 $ROS_DISTRO is sourced: the environment sees its rclpy and message packages (a venv with --system-site-packages from $python); no ROS wheels from PyPI"
}

from_wheels() {
    local distro=${ORICF_ROS_DISTRO:-jazzy} arch=${ORICF_ARCH:-$(uname -m)} python probed version rclpy
    among "$distro" "${DISTROS[@]}" || refuse "ORICF_ROS_DISTRO=$distro: the set-up installs ${DISTROS[*]} (PyPI wheels); for another ROS 2, install it from apt, source its setup.bash and run again"
    python=${PYTHON:-$(command -v python3.11 || command -v python3 || true)}
    if [[ -z "$python" ]] || ! command -v "$python" >/dev/null; then
        refuse "no python3 found: install Python 3.10 or newer (apt install python3 python3-venv) or set PYTHON"
    fi
    python=$(command -v "$python")
    probed=$(probe "$python")
    read -r version rclpy <<<"$probed"
    too_old "$version" && refuse "Python $version ($python) is too old: ORICF needs Python 3.10 or newer; install one and set PYTHON to it"
    if among "$arch" "${WHEEL_ARCHES[@]}" && among "$version" "${WHEEL_PYTHONS[@]}"; then
        local extra=ros
        [[ "$distro" != jazzy ]] && extra="ros-$distro"
        echo "wheels $python $extra $version"
        echo "ROS 2 ${distro^} from PyPI wheels (the $extra extra)"
    else
        echo "none $python - $version"
        echo "no ROS 2 $distro wheels for $arch with Python $version and no ROS 2 sourced: installing without ROS; $NO_ROS. For ROS 2, install it from apt, source it and run again (docs/ros.md)"
    fi
}

if [[ -n "${ROS_DISTRO:-}" ]]; then from_sourced_ros; else from_wheels; fi
