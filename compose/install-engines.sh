#!/usr/bin/env bash
# Installs the container engines that the engines test suite runs on (docs/testing.md), as
# root on Debian: Docker (docker.io, with docker-compose, compose v1) and podman (with
# podman-compose, runc, catatonit for `podman kube play`'s pods), and debootstrap, which
# makes the base image when no registry answers (compose/make-base-image.sh). Then starts a
# Docker engine when none answers and no systemd runs one (dockerd in the background, its
# log in /var/log/oricf-dockerd.log). Safe to run again.
#
#   compose/install-engines.sh && scripts/test.sh -m engines tests/compose
set -euo pipefail
PACKAGES=(docker.io docker-compose podman podman-compose runc catatonit debootstrap)

die() { printf 'compose/install-engines.sh: %s\n' "$*" >&2; exit 1; }
[[ $(id -u) -eq 0 ]] || die "run it as root (apt-get, dockerd)"
missing=()
for pkg in "${PACKAGES[@]}"; do dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg"); done
if ((${#missing[@]})); then
    echo "==> apt-get install ${missing[*]}"
    apt-get update -qq || die "apt-get update failed"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >/dev/null || die "could not install ${missing[*]}"
fi
if ! timeout 20 docker info >/dev/null 2>&1; then
    if [[ -d /run/systemd/system ]]; then
        systemctl start docker || die "systemctl start docker failed"
    else
        echo "==> no systemd: dockerd in the background (log: /var/log/oricf-dockerd.log)"
        setsid dockerd >/var/log/oricf-dockerd.log 2>&1 < /dev/null &
    fi
    for _ in $(seq 30); do timeout 5 docker info >/dev/null 2>&1 && break; sleep 1; done
    timeout 20 docker info >/dev/null 2>&1 || die "the Docker engine does not answer (/var/log/oricf-dockerd.log)"
fi
echo "==> docker $(docker version -f '{{.Server.Version}}') with docker-compose" \
    "$(docker-compose version --short); $(podman --version) with podman-compose"
