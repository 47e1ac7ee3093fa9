#!/usr/bin/env bash
# Builds one image from compose/Dockerfile the way that works on Docker and on podman alike.
# compose/stack.sh build (and up) run it with the build arguments the compose files declare:
#
#   compose/build-image.sh TAG EXTRAS [MODEL ...]
#   e.g. compose/build-image.sh oricf:local asr,llm yolox-nano whisper-tiny-en gemma3-270m piper-joe-medium pybullet-hopper
#
# 1. Engine: $ORICF_ENGINE, else the one compose/stack.sh picks (its `env`).
# 2. Base image: $ORICF_BASE_IMAGE; else python:3.11-slim if present; else
#    localhost/oricf-base:bookworm if present; else python:3.11-slim if it can be pulled; else
#    one made from Debian packages by compose/make-base-image.sh (no registry needed).
# 3. Build context: compose/prepare-build.sh EXTRAS MODEL... when .venv exists (cached wheels,
#    this machine's model store; ORICF_PREPARE=0 skips it). Its wheels are for .venv's Python,
#    so with a base image of the same Python the build uses no package index (--no-index),
#    unless ORICF_PIP_OPTIONS says otherwise.
# 4. `ENGINE build`, on podman with --format docker (an OCI image has no HEALTHCHECK) and
#    --ignorefile compose/Dockerfile.dockerignore; on Docker with BuildKit, which reads that
#    file itself: a docker client with buildx, else the first one on PATH older than 23
#    (BuildKit built in; Debian's docker.io), else the build stops saying so. The classic
#    builder would send the whole repository (.venv too) as the build context.
# 5. ORICF_ARCH (Debian's name, e.g. arm64; default this machine's) builds for another
#    architecture, every step run through qemu-user-static (binfmt_misc): the base image is
#    $ORICF_BASE_IMAGE, else localhost/oricf-base:bookworm-ARCH, made by
#    compose/make-base-image.sh when missing; the build context holds that architecture's
#    wheels (its llama-cpp-python wheel: scripts/arm64-setup.sh's, for arm64).
# The build log goes to ${TMPDIR:-/tmp}/oricf-build-TAG.log; its end is shown on failure.
set -euo pipefail
cd "$(dirname "$0")/.."
(($# >= 2)) || { sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0" >&2; exit 2; }
TAG=$1 EXTRAS=$2
shift 2
MODELS=("$@")
VENV_PY="${ORICF_VENV:-.venv}/bin/python"
LOG="${TMPDIR:-/tmp}/oricf-build-${TAG//[^A-Za-z0-9_.-]/_}.log"

die() { printf 'compose/build-image.sh: %s\n' "$*" >&2; exit 1; }
[[ -n "${ORICF_ENGINE:-}" ]] || eval "$(compose/stack.sh env)"
ENGINE=$ORICF_ENGINE

image_exists() { "$ENGINE" image inspect "$1" >/dev/null 2>&1; }

buildkit_docker() {  # a docker client that builds with BuildKit
    local client major
    if docker buildx version >/dev/null 2>&1; then echo docker; return; fi
    while read -r client; do     # docker 23 and later need buildx for BuildKit; older have it
        major=$("$client" version -f '{{.Client.Version}}' 2>/dev/null) || continue
        ((10#${major%%.*} < 23)) && { echo "$client"; return; }
    done < <(type -ap docker)
    die "no docker client here builds with BuildKit ($(command -v docker) has no buildx):" \
        "install the buildx plugin, or Debian's docker.io (its client has BuildKit built in)"
}

HOST_ARCH=$(dpkg --print-architecture)
ARCH="${ORICF_ARCH:-$HOST_ARCH}"
FOREIGN=0
[[ "$ARCH" != "$HOST_ARCH" ]] && FOREIGN=1

base_image() {
    if [[ -n "${ORICF_BASE_IMAGE:-}" ]]; then echo "$ORICF_BASE_IMAGE"
    elif ((FOREIGN)); then
        image_exists "localhost/oricf-base:bookworm-$ARCH" \
            || ORICF_ENGINE=$ENGINE ORICF_ARCH=$ARCH compose/make-base-image.sh >&2
        echo "localhost/oricf-base:bookworm-$ARCH"
    elif image_exists python:3.11-slim; then echo python:3.11-slim
    elif image_exists localhost/oricf-base:bookworm; then echo localhost/oricf-base:bookworm
    elif timeout 120 "$ENGINE" pull -q python:3.11-slim >/dev/null 2>&1; then echo python:3.11-slim
    else
        echo "no registry answers: compose/make-base-image.sh (debootstrap, about a minute)" >&2
        ORICF_ENGINE=$ENGINE compose/make-base-image.sh localhost/oricf-base:bookworm >&2
        echo localhost/oricf-base:bookworm
    fi
}

BASE=$(base_image)
: >"$LOG"
OPTIONS="${ORICF_PIP_OPTIONS-}"
if [[ "${ORICF_PREPARE:-1}" != 0 && -x "$VENV_PY" ]]; then
    echo "==> build context: compose/prepare-build.sh $EXTRAS${MODELS[*]:+ ${MODELS[*]}}"
    ORICF_ARCH=$ARCH compose/prepare-build.sh "$EXTRAS" "${MODELS[@]}" >>"$LOG" 2>&1 \
        || { tail -20 "$LOG"; die "compose/prepare-build.sh failed (log: $LOG)"; }
    if [[ -z "${ORICF_PIP_OPTIONS+set}" ]]; then
        venv_py=$("$VENV_PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
        image_py=$("$ENGINE" run --rm "$BASE" python3 -c 'import sys; print("%d.%d" % sys.version_info[:2])')
        [[ "$venv_py" == "$image_py" ]] && OPTIONS=--no-index
    fi
fi
BUILD=("$ENGINE" build)
if [[ $ENGINE == podman ]]; then
    BUILD+=(--format docker --ignorefile compose/Dockerfile.dockerignore)
else
    client=$(buildkit_docker) || exit 1
    BUILD=("$client" build)
fi
# The platform only for another architecture: a native build stays as it was on engines
# whose builder takes no --platform.
((FOREIGN)) && BUILD+=(--platform "linux/$ARCH")
echo "==> image $TAG ($ARCH): base $BASE, EXTRAS=$EXTRAS, MODELS='${MODELS[*]}', PIP_OPTIONS='$OPTIONS'"
DOCKER_BUILDKIT=1 "${BUILD[@]}" -f compose/Dockerfile -t "$TAG" \
    --build-arg "BASE_IMAGE=$BASE" --build-arg "PIP_OPTIONS=$OPTIONS" \
    --build-arg "EXTRAS=$EXTRAS" --build-arg "MODELS=${MODELS[*]}" . >>"$LOG" 2>&1 \
    || { tail -40 "$LOG"; die "the build of $TAG failed (log: $LOG)"; }
SIZE=$("$ENGINE" image inspect -f '{{.Size}}' "$TAG")
echo "    $TAG built in $SECONDS s, $((SIZE / 1000000)) MB (log: $LOG)"
