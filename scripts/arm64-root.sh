#!/usr/bin/env bash
# An emulated arm64 (aarch64) Debian root on an x86-64 machine, where ORICF is set up and run
# as on an Arm robot (a Jetson, a Raspberry Pi): Debian's debootstrap makes the root once,
# qemu-user-static runs its programs (binfmt_misc), and it is reused from then on.
#
#   scripts/arm64-root.sh make           the root (debootstrap, once; about 10 minutes)
#   scripts/arm64-root.sh setup          the project copied in, llama-cpp-python cross-compiled
#                                        for Arm once, then the README's scripts/setup.sh in it
#   scripts/arm64-root.sh run CMD [ARG...]  CMD in the root, in the project's copy (/opt/oricf/src)
#   scripts/arm64-root.sh path           where the root is
#   scripts/arm64-root.sh cpuinfo        the /proc/cpuinfo of the emulated CPU (below)
#   scripts/arm64-root.sh qemu-cpu       which CPU qemu emulates (QEMU_CPU)
#
# The root is $ORICF_ARM64_ROOT, else $ORICF_CACHE/arm64-root (~/.cache/oricf/arm64-root).
# The machine's model store (~/.cache/oricf/models, or $ORICF_MODEL_DIR) and wheel cache
# (~/.cache/oricf/wheels: keyed by build options, so an Arm wheel sits beside an x86-64 one)
# are mounted into the root, so nothing is downloaded or built twice. Processes in the root share the machine's network:
# a service started there answers a client here on 127.0.0.1. `run` mounts /proc, /dev, /sys
# and the store in a mount namespace of its own, so nothing stays mounted after it; and this
# machine's certificate authorities (/etc/ssl/certs, read-only, pip pointed at them): where
# a TLS proxy stands between it and PyPI, the root trusts what this machine trusts.
# Needs root, debootstrap, qemu-user-static and binfmt-support (apt-get install -y debootstrap
# qemu-user-static binfmt-support); `setup` also g++-aarch64-linux-gnu, cmake and rsync.
set -euo pipefail
cd "$(dirname "$0")/.."
CACHE="${ORICF_CACHE:-$HOME/.cache/oricf}"
ROOT="${ORICF_ARM64_ROOT:-$CACHE/arm64-root}"
SUITE=bookworm  # Python 3.11: onnxruntime has aarch64 wheels from 3.11 on
MIRROR="${ORICF_BASE_MIRROR:-http://deb.debian.org/debian}"
STORE="${ORICF_MODEL_DIR:-$CACHE/models}"
# What scripts/setup.sh would install with apt-get (espeak-ng, sox, PortAudio), Python with
# venv, and what builds and runs native code (libgomp1: llama.cpp's and CTranslate2's OpenMP).
PACKAGES="python3,python3-venv,python3-dev,ca-certificates,libgomp1,espeak-ng,sox,libportaudio2"
PACKAGES+=",cmake,g++,procps"
SRC=/opt/oricf/src        # the project's copy in the root
VENV=/opt/oricf/venv      # its virtual environment (not the checkout's .venv: x86-64 there)

die() { printf 'scripts/arm64-root.sh: %s\n' "$*" >&2; exit 1; }
need() { command -v "$1" >/dev/null 2>&1 || die "$1 not found: apt-get install -y $2"; }

binfmt() {  # aarch64 programs run through qemu: binfmt_misc mounted, qemu-aarch64 enabled
    [[ -e /proc/sys/fs/binfmt_misc/register ]] \
        || mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc 2>/dev/null \
        || die "binfmt_misc cannot be mounted here (a container without it?)"
    if [[ ! -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ]]; then
        need update-binfmts binfmt-support
        update-binfmts --enable qemu-aarch64 >/dev/null 2>&1 \
            || die "qemu-aarch64 is not registered: apt-get install -y qemu-user-static binfmt-support"
    fi
}

make_root() {
    [[ $(id -u) -eq 0 ]] || die "debootstrap and chroot need root"
    need qemu-aarch64-static qemu-user-static
    binfmt
    if [[ -f "$ROOT/.oricf-root" ]]; then echo "arm64 root ready: $ROOT"; return; fi
    need debootstrap debootstrap
    local tmp="$ROOT.partial"
    rm -rf "$tmp"
    mkdir -p "$(dirname "$ROOT")"
    echo "==> debootstrap --arch=arm64 $SUITE into $ROOT ($PACKAGES)"
    debootstrap --arch=arm64 --variant=minbase --include="$PACKAGES" "$SUITE" "$tmp" "$MIRROR" \
        || die "debootstrap failed (its log: $tmp/debootstrap/debootstrap.log)"
    rm -rf "$tmp"/var/cache/apt/archives/*.deb
    touch "$tmp/.oricf-root"
    mv "$tmp" "$ROOT"
    echo "arm64 root ready: $ROOT ($SECONDS s)"
}

# The CPU the root runs on: qemu emulates a Cortex-A72 (QEMU_CPU), and /proc/cpuinfo says so,
# one such core for each of this machine's. Without it the root would read this machine's
# x86-64 cpuinfo (qemu 7.2 passes it through), and onnxruntime's CPU detection crashes on it
# (SIGSEGV at import); scripts/llama-wheel.sh reads its Features: plain Armv8-A, no extension.
QEMU_CPU=cortex-a72
cpuinfo() {
    local cpu
    for ((cpu = 0; cpu < $(nproc); cpu++)); do
        printf 'processor\t: %d\nBogoMIPS\t: 108.00\nFeatures\t: fp asimd evtstrm crc32 cpuid\n' "$cpu"
        printf 'CPU implementer\t: 0x41\nCPU architecture: 8\nCPU variant\t: 0x0\n'
        printf 'CPU part\t: 0xd08\nCPU revision\t: 3\n\n'
    done
}

in_root() {  # CMD... in the root, with /proc, /dev, /sys and the model store mounted
    [[ -f "$ROOT/.oricf-root" ]] || die "no arm64 root at $ROOT: scripts/arm64-root.sh make"
    binfmt
    mkdir -p "$STORE" "$CACHE/wheels" "$ROOT$SRC" \
        "$ROOT/root/.cache/oricf/models" "$ROOT/root/.cache/oricf/wheels"
    cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
    cpuinfo >"$ROOT/opt/oricf/cpuinfo"
    # unshare's mount namespace ends with the command: nothing stays mounted. exec keeps one
    # process id from here to the program, so a signal sent to it reaches the program.
    # shellcheck disable=SC2016  # expanded by the shell in the namespace, from its arguments
    exec unshare --mount --propagation private /bin/sh -c '
        root=$1 store=$2 wheels=$3 src=$4; shift 4
        mount -t proc proc "$root/proc" \
            && mount --bind "$root/opt/oricf/cpuinfo" "$root/proc/cpuinfo" \
            && mount --rbind /dev "$root/dev" \
            && mount --rbind /sys "$root/sys" && mount -t tmpfs tmpfs "$root/tmp" \
            && mount --bind "$store" "$root/root/.cache/oricf/models" \
            && mount --bind "$wheels" "$root/root/.cache/oricf/wheels" \
            && mount --bind /etc/ssl/certs "$root/etc/ssl/certs" \
            && mount -o remount,bind,ro "$root/etc/ssl/certs" || exit 1
        exec chroot "$root" /usr/bin/env -i HOME=/root PATH=/usr/local/bin:/usr/bin:/bin \
            LANG=C.UTF-8 ORICF_VENV='"$VENV"' PIP_CERT=/etc/ssl/certs/ca-certificates.crt \
            QEMU_CPU='"$QEMU_CPU"' \
            /bin/sh -c "cd $src && exec \"\$@\"" sh "$@"
    ' sh "$ROOT" "$STORE" "$CACHE/wheels" "$SRC" "$@"
}

case "${1:-}" in
    make) make_root ;;
    run) shift; (($#)) || die "run needs a command"; in_root "$@" ;;
    path) echo "$ROOT" ;;
    cpuinfo) cpuinfo ;;
    qemu-cpu) echo "$QEMU_CPU" ;;
    setup) shift; exec scripts/arm64-setup.sh "$@" ;;
    *) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0" >&2; exit 2 ;;
esac
