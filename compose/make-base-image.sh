#!/usr/bin/env bash
# Makes a local Debian base image for compose/Dockerfile on a machine that cannot pull from a
# container registry: debootstrap builds a minimal Debian root file system from Debian's own
# packages, and `podman import` (or `docker import`) turns it into an image.
#
#   compose/make-base-image.sh [IMAGE]      default IMAGE: localhost/oricf-base:bookworm
#
# compose/stack.sh build makes it itself when no registry answers; by hand, build with
#   --build-arg BASE_IMAGE=localhost/oricf-base:bookworm
# Needs root and debootstrap (apt-get install -y debootstrap). Skips the work when IMAGE exists
# (set ORICF_REBUILD_BASE=1 to make it again). Takes about a minute plus the download.
set -euo pipefail

IMAGE="${1:-localhost/oricf-base:bookworm}"
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

ROOTFS=$(mktemp -d /tmp/oricf-rootfs.XXXXXX)
trap 'rm -rf "$ROOTFS"' EXIT
echo "debootstrap $SUITE into $ROOTFS ($PACKAGES)"
debootstrap --variant=minbase --include="$PACKAGES" "$SUITE" "$ROOTFS" "$MIRROR"
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
tar -C "$ROOTFS" -c . | $ENGINE import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["/bin/bash"]' - "$IMAGE"
echo "base image $IMAGE ready"
