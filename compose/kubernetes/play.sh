#!/usr/bin/env bash
# Runs the pods of compose/kubernetes/services on podman, as a cluster's kubelet would: the
# rendered manifests' Deployments, ConfigMaps and Secret through `podman kube play`, from the
# image compose/stack.sh builds (docs/kubernetes.md, "On podman").
#
#   compose/kubernetes/play.sh up [DEPLOYMENT...]      render, play (all Deployments, or
#                                                      those named), wait until each pod is SERVING
#   compose/kubernetes/play.sh ps                      each pod: its address, health
#   compose/kubernetes/play.sh render [DEPLOYMENT...]  what `up` plays, on stdout
#   compose/kubernetes/play.sh down      remove the pods and the volumes and secrets they made
#
# 1. Render: kustomize (or kubectl kustomize) of compose/kubernetes/services, with the
#    certificates of compose/kubernetes/certs ($ORICF_KUBE_CERTS) and the image
#    $ORICF_IMAGE (default oricf:local; build it with ORICF_ENGINE=podman compose/stack.sh build).
# 2. Keep what podman runs: Deployments, ConfigMaps, Secrets. What a cluster adds (the
#    Namespace, the headless Services and their DNS, HorizontalPodAutoscalers, the
#    NetworkPolicy) is left out and named.
# 3. Work around podman 4.3 (Debian bookworm): before 4.4 a Secret volume panics without
#    `optional` and gets its files still base64-encoded, so a Secret is played as a ConfigMap
#    of its decoded files; no podman creates the folders of a ConfigMap item's path
#    (labels/coco80.txt, policies/hopper.yaml), so their volumes are made first with those
#    folders in them (one volume per ConfigMap: pods that mount one share its items); podman
#    publishes each containerPort on the host's every address, so the containers' `ports`
#    (declarations only, in Kubernetes) are left out and each pod is reached at its address.
# 4. `podman kube play`, then each pod's own health port (50050, grpc.health.v1, plaintext)
#    is asked from inside the pod as the kubelet's gRPC probe would, until SERVING
#    ($ORICF_WAIT_TIMEOUT s, default 600). podman runs no gRPC probes itself.
# Needs root, podman with catatonit, kustomize or kubectl, a Python with PyYAML.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
cd "$ROOT"
CERTS="${ORICF_KUBE_CERTS:-compose/kubernetes/certs}"
IMAGE="${ORICF_IMAGE:-oricf:local}"
WORK="${TMPDIR:-/tmp}/oricf-kube-play"
PLAYED=$WORK/played.yaml      # what `up` played, until `down`
NEXT=$WORK/next.yaml
HEALTH_PORT=50050
export CONTAINERS_CONF="${CONTAINERS_CONF:-$ROOT/compose/containers.conf}"

die() { printf 'compose/kubernetes/play.sh: %s\n' "$*" >&2; exit 1; }
usage() { sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; }

pick_python() {
    local py
    for py in "${ORICF_VENV:-.venv}/bin/python" /usr/bin/python3 python3; do
        if command -v "$py" >/dev/null && "$py" -c 'import yaml' 2>/dev/null; then PY=$py; return; fi
    done
    die "reading the manifests needs a Python with PyYAML: apt-get install -y python3-yaml"
}

kustomize_command() {
    if command -v kustomize >/dev/null; then KUSTOMIZE=(kustomize build)
    elif command -v kubectl >/dev/null; then KUSTOMIZE=(kubectl kustomize)
    else die "kustomize or kubectl is needed to render compose/kubernetes"
    fi
    KUSTOMIZE+=(--load-restrictor LoadRestrictionsNone)
}

podman_before() {  # podman's version is older than $1 (MAJOR.MINOR)
    local version
    version=$(podman version -f '{{.Client.Version}}')
    IFS=. read -r major minor _ <<<"$version"
    IFS=. read -r want_major want_minor <<<"$1"
    ((10#$major < want_major || (10#$major == want_major && 10#$minor < want_minor)))
}

render() {  # the manifests podman plays (Deployments: all, or those named), into $NEXT
    local files=(ca.pem server.pem server.key tokens) file copy secrets_as=secret
    for file in "${files[@]}"; do
        [[ -e "$CERTS/$file" ]] || die "missing $CERTS/$file. Make the certificates once:
  oricf certs $CERTS --host detector.oricf.svc.cluster.local --host asr.oricf.svc.cluster.local --host llm.oricf.svc.cluster.local --host tts.oricf.svc.cluster.local --host policy.oricf.svc.cluster.local"
    done
    mkdir -p "$WORK"
    # kustomize reads ../certs: a copy of the tree when the certificates live elsewhere
    copy=$(mktemp -d "$WORK/tree.XXXXXX")
    mkdir -p "$copy/compose/kubernetes/certs"
    cp -r compose/kubernetes/services "$copy/compose/kubernetes/"
    cp -r configs "$copy/"
    cp "${files[@]/#/$CERTS/}" "$copy/compose/kubernetes/certs/"
    "${KUSTOMIZE[@]}" "$copy/compose/kubernetes/services" >"$WORK/rendered.yaml" \
        || { rm -rf "$copy"; die "kustomize failed"; }
    rm -rf "$copy"
    podman_before 4.4 && secrets_as=configmap
    "$PY" - "$WORK/rendered.yaml" "$IMAGE" "$secrets_as" "$@" >"$NEXT" <<'EOF'
import base64, sys, yaml
rendered, image, secrets_as, *asked = sys.argv[1:]
played, left_out, found = [], [], set()
for doc in yaml.safe_load_all(open(rendered)):
    if not doc:
        continue
    kind, name = doc["kind"], doc["metadata"]["name"]
    if kind not in ("Deployment", "ConfigMap", "Secret"):
        left_out.append(f"{kind}/{name}")
        continue
    if kind == "Deployment" and asked and name not in asked:
        continue
    found.add(name)
    if kind == "Secret" and secrets_as == "configmap":
        data = {k: base64.b64decode(v).decode() for k, v in doc.get("data", {}).items()}
        doc = {"apiVersion": "v1", "kind": "ConfigMap", "metadata": doc["metadata"], "data": data}
    if kind == "Deployment":
        pod = doc["spec"]["template"]["spec"]
        for container in pod["containers"]:
            container["image"] = image
            # podman publishes a containerPort on every host address (a cluster does not):
            # the services listen on their ports anyway, reached at the pod's address
            container.pop("ports", None)
        for volume in pod.get("volumes", []):
            if "secret" in volume and secrets_as == "configmap":
                secret = volume.pop("secret")
                volume["configMap"] = {"name": secret["secretName"]}
    played.append(doc)
if set(asked) - found:
    sys.exit(f"no Deployment {' '.join(sorted(set(asked) - found))} in the manifests")
print("left to a cluster:", " ".join(left_out), file=sys.stderr)
yaml.safe_dump_all(played, sys.stdout, sort_keys=False)
EOF
    [[ -s "$NEXT" ]] || die "nothing to play"
}

item_folders() {  # VOLUME FOLDER lines: the folders that ConfigMap items' paths need
    "$PY" - "$PLAYED" <<'EOF'
import posixpath, sys, yaml
for doc in yaml.safe_load_all(open(sys.argv[1])):
    if doc["kind"] != "Deployment":
        continue
    for volume in doc["spec"]["template"]["spec"].get("volumes", []):
        source = volume.get("configMap") or {}
        for item in source.get("items", []):
            folder = posixpath.dirname(item["path"])
            if folder:
                print(source["name"], folder)
EOF
}

pods() {  # the pods `podman kube play` makes: NAME-pod-I for each Deployment's replicas
    "$PY" - "$PLAYED" <<'EOF'
import sys, yaml
for doc in yaml.safe_load_all(open(sys.argv[1])):
    if doc["kind"] == "Deployment":
        container = doc["spec"]["template"]["spec"]["containers"][0]["name"]
        for i in range(doc["spec"].get("replicas", 1)):
            print(f"{doc['metadata']['name']}-pod-{i}", container)
EOF
}

address_of() {  # the pod's IP address on podman's network
    local infra
    infra=$(podman pod inspect -f '{{.InfraContainerID}}' "$1")
    podman inspect -f '{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}' "$infra"
}

health_of() {  # SERVING, or what else: the pod's health port asked from inside the pod
    local pod=$1 container=$2 state
    state=$(podman inspect -f '{{.State.Status}}' "$pod-$container" 2>/dev/null) \
        || { echo "no container"; return; }
    [[ $state == running ]] || { echo "not running ($state)"; return; }
    if podman exec "$pod-$container" python -m oricf.launch.health "127.0.0.1:$HEALTH_PORT" \
            >/dev/null 2>&1; then echo SERVING
    else echo "not SERVING yet"; fi
}

cmd_up() {  # DEPLOYMENT...: those only
    local volume folder mountpoint start=$SECONDS timeout="${ORICF_WAIT_TIMEOUT:-600}"
    local pod container health pending next
    podman image exists "$IMAGE" \
        || die "no image $IMAGE in podman: ORICF_ENGINE=podman compose/stack.sh build detector"
    [[ ! -e "$PLAYED" ]] || cmd_down >/dev/null     # what an earlier `up` left
    render "$@"
    mv "$NEXT" "$PLAYED"
    while read -r volume folder; do
        podman volume exists "$volume" || podman volume create "$volume" >/dev/null
        mountpoint=$(podman volume inspect -f '{{.Mountpoint}}' "$volume")
        mkdir -p "$mountpoint/$folder"
    done < <(item_folders)
    echo "==> podman kube play $PLAYED"
    podman kube play "$PLAYED" >"$WORK/play.log" 2>&1 \
        || { cat "$WORK/play.log"; die "podman kube play failed"; }
    mapfile -t pending < <(pods)
    while ((${#pending[@]})); do
        next=()
        for line in "${pending[@]}"; do
            read -r pod container <<<"$line"
            health=$(health_of "$pod" "$container")
            case $health in
                SERVING) echo "$pod SERVING after $((SECONDS - start)) s on $(address_of "$pod"):$HEALTH_PORT" ;;
                "not running"*|"no container")
                    podman logs --tail 30 "$pod-$container" >&2 || true
                    die "$pod: $health" ;;
                *) next+=("$line") ;;
            esac
        done
        pending=("${next[@]+"${next[@]}"}")
        ((${#pending[@]})) || break
        ((SECONDS - start < timeout)) || die "not SERVING after $timeout s: ${pending[*]}"
        sleep 2
    done
}

cmd_ps() {
    local pod container
    [[ -e "$PLAYED" ]] || die "nothing played here (compose/kubernetes/play.sh up)"
    printf '%-18s %-14s %s\n' POD ADDRESS HEALTH
    while read -r pod container; do
        if podman pod exists "$pod"; then
            printf '%-18s %-14s %s\n' "$pod" "$(address_of "$pod")" "$(health_of "$pod" "$container")"
        else
            printf '%-18s %-14s %s\n' "$pod" - "no pod"
        fi
    done < <(pods)
}

cmd_down() {
    local name kind
    [[ -e "$PLAYED" ]] || { echo "==> nothing played here"; return; }
    while read -r name _; do   # SIGTERM, then terminationGracePeriodSeconds as rendered
        if podman pod exists "$name"; then
            podman pod stop -t 15 "$name" >>"$WORK/down.log" 2>&1 || true
            podman pod rm -f "$name" >>"$WORK/down.log" 2>&1 || true
        fi
    done < <(pods)
    while read -r kind name; do   # the volumes and secrets kube play made stay otherwise
        podman volume rm -f "$name" >/dev/null 2>&1 || true
        [[ $kind == Secret ]] && { podman secret rm "$name" >/dev/null 2>&1 || true; }
    done < <("$PY" -c 'import sys, yaml
for d in yaml.safe_load_all(open(sys.argv[1])):
    if d["kind"] in ("ConfigMap", "Secret"): print(d["kind"], d["metadata"]["name"])' "$PLAYED")
    while read -r name _; do
        ! podman pod exists "$name" || die "pod $name is left"
    done < <(pods)
    rm -f "$PLAYED"
    echo "==> down, no pod left"
}

case ${1:-} in
    up|ps|render|down) ;;
    -h|--help|help) usage; exit 0 ;;
    *) usage >&2; exit 2 ;;
esac
command -v podman >/dev/null || die "podman is not installed: apt-get install -y podman catatonit"
pick_python
case $1 in
    up) shift; kustomize_command; cmd_up "$@"; cmd_ps ;;
    ps) cmd_ps ;;
    render) shift; kustomize_command; render "$@"; cat "$NEXT" ;;
    down) cmd_down ;;
esac
