#!/usr/bin/env bash
# Compose smoke test of the edge stack (compose/edge.yaml). Not part of CI: it builds images.
#
#   compose/smoke-test.sh            build, start, check, tear down
#   compose/smoke-test.sh --robot    also the robot side (compose/robot.yaml): the gateway
#                                    image, started with every service onboard
#                                    (ORICF_PLACEMENT=onboard), checked over real DDS
#   compose/smoke-test.sh --keep     leave the stack running afterwards
#
# 1. Picks the engine: `docker compose` when a Docker engine answers, else podman with
#    podman-compose (as root, with compose/containers.conf unless CONTAINERS_CONF is set).
# 2. Base image: $ORICF_BASE_IMAGE if set; else python:3.11-slim if present or pullable; else
#    one made from Debian packages by compose/make-base-image.sh (no registry needed).
# 3. compose/prepare-build.sh fills the build context (cached wheels, this machine's model
#    store); with a base image of the same Python as .venv the build then uses no index.
# 4. Builds the image with the build arguments of edge.yaml, then makes this run's own
#    certificates and token as edge.yaml's header says (oricf certs, keys and token given to
#    the services' group 10001 through the engine, so that rootless engines map it too) and
#    points ORICF_CERTS at them: the stack runs as deployed, with mTLS and tokens.
# 5. Starts the stack, waits until each service reports SERVING (grpc.health.v1 over mTLS,
#    on the published port and through the container's own health check), then calls each
#    one with grpcurl, its client certificate and the token, and checks the answer: Detect
#    finds a person in darknet's person.jpg, Transcribe of espeak-ng speech gives the words
#    back, Generate with the fact people_count=3 answers with the count. Then checks that each
#    service refuses a call without a token (Unauthenticated), with a wrong one
#    (PermissionDenied), in plaintext, without a client certificate, and reflection.
#    With --robot: publishes vtest.avi frames and a question from this machine on a private
#    ROS_DOMAIN_ID and checks the containerized gateway, which presents the client
#    certificate and token (placement/tls.yaml), answers on /human_counter and /answer.
# 6. Tears the stack down (unless --keep) and checks no container is left.
#
# Needs: scripts/setup.sh done (.venv, models, grpcurl), espeak-ng and sox, and either Docker
# with compose v2 or `apt-get install podman podman-compose runc debootstrap` (as root).
# Exit 0 only when every check passed. Environment: ORICF_IMAGE (default oricf:local),
# ORICF_SMOKE_TIMEOUT (seconds to reach SERVING, default 600).
set -euo pipefail
cd "$(dirname "$0")/.."
KEEP=0 ROBOT=0
for arg in "$@"; do
    case "$arg" in
        --keep) KEEP=1 ;;
        --robot) ROBOT=1 ;;
        *) echo "usage: compose/smoke-test.sh [--robot] [--keep]" >&2; exit 2 ;;
    esac
done
PY="${ORICF_VENV:-.venv}/bin/python"
PROJECT=oricf-smoke
export ORICF_IMAGE="${ORICF_IMAGE:-oricf:local}"
export ORICF_GATEWAY_IMAGE="${ORICF_GATEWAY_IMAGE:-oricf-gateway:local}"
TIMEOUT="${ORICF_SMOKE_TIMEOUT:-600}"
SERVICES=(detector asr llm)
declare -A PORTS=([detector]=50051 [asr]=50052 [llm]=50053)
declare -A RPCS=([detector]=oricf.v1.Detector/Detect [asr]=oricf.v1.SpeechRecognizer/Transcribe
                 [llm]=oricf.v1.LanguageModel/Generate)
HEALTH=grpc.health.v1.Health/Check

step() { printf '\n==> %s\n' "$*"; }
die() { printf 'smoke-test: FAIL: %s\n' "$*" >&2; exit 1; }

if docker compose version >/dev/null 2>&1 && docker info >/dev/null 2>&1; then
    ENGINE=docker; COMPOSE=(docker compose)
elif command -v podman >/dev/null && command -v podman-compose >/dev/null; then
    ENGINE=podman; COMPOSE=(podman-compose)
    export CONTAINERS_CONF="${CONTAINERS_CONF:-$PWD/compose/containers.conf}"
else
    die "neither docker compose (with a running engine) nor podman-compose is installed"
fi
COMPOSE+=(-p "$PROJECT" -f compose/edge.yaml)
if ((ROBOT)) && [[ $ENGINE == podman ]] \
        && "${COMPOSE[0]}" version 2>/dev/null | grep -q 'version  *1\.0\.[0-5]$'; then
    die "--robot needs podman-compose 1.0.6 or later for network_mode: host (pip install podman-compose)"
fi
if ((ROBOT)); then
    COMPOSE+=(-f compose/robot.yaml)
    export ORICF_PLACEMENT=onboard ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    ORICF_ROS_USER="$(id -u):$(id -g)"    # the check's ROS node runs as this user
    export ORICF_ROS_USER
    export ROS_DOMAIN_ID=$((RANDOM % 100 + 1))
fi
GRPCURL=$("$PY" -c 'from oricf.store import ModelStore; print(ModelStore().path("grpcurl"))')
WORK=$(mktemp -d /tmp/oricf-smoke.XXXXXX)
STARTED=0
step "engine: ${COMPOSE[*]}"

cleanup() {
    local status=$?
    if ((status != 0)) && ((STARTED)); then
        "${COMPOSE[@]}" logs >"$WORK/logs.txt" 2>&1 || true
        echo "--- last lines of the services' logs"; tail -60 "$WORK/logs.txt"
    fi
    if ((KEEP)); then
        echo "stack left running: ${COMPOSE[*]} down"
    else
        step "tear down"
        "${COMPOSE[@]}" down >"$WORK/down.log" 2>&1 || cat "$WORK/down.log"
    fi
    rm -rf "$WORK"
}

base_image() {
    if [[ -n "${ORICF_BASE_IMAGE:-}" ]]; then echo "$ORICF_BASE_IMAGE"; return; fi
    if $ENGINE image inspect python:3.11-slim >/dev/null 2>&1 \
        || timeout 60 $ENGINE pull -q python:3.11-slim >/dev/null 2>&1; then
        echo python:3.11-slim; return
    fi
    echo "no registry reachable: making a Debian base image" >&2
    compose/make-base-image.sh localhost/oricf-base:bookworm >&2
    echo localhost/oricf-base:bookworm
}

build_image() {  # base, compose file, service, image tag, prepare-build arguments...
    local base=$1 file=$2 service=$3 tag=$4 pip_options="" venv_py image_py
    shift 4
    compose/prepare-build.sh "$@" >"$WORK/prepare.log" 2>&1 \
        || { cat "$WORK/prepare.log"; die "prepare-build"; }
    venv_py=$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
    image_py=$($ENGINE run --rm "$base" python3 -c 'import sys; print("%d.%d" % sys.version_info[:2])')
    [[ "$venv_py" == "$image_py" ]] && pip_options="--no-index"
    # The build arguments of the compose file (EXTRAS, MODELS), so the image matches it.
    mapfile -t args < <("$PY" -c 'import yaml, sys
args = yaml.safe_load(open(sys.argv[1]))["services"][sys.argv[2]]["build"]["args"]
for key in ("EXTRAS", "MODELS"):
    print(f"--build-arg={key}={args[key]}")' "$file" "$service")
    local extra=()
    [[ $ENGINE == podman ]] && extra=(--format docker --ignorefile compose/Dockerfile.dockerignore)
    echo "$tag: base $base, Python $image_py, pip options '${pip_options}', ${args[*]}"
    DOCKER_BUILDKIT=1 $ENGINE build "${extra[@]}" -f compose/Dockerfile -t "$tag" \
        --build-arg "BASE_IMAGE=$base" --build-arg "PIP_OPTIONS=$pip_options" "${args[@]}" . \
        >"$WORK/build.log" 2>&1 || { tail -40 "$WORK/build.log"; die "image build of $tag"; }
}

make_certs() {  # edge.yaml's two steps, into this run's folder; sets CERTS, TLS, SCHEMA, AUTH
    CERTS="$WORK/certs"
    "$PY" -m oricf certs "$CERTS" --host localhost --host 127.0.0.1
    # chgrp as the engine's root: group 10001 as the containers see it, also when rootless
    $ENGINE run --rm --no-healthcheck --user 0 --entrypoint chgrp -v "$CERTS:/certs" \
        "$ORICF_IMAGE" 10001 /certs/server.key /certs/client.key /certs/tokens
    chmod 640 "$CERTS/server.key" "$CERTS/client.key" "$CERTS/tokens"
    export ORICF_CERTS="$CERTS"
    ORICF_SMOKE_TOKEN=$(head -1 "$CERTS/tokens")
    export ORICF_SMOKE_TOKEN
    "$PY" compose/smoke_check.py protoset >"$WORK/oricf.protoset"
    TLS=(-cacert "$CERTS/ca.pem" -cert "$CERTS/client.pem" -key "$CERTS/client.key")
    SCHEMA=(-protoset "$WORK/oricf.protoset")
    # grpcurl expands the variable itself: the token stays out of every command line
    AUTH=(-expand-headers -H 'authorization: Bearer ${ORICF_SMOKE_TOKEN}')
}

container_of() {  # the container running a compose service
    $ENGINE ps -q --filter "label=com.docker.compose.project=$PROJECT" \
        --filter "label=com.docker.compose.service=$1" | head -1
}

container_healthy() {
    local id
    id=$(container_of "$1")
    [[ -n "$id" ]] || return 1
    if [[ $ENGINE == podman ]]; then
        podman healthcheck run "$id" >/dev/null 2>&1   # podman without systemd: run it here
    else
        [[ $(docker inspect -f '{{.State.Health.Status}}' "$id") == healthy ]]
    fi
}

wait_serving() {
    local name=$1 port=${PORTS[$1]} start=$SECONDS
    until "$GRPCURL" "${TLS[@]}" "${SCHEMA[@]}" -max-time 3 "127.0.0.1:$port" "$HEALTH" \
            2>/dev/null | grep -q '"SERVING"'; do
        ((SECONDS - start < TIMEOUT)) || die "$name not SERVING after $TIMEOUT s"
        sleep 2
    done
    until container_healthy "$name"; do
        ((SECONDS - start < TIMEOUT)) || die "$name: the container's health check never passed"
        sleep 2
    done
    echo "$name SERVING on :$port after $((SECONDS - start)) s (container health check passed)"
}

call_and_check() {
    local name=$1
    "$PY" compose/smoke_check.py request "$name" >"$WORK/$name.json"
    "$GRPCURL" "${TLS[@]}" "${SCHEMA[@]}" "${AUTH[@]}" -max-time 60 -max-msg-sz 67108864 -d @ \
        "127.0.0.1:${PORTS[$name]}" "${RPCS[$name]}" <"$WORK/$name.json" >"$WORK/$name.reply" \
        || die "$name: grpcurl ${RPCS[$name]} failed"
    "$PY" compose/smoke_check.py check "$name" <"$WORK/$name.reply"
}

refused() {  # what grpcurl must say, its arguments: the call must fail, for that reason
    local expected=$1 out
    shift
    if out=$("$GRPCURL" -max-time 5 "$@" 2>&1); then
        echo "answered: $out"; return 1
    fi
    grep -q "$expected" <<<"$out" || { echo "$out"; return 1; }
}

check_refusals() {  # the health RPC needs no token: it fails on the transport alone
    local name=$1 address=127.0.0.1:${PORTS[$1]} rpc=${RPCS[$1]}
    refused "Code: Unauthenticated" "${TLS[@]}" "${SCHEMA[@]}" -d '{}' "$address" "$rpc" \
        || die "$name: a call without a token was not refused as Unauthenticated"
    refused "Code: PermissionDenied" "${TLS[@]}" "${SCHEMA[@]}" \
        -H "authorization: Bearer wrong" -d '{}' "$address" "$rpc" \
        || die "$name: a wrong token was not refused as PermissionDenied"
    refused "Failed to dial" -plaintext "${SCHEMA[@]}" "$address" "$HEALTH" \
        || die "$name: answered in plaintext"
    refused "Failed to dial" -cacert "$CERTS/ca.pem" "${SCHEMA[@]}" "$address" "$HEALTH" \
        || die "$name: answered a caller without a client certificate"
    refused "does not support the reflection API" "${TLS[@]}" "${AUTH[@]}" "$address" list \
        || die "$name: serves reflection"
    echo "ok   $name refuses: no token (Unauthenticated), a wrong token (PermissionDenied)," \
        "plaintext, no client certificate, reflection"
}

step "base image"
BASE=$(base_image)
step "images (build log: $WORK/build.log)"
SECONDS=0
build_image "$BASE" compose/edge.yaml detector "$ORICF_IMAGE"
((ROBOT)) && build_image "$BASE" compose/robot.yaml gateway "$ORICF_GATEWAY_IMAGE" ros
echo "built in $SECONDS s"
trap cleanup EXIT
step "certificates and token (mTLS, bearer token)"
make_certs
step "start the edge stack"
STARTED=1
"${COMPOSE[@]}" up -d >"$WORK/up.log" 2>&1 || { cat "$WORK/up.log"; die "compose up"; }
step "wait for SERVING"
for name in "${SERVICES[@]}"; do wait_serving "$name"; done
step "call each service with grpcurl"
failed=0
for name in "${SERVICES[@]}"; do call_and_check "$name" || failed=1; done
step "refusals"
for name in "${SERVICES[@]}"; do check_refusals "$name"; done
if ((ROBOT)); then
    step "the robot side over DDS (ROS_DOMAIN_ID $ROS_DOMAIN_ID)"
    "$PY" compose/smoke_check.py ros || failed=1
fi
((failed == 0)) || die "a check failed"
((KEEP)) && { echo "PASS"; exit 0; }
trap - EXIT
STARTED=0
cleanup
left=$($ENGINE ps -a -q --filter "label=com.docker.compose.project=$PROJECT")
[[ -z "$left" ]] || die "containers left after down: $left"
what="edge stack"
((ROBOT)) && what="edge stack and gateway"
echo "PASS: $what built, SERVING over mTLS, answered correctly with the token," \
    "refused callers without credentials, and torn down ($SECONDS s)"
