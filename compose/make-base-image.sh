#!/usr/bin/env bash
# Makes a local Debian base image for compose/Dockerfile on a machine that cannot pull from a
# container registry: debootstrap builds a minimal Debian root file system from Debian's own
# packages, and `podman import` (or `docker import`) turns it into an image.
#
#   compose/make-base-image.sh [IMAGE]      default IMAGE: localhost/oricf-base:bookworm
#   ORICF_ARCH=arm64 compose/make-base-image.sh     default IMAGE: localhost/oricf-base:bookworm-arm64
#
# ORICF_ARCH (Debian's name: amd64, arm64; default this machine's) makes it for another
# architecture: debootstrap runs that architecture's programs through qemu-user-static
# (apt-get install -y qemu-user-static binfmt-support), and the image is marked with it, so
# an engine runs it through the same emulator.
# compose/stack.sh build makes it itself when no registry answers; by hand, build with
#   --build-arg BASE_IMAGE=localhost/oricf-base:bookworm
# Needs root and debootstrap (apt-get install -y debootstrap). Skips the work when IMAGE exists
# (set ORICF_REBUILD_BASE=1 to make it again). Takes about a minute plus the download.
set -euo pipefail

ARCH="${ORICF_ARCH:-$(dpkg --print-architecture)}"
SUFFIX=""
[[ "$ARCH" != "$(dpkg --print-architecture)" ]] && SUFFIX="-$ARCH"
IMAGE="${1:-localhost/oricf-base:bookworm$SUFFIX}"
SUITE="${ORICF_BASE_SUITE:-bookworm}"
MIRROR="${ORICF_BASE_MIRROR:-http://deb.debian.org/debian}"
# What python:3.11-slim offers that the Dockerfile relies on: a Python with venv (its ensurepip
# brings pip into the build stage; the system needs no python3-pip), CA certificates for pip,
# and libgomp1 (llama.cpp and CTranslate2 use OpenMP).
PACKAGES="python3,python3-venv,ca-certificates,libgomp1,espeak-ng"

# The engine compose/stack.sh picked (ORICF_ENGINE), else podman when installed, else docker.
ENGINE="${ORICF_ENGINE:-}"
if [[ -z "$ENGINE" ]]; then
    if command -v podman >/dev/null 2>&1; then ENGINE=podman; else ENGINE=docker; fi
fi

if [[ "${ORICF_REBUILD_BASE:-0}" != 1 ]] && $ENGINE image inspect "$IMAGE" >/dev/null 2>&1; then
    echo "base image $IMAGE already exists"
    exit 0
fi
[[ $(id -u) -eq 0 ]] || { echo "make-base-image: debootstrap needs root" >&2; exit 1; }
command -v debootstrap >/dev/null || { echo "make-base-image: install debootstrap" >&2; exit 1; }
if [[ -n "$SUFFIX" ]] && ! ls /proc/sys/fs/binfmt_misc/qemu-* >/dev/null 2>&1; then
    echo "make-base-image: $ARCH programs need an emulator: apt-get install -y" \
        "qemu-user-static binfmt-support" >&2
    exit 1
fi

ROOTFS=$(mktemp -d /tmp/oricf-rootfs.XXXXXX)
trap 'rm -rf "$ROOTFS"' EXIT
echo "debootstrap $SUITE for $ARCH into $ROOTFS ($PACKAGES)"
debootstrap --arch="$ARCH" --variant=minbase --include="$PACKAGES" "$SUITE" "$ROOTFS" "$MIRROR"
# Keep the image small: package lists, caches, documentation (but the copyright files),
# manual pages and translations are not needed at run time (about 50 MB), and packages
# installed later leave them out too.
rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/lib/apt/lists/* \
    "$ROOTFS"/usr/share/man/* "$ROOTFS"/usr/share/info/* "$ROOTFS"/usr/share/locale/*
find "$ROOTFS/usr/share/doc" -mindepth 1 ! -type d ! -name copyright -delete
find "$ROOTFS/usr/share/doc" -mindepth 1 -depth -type d -empty -delete
cat >"$ROOTFS/etc/dpkg/dpkg.cfg.d/oricf-slim" <<'EXCLUDE'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
EXCLUDE
PATH_ENV='PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin'
ARCH_OPTION=()
[[ $ENGINE == podman ]] && ARCH_OPTION=(--arch "$ARCH")
if [[ -z "$SUFFIX" || $ENGINE == podman ]]; then
    tar -C "$ROOTFS" -c . | $ENGINE import "${ARCH_OPTION[@]}" --change "ENV $PATH_ENV" \
        --change 'CMD ["/bin/bash"]' - "$IMAGE"
else
    # docker import (20.10) marks every image with the engine's own architecture, whatever
    # --platform says; a build from scratch takes the platform it is given.
    mkdir "$ROOTFS.context"
    trap 'rm -rf "$ROOTFS" "$ROOTFS.context"' EXIT
    tar -C "$ROOTFS" -cf "$ROOTFS.context/rootfs.tar" .
    printf 'FROM scratch\nADD rootfs.tar /\nENV %s\nCMD ["/bin/bash"]\n' "$PATH_ENV" \
        >"$ROOTFS.context/Dockerfile"
    DOCKER_BUILDKIT=0 docker build -q --platform "linux/$ARCH" -t "$IMAGE" "$ROOTFS.context"
fi
echo "base image $IMAGE ready"
