#!/usr/bin/env bash
# Compose smoke test of the edge stack (compose/edge.yaml). Not part of CI: it builds images.
#
#   compose/smoke-test.sh            build, start, check, tear down
#   compose/smoke-test.sh --robot    also the robot side (compose/robot.yaml): the gateway
#                                    image, started with every service onboard
#                                    (ORICF_PLACEMENT=onboard), checked over real DDS
#   compose/smoke-test.sh --keep     leave the stack running afterwards
#
# Everything about the engine goes through compose/stack.sh, as a deployment does, in the
# compose project oricf-smoke:
# 1. `compose/stack.sh check`: the engine (`docker compose` when a Docker engine answers, else
#    podman with podman-compose and compose/containers.conf), the compose tool's version
#    (--robot: podman-compose >= 1.0.6), and that a container starts.
# 2. `compose/stack.sh build`: the images (compose/build-image.sh: base image, build context,
#    the build command), then this run's own certificates and token as edge.yaml's header
#    says (oricf certs, keys and token given to the services' group 10001 through the
#    engine, so that rootless engines map it too), with ORICF_CERTS pointing at them: the
#    stack runs as deployed, with mTLS and tokens.
# 3. `compose/stack.sh up` (every container started and still running), then waits until each
#    service reports SERVING (grpc.health.v1 over mTLS on the published port, then the
#    container's own health check: `compose/stack.sh wait`), then calls each
#    one with grpcurl, its client certificate and the token, and checks the answer: Detect
#    finds a person in darknet's person.jpg, Transcribe of espeak-ng speech gives the words
#    back, Generate with the fact people_count=3 answers with the count, Synthesize speaks
#    the sentence, Act with a Hopper observation answers it with the actions the same policy
#    gives on this machine (the image's converted weights). Then checks that each service
#    refuses a call without a token (Unauthenticated), with a wrong one
#    (PermissionDenied), in plaintext, without a client certificate, and reflection.
#    With --robot: publishes vtest.avi frames and a question from this machine on a private
#    ROS_DOMAIN_ID and checks the containerized gateway, which presents the client
#    certificate and token (placement/tls.yaml), answers on /human_counter and /answer.
# 4. `compose/stack.sh down` (unless --keep), which checks that no container is left.
#
# Needs: scripts/setup.sh done (.venv, models, grpcurl), espeak-ng and sox, and either Docker
# with compose v2 or `apt-get install podman podman-compose runc debootstrap` (as root;
# --robot: `compose/stack.sh install-podman-compose` too). Exit 0 only when every check
# passed. Environment: ORICF_IMAGE (default oricf:local), ORICF_SMOKE_TIMEOUT (seconds to
# reach SERVING, default 600), ORICF_SMOKE_SERVICES (the services started and checked,
# default all five: "detector asr llm tts policy"; not with --robot), ORICF_ARCH (the
# images' architecture, e.g. arm64 under emulation: compose/build-image.sh), and what
# compose/stack.sh reads (docs/containers.md).
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
((ROBOT)) && [[ -n "${ORICF_SMOKE_SERVICES:-}" ]] \
    && { echo "ORICF_SMOKE_SERVICES: not with --robot (the gateway calls them all)" >&2; exit 2; }
PY="${ORICF_VENV:-.venv}/bin/python"
export ORICF_PROJECT=oricf-smoke
export ORICF_IMAGE="${ORICF_IMAGE:-oricf:local}"
export ORICF_GATEWAY_IMAGE="${ORICF_GATEWAY_IMAGE:-oricf-gateway:local}"
TIMEOUT="${ORICF_SMOKE_TIMEOUT:-600}"
read -ra SERVICES <<<"${ORICF_SMOKE_SERVICES:-detector asr llm tts policy}"
UP=()     # every container of the stack, unless only some services are checked
[[ -n "${ORICF_SMOKE_SERVICES:-}" ]] && UP=("${SERVICES[@]}")
declare -A PORTS=([detector]=50051 [asr]=50052 [llm]=50053 [tts]=50054 [policy]=50055)
declare -A RPCS=([detector]=oricf.v1.Detector/Detect [asr]=oricf.v1.SpeechRecognizer/Transcribe
                 [llm]=oricf.v1.LanguageModel/Generate [tts]=oricf.v1.SpeechSynthesizer/Synthesize
                 [policy]=oricf.v1.Policy/Act)
HEALTH=grpc.health.v1.Health/Check

step() { printf '\n==> %s\n' "$*"; }
die() { printf 'smoke-test: FAIL: %s\n' "$*" >&2; exit 1; }

STACK=(compose/stack.sh)
((ROBOT)) && STACK+=(--robot)
step "engine: compose/stack.sh check"
"${STACK[@]}" check || die "compose/stack.sh check"
eval "$("${STACK[@]}" env)"    # the same engine (and CONTAINERS_CONF) for this script
ENGINE=$ORICF_ENGINE
if ((ROBOT)); then
    export ORICF_PLACEMENT=onboard ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    ORICF_ROS_USER="$(id -u):$(id -g)"    # the check's ROS node runs as this user
    export ORICF_ROS_USER
    export ROS_DOMAIN_ID=$((RANDOM % 100 + 1))
fi
GRPCURL=$("$PY" -c 'from oricf.store import ModelStore; print(ModelStore().path("grpcurl"))')
WORK=$(mktemp -d /tmp/oricf-smoke.XXXXXX)
STARTED=0

cleanup() {
    local status=$?
    if ((status != 0)) && ((STARTED)); then
        "${STACK[@]}" logs >"$WORK/logs.txt" 2>&1 || true
        echo "--- last lines of the services' logs"; tail -60 "$WORK/logs.txt"
    fi
    if ((KEEP)); then
        echo "stack left running: ORICF_PROJECT=$ORICF_PROJECT ${STACK[*]} down"
    else
        step "tear down: compose/stack.sh down"
        "${STACK[@]}" down || status=1
    fi
    rm -rf "$WORK"
    return "$status"
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
    # shellcheck disable=SC2016  # grpcurl, not the shell, expands it
    AUTH=(-expand-headers -H 'authorization: Bearer ${ORICF_SMOKE_TOKEN}')
}

wait_serving() {
    local name=$1 port=${PORTS[$1]} start=$SECONDS
    until "$GRPCURL" "${TLS[@]}" "${SCHEMA[@]}" -max-time 3 "127.0.0.1:$port" "$HEALTH" \
            2>/dev/null | grep -q '"SERVING"'; do
        ((SECONDS - start < TIMEOUT)) || die "$name not SERVING after $TIMEOUT s"
        sleep 2
    done
    echo "$name SERVING on :$port after $((SECONDS - start)) s"
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

step "images: compose/stack.sh build"
SECONDS=0
"${STACK[@]}" build || die "image build"
echo "built in $SECONDS s"
trap cleanup EXIT
step "certificates and token (mTLS, bearer token)"
make_certs
step "start: compose/stack.sh up"
STARTED=1
"${STACK[@]}" up "${UP[@]+"${UP[@]}"}" || die "compose/stack.sh up"
step "wait for SERVING"
for name in "${SERVICES[@]}"; do wait_serving "$name"; done
ORICF_WAIT_TIMEOUT=$TIMEOUT "${STACK[@]}" wait "${SERVICES[@]}" \
    || die "the containers' health checks did not pass"
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
cleanup || die "compose/stack.sh down"
what="edge stack"
((ROBOT)) && what="edge stack and gateway"
echo "PASS: $what built, SERVING over mTLS, answered correctly with the token," \
    "refused callers without credentials, and torn down ($SECONDS s)"
