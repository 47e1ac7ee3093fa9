#!/usr/bin/env bash
# The one entry point of the container route: the same commands on Docker and on podman.
#
#   compose/stack.sh [--robot] [--project NAME] COMMAND [ARGS]
#
#   check                      engine, compose tool and version, containers.conf, whether a
#                              container starts, images, certificates; non-zero if unusable
#   build [SERVICE...]         the images, as the compose files declare them
#   up [--build] [SERVICE...]  build missing images (all with --build), start in the
#                              background; non-zero, with the logs, unless every container
#                              started and is still running
#   wait [SERVICE...]          until each service's health check passes (SERVING)
#   ps                         each service: container, state, health (SERVING, or why not)
#   logs [ARGS...]             the compose tool's logs
#   down                       stop and remove; non-zero if a container is left
#   env                        the engine settings for a shell: eval "$(compose/stack.sh env)"
#   install-podman-compose     podman-compose >= 1.0.6 into ~/.local/oricf-compose (a venv)
#
# --robot: compose/edge.yaml with compose/robot.yaml (the gateway; podman-compose >= 1.0.6).
# --project: the compose project (default $ORICF_PROJECT, else oricf).
#
# Engine: $ORICF_ENGINE (docker or podman), else Docker when its engine answers and a compose
# tool is there (`docker compose`, v2, else `docker-compose`, v1), else podman with
# podman-compose: $ORICF_PODMAN_COMPOSE, else the one install-podman-compose made, else the
# one on PATH; CONTAINERS_CONF defaults to compose/containers.conf. Images: compose/build-image.sh (base image, build context, the
# build command). Also read: ORICF_IMAGE, ORICF_GATEWAY_IMAGE, ORICF_CERTS,
# ORICF_WAIT_TIMEOUT (s, default 600), ORICF_ARCH (images of another architecture, run under
# emulation with compose/emulated.yaml). docs/containers.md.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
PC_VENV="${ORICF_COMPOSE_VENV:-$HOME/.local/oricf-compose}"
PC_MIN=1.0.3            # the oldest podman-compose the edge stack ran with (Debian bookworm)
PC_MIN_ROBOT=1.0.6      # network_mode: host without a second network
ROBOT=0 PROJECT="${ORICF_PROJECT:-oricf}"
FILES=(compose/edge.yaml)

die() { printf 'compose/stack.sh: %s\n' "$*" >&2; exit 1; }
usage() { sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; }

version_at_least() {  # $1 >= $2 (MAJOR.MINOR.PATCH), in bash: no pipe to close early
    local -a a b
    local i
    IFS=. read -ra a <<<"$1"
    IFS=. read -ra b <<<"$2"
    for i in 0 1 2; do
        ((10#${a[i]:-0} > 10#${b[i]:-0})) && return 0
        ((10#${a[i]:-0} < 10#${b[i]:-0})) && return 1
    done
    return 0
}

podman_compose_version() {  # what `podman-compose version` says, e.g. 1.0.3
    local out re='podman-composer? version +([0-9]+\.[0-9]+\.[0-9]+)'
    out=$("$1" version 2>&1) || true   # captured whole: grep -q in a pipe would break it
    [[ $out =~ $re ]] && echo "${BASH_REMATCH[1]}"
}

docker_answers() { command -v docker >/dev/null && timeout 20 docker info >/dev/null 2>&1; }

docker_compose() {  # sets COMPOSE, COMPOSE_VERSION: compose v2 (the docker plugin), else v1
    if docker compose version >/dev/null 2>&1; then
        COMPOSE=(docker compose)
        COMPOSE_VERSION=$(docker compose version --short)
    elif command -v docker-compose >/dev/null; then
        COMPOSE=(docker-compose)
        COMPOSE_VERSION=$(docker-compose version --short)
    else
        return 1
    fi
    COMPOSE_VERSION=${COMPOSE_VERSION#v}
}

pick_engine() {  # sets ENGINE, COMPOSE, COMPOSE_VERSION (and CONTAINERS_CONF for podman)
    ENGINE="${ORICF_ENGINE:-}"
    if [[ -z "$ENGINE" ]]; then
        if docker_answers && docker_compose; then ENGINE=docker
        elif command -v podman >/dev/null; then ENGINE=podman
        else die "no engine: a Docker engine with docker compose or docker-compose" \
            "(apt-get install -y docker.io docker-compose), or podman" \
            "(apt-get install -y podman podman-compose runc)"
        fi
    fi
    case "$ENGINE" in
        docker) docker_answers || die "ORICF_ENGINE=docker: no Docker engine answers (docker info)"
                docker_compose || die "ORICF_ENGINE=docker: neither \`docker compose\` (v2) nor" \
                    "docker-compose (v1) is installed: apt-get install -y docker-compose" ;;
        podman) command -v podman >/dev/null || die "ORICF_ENGINE=podman: podman is not installed"
                export CONTAINERS_CONF="${CONTAINERS_CONF:-$ROOT/compose/containers.conf}"
                pick_podman_compose ;;
        *) die "ORICF_ENGINE is docker or podman, not '$ENGINE'" ;;
    esac
}

pick_podman_compose() {
    local tool=""
    if [[ -n "${ORICF_PODMAN_COMPOSE:-}" ]]; then
        tool=$ORICF_PODMAN_COMPOSE
        [[ -x "$tool" ]] || die "ORICF_PODMAN_COMPOSE=$tool is not an executable"
    elif [[ -x "$PC_VENV/bin/podman-compose" ]]; then tool=$PC_VENV/bin/podman-compose
    else tool=$(command -v podman-compose) \
        || die "podman-compose is missing: compose/stack.sh install-podman-compose"
    fi
    COMPOSE_VERSION=$(podman_compose_version "$tool") || die "$tool version: no version number"
    version_at_least "$COMPOSE_VERSION" "$PC_MIN" \
        || die "$tool is $COMPOSE_VERSION, older than $PC_MIN: compose/stack.sh install-podman-compose"
    if ((ROBOT)) && [[ $COMMAND != down ]] && ! version_at_least "$COMPOSE_VERSION" "$PC_MIN_ROBOT"; then
        die "--robot needs podman-compose >= $PC_MIN_ROBOT (network_mode: host); $tool is" \
            "$COMPOSE_VERSION. Install one in a venv (Debian's pip refuses: externally" \
            "managed): compose/stack.sh install-podman-compose"
    fi
    PODMAN_COMPOSE=$tool
    COMPOSE=("$tool")
}

pick_python() {  # a Python with PyYAML, to read the compose files
    local py
    for py in "${ORICF_VENV:-.venv}/bin/python" "$PC_VENV/bin/python" /usr/bin/python3 python3; do
        if command -v "$py" >/dev/null && "$py" -c 'import yaml' 2>/dev/null; then PY=$py; return; fi
    done
    die "reading the compose files needs a Python with PyYAML: apt-get install -y python3-yaml"
}

read_services() {  # SERVICES, and per service: IMAGE, KIND (serve/gateway), HEALTH, BUILD args
    local name image kind health extras models
    SERVICES=()
    declare -gA IMAGE=() KIND=() HEALTH=() EXTRAS=() MODELS=()
    while IFS=$'\t' read -r name image kind health extras models; do
        SERVICES+=("$name")
        IMAGE[$name]=$image KIND[$name]=$kind HEALTH[$name]=$health
        EXTRAS[$name]=$extras MODELS[$name]=$models
    done < <("$PY" - "${FILES[@]}" <<'EOF'
import os, re, sys, yaml
variable = re.compile(r"\$\{(\w+)(?::?-([^}]*))?\}")   # ${VAR:-default}, as compose reads it
def expand(value):
    return variable.sub(lambda m: os.environ.get(m[1]) or m[2] or "", str(value))
for path in sys.argv[1:]:
    for name, service in yaml.safe_load(open(path))["services"].items():
        args = service.get("build", {}).get("args", {})
        health = "no" if service.get("healthcheck", {}).get("disable") else "yes"
        print(name, expand(service["image"]), service["command"][0], health,
              expand(args.get("EXTRAS", "")), expand(args.get("MODELS", "")), sep="\t")
EOF
    )
    ((${#SERVICES[@]})) || die "no services in ${FILES[*]}"
}

select_services() {  # NAMES: the services named (each checked), else all of them
    local name
    (($#)) || set -- "${SERVICES[@]}"
    for name in "$@"; do
        [[ -n "${IMAGE[$name]:-}" ]] || die "no service '$name' in ${FILES[*]}"
    done
    NAMES=("$@")
}

image_exists() { $ENGINE image inspect "$1" >/dev/null 2>&1; }

container_of() {  # the container of a service in this project, running or not
    local ids
    ids=$($ENGINE ps -a -q --filter "label=com.docker.compose.project=$PROJECT" \
        --filter "label=com.docker.compose.service=$1")
    echo "${ids%%$'\n'*}"
}

build_images() {  # rebuild (0: only missing images), services: each image once
    local rebuild=$1 name built=" " models
    shift
    select_services "$@"
    for name in "${NAMES[@]}"; do
        [[ $built == *" ${IMAGE[$name]} "* ]] && continue
        built+="${IMAGE[$name]} "
        ((rebuild)) || ! image_exists "${IMAGE[$name]}" || continue
        read -ra models <<<"${MODELS[$name]}"
        ORICF_ENGINE=$ENGINE compose/build-image.sh "${IMAGE[$name]}" "${EXTRAS[$name]}" \
            "${models[@]+"${models[@]}"}"
    done
}

check_certs() {  # what the services read from the certificates' folder, before starting them
    local dir="${ORICF_CERTS:-./certs}" name file missing=()
    local -a files=(ca.pem client.pem client.key tokens)
    [[ $dir == /* ]] || dir=$ROOT/compose/${dir#./}  # compose resolves it against compose/
    for name in "$@"; do [[ ${KIND[$name]} == serve ]] && files+=(server.pem server.key) && break; done
    for file in "${files[@]}"; do [[ -e "$dir/$file" ]] || missing+=("$file"); done
    ((${#missing[@]} == 0)) && return
    die "missing in $dir: ${missing[*]}. Make them once (docs/security.md):
  oricf certs compose/certs --host edge.local --host localhost --host 127.0.0.1
  cd compose/certs && sudo chgrp 10001 server.key client.key tokens && chmod 640 server.key client.key tokens"
}

health_of() {  # SERVING, or what else: the service's own health check (grpc.health.v1)
    local id state status output
    id=$(container_of "$1")
    [[ -n "$id" ]] || { echo "no container"; return; }
    state=$($ENGINE inspect -f '{{.State.Status}}' "$id")
    [[ $state == running ]] || { echo "not running ($state)"; return; }
    [[ ${HEALTH[$1]} == yes ]] || { echo "no health check"; return; }
    # podman runs health checks from systemd timers; without systemd nothing runs them
    [[ $ENGINE == podman ]] && { podman healthcheck run "$id" >/dev/null 2>&1 || true; }
    status=$($ENGINE inspect -f '{{if .State.Health}}{{.State.Health.Status}}{{end}}' "$id")
    output=$($ENGINE inspect -f '{{if .State.Health}}{{range .State.Health.Log}}{{.Output}}{{end}}{{end}}' "$id")
    output=$(tr -s '\n' ' ' <<<"$output")
    case $status in
        healthy) echo SERVING ;;
        "") echo "no health check" ;;
        *) echo "$status: ${output: -60}" ;;
    esac
}

show_failed() {  # the last log lines of a service's container
    local id
    id=$(container_of "$1")
    echo "--- $1: last log lines"
    [[ -z "$id" ]] || $ENGINE logs --tail 30 "$id" 2>&1 || true
}

cmd_up() {
    local rebuild=0 status=0 name id state bad=() log=$LOGS/up.log
    [[ ${1:-} == --build ]] && { rebuild=1; shift; }
    select_services "$@"
    local names=("${NAMES[@]}")
    check_certs "${names[@]}"
    build_images "$rebuild" "${names[@]}"
    echo "==> ${COMPOSE[*]} up -d${*:+ $*} (log: $log)"
    "${COMPOSE[@]}" up -d --no-build "$@" >"$log" 2>&1 || status=$?
    sleep "${ORICF_SETTLE_S:-5}"    # a service that cannot start exits within seconds
    for name in "${names[@]}"; do
        id=$(container_of "$name")
        state=$([[ -z "$id" ]] || $ENGINE inspect -f '{{.State.Status}}, {{.RestartCount}} restarts' "$id")
        [[ $state == "running, 0 restarts" ]] || bad+=("$name (${state:-no container})")
    done
    if ((status != 0 || ${#bad[@]})); then   # podman-compose 1.0.3 says 0 even then
        echo "--- ${COMPOSE[*]} up exited with $status; its last lines:"; tail -15 "$log"
        for name in "${bad[@]}"; do show_failed "${name%% *}"; done
        die "not started: ${bad[*]:-see above} (compose/stack.sh down removes what is left)"
    fi
    cmd_ps
}

cmd_wait() {
    local start=$SECONDS timeout="${ORICF_WAIT_TIMEOUT:-600}" name health pending=() next
    select_services "$@"
    for name in "${NAMES[@]}"; do [[ ${HEALTH[$name]} == yes ]] && pending+=("$name"); done
    while ((${#pending[@]})); do
        next=()
        for name in "${pending[@]}"; do
            health=$(health_of "$name")
            case $health in
                SERVING) echo "$name SERVING after $((SECONDS - start)) s (its health check)" ;;
                "not running"*|"no container") show_failed "$name"; die "$name: $health" ;;
                *) next+=("$name") ;;
            esac
        done
        pending=("${next[@]+"${next[@]}"}")
        ((${#pending[@]})) || break
        ((SECONDS - start < timeout)) || die "not SERVING after $timeout s: ${pending[*]} ($health)"
        sleep 3
    done
}

cmd_ps() {
    local name id info
    printf '%-10s %-28s %-24s %s\n' SERVICE CONTAINER STATE HEALTH
    for name in "${SERVICES[@]}"; do
        id=$(container_of "$name")
        if [[ -z "$id" ]]; then printf '%-10s %-28s %-24s %s\n' "$name" - "not created" -; continue; fi
        info=$($ENGINE inspect -f '{{.Name}} {{.State.Status}},{{.RestartCount}}' "$id")
        read -r cname state <<<"$info"
        printf '%-10s %-28s %-24s %s\n' "$name" "${cname#/}" "${state/,/, restarts }" \
            "$(health_of "$name")"
    done
}

project_containers() {
    $ENGINE ps -a -q --filter "label=com.docker.compose.project=$PROJECT"
}

cmd_down() {
    local log=$LOGS/down.log left
    "${COMPOSE[@]}" down >"$log" 2>&1 || { cat "$log"; die "${COMPOSE[*]} down failed"; }
    left=$(project_containers)
    if [[ -n "$left" ]]; then  # podman: a container restarting (restart policy) outlives `stop`
        echo "--- $COMPOSE_TOOL down left $(wc -w <<<"$left") container(s): removing them"
        # shellcheck disable=SC2086  # one id a word
        { $ENGINE stop -t 15 $left; $ENGINE rm -f $left; } >>"$log" 2>&1 || true
        left=$(project_containers)
        [[ -z "$left" ]] || { cat "$log"; die "containers left after down: ${left//$'\n'/ }"; }
    fi
    if [[ $ENGINE == podman ]]; then  # what podman-compose may leave: its pod, its network
        podman pod rm -f "pod_$PROJECT" >/dev/null 2>&1 || true
        podman network rm "${PROJECT}_default" >/dev/null 2>&1 || true
    fi
    echo "==> $PROJECT: down, no container left"
}

cmd_check() {
    local image="" id robot=yes
    # the robot side's network_mode: host: every docker compose (v1 and v2), podman-compose 1.0.6+
    [[ $ENGINE == docker ]] || version_at_least "$COMPOSE_VERSION" "$PC_MIN_ROBOT" \
        || robot="no, needs $PC_MIN_ROBOT: compose/stack.sh install-podman-compose"
    local version
    version=$($ENGINE --version)
    [[ $ENGINE == podman ]] || version+=", engine $(docker version -f '{{.Server.Version}}')"
    echo "engine:          $ENGINE ($version)"
    echo "compose:         $COMPOSE_TOOL $COMPOSE_VERSION (robot side: $robot)"
    [[ $ENGINE == docker ]] || echo "CONTAINERS_CONF: $CONTAINERS_CONF"
    echo "project:         $PROJECT (${FILES[*]})"
    for name in "${SERVICES[@]}"; do
        if image_exists "${IMAGE[$name]}"; then image=${IMAGE[$name]}; fi
    done
    for id in $(printf '%s\n' "${IMAGE[@]}" | sort -u); do
        echo "image:           $id $(image_exists "$id" && echo present || echo "missing (compose/stack.sh build)")"
    done
    if [[ -n "$image" ]]; then
        $ENGINE run --rm --entrypoint true "$image" >"$LOGS/check.log" 2>&1 \
            || { cat "$LOGS/check.log"; die "a container of $image does not start (CONTAINERS_CONF?)"; }
        echo "containers:      start ($image)"
    fi
    if (check_certs "${SERVICES[@]}") 2>/dev/null; then echo "certificates:    present"
    else echo "certificates:    missing: compose/stack.sh up refuses to start (docs/security.md)"; fi
}

cmd_install_podman_compose() {
    local python="${ORICF_PYTHON:-python3}"
    echo "==> $python -m venv $PC_VENV && $PC_VENV/bin/pip install 'podman-compose>=$PC_MIN_ROBOT'"
    "$python" -m venv "$PC_VENV" || die "no venv: on Debian, apt-get install -y python3-venv"
    "$PC_VENV/bin/pip" install -q "podman-compose>=$PC_MIN_ROBOT" || die "pip install failed"
    echo "podman-compose $(podman_compose_version "$PC_VENV/bin/podman-compose") in $PC_VENV;" \
        "compose/stack.sh uses it from now on"
}

while (($#)); do
    case $1 in
        --robot) ROBOT=1; FILES+=(compose/robot.yaml); shift ;;
        --project) PROJECT=${2:?--project NAME}; shift 2 ;;
        -h|--help|help) usage; exit 0 ;;
        -*) usage >&2; exit 2 ;;
        *) break ;;
    esac
done
COMMAND=${1:-}
(($#)) && shift
case $COMMAND in
    install-podman-compose) cmd_install_podman_compose; exit ;;
    check|build|up|wait|ps|logs|down|env) ;;
    *) usage >&2; exit 2 ;;
esac
# down: the robot's file too, so that no gateway container outlives the stack
[[ $COMMAND == down && $ROBOT == 0 ]] && FILES+=(compose/robot.yaml)
pick_engine
LOGS="${TMPDIR:-/tmp}/oricf-stack-$PROJECT"
mkdir -p "$LOGS"
COMPOSE_TOOL="${COMPOSE[*]}"
COMPOSE+=(-p "$PROJECT")
for file in "${FILES[@]}"; do COMPOSE+=(-f "$file"); done
# Images of another architecture (ORICF_ARCH, compose/build-image.sh) run under emulation:
# compose/emulated.yaml gives their containers the emulated CPU's /proc/cpuinfo.
if [[ -n "${ORICF_ARCH:-}" && "$ORICF_ARCH" != "$(dpkg --print-architecture)" ]]; then
    export ORICF_EMULATED_CPUINFO="$LOGS/cpuinfo-$ORICF_ARCH"
    ORICF_QEMU_CPU=$(scripts/arm64-root.sh qemu-cpu)
    export ORICF_QEMU_CPU
    scripts/arm64-root.sh cpuinfo >"$ORICF_EMULATED_CPUINFO"
    COMPOSE+=(-f compose/emulated.yaml)
fi
if [[ $COMMAND == env ]]; then
    printf 'export ORICF_ENGINE=%q\n' "$ENGINE"
    [[ $ENGINE == docker ]] || printf 'export CONTAINERS_CONF=%q ORICF_PODMAN_COMPOSE=%q\n' \
        "$CONTAINERS_CONF" "$PODMAN_COMPOSE"
    exit 0
fi
pick_python
read_services
case $COMMAND in
    check) cmd_check ;;
    build) build_images 1 "$@" ;;
    up) cmd_up "$@" ;;
    wait) cmd_wait "$@" ;;
    ps) cmd_ps ;;
    logs) "${COMPOSE[@]}" logs "$@" ;;
    down) cmd_down ;;
esac
