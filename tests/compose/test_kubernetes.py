"""Every object compose/kubernetes/ makes, as rendered by kustomize, against the Kubernetes API
schemas (kubernetes-validate, strict: unknown keys refused) of the oldest and the newest
Kubernetes it targets, and KServe's objects against KServe's CRD schemas
(tests/compose/schemas/kserve.json); then against the repository: what the objects name
exists, Services select their pods, probes ask the health port the overlay opens."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import jsonschema
import kubernetes_validate  # the dev extra: no validator, no test run (never skipped)
import pytest

from oricf.config import REPO_ROOT, read_yaml
from tests.compose.kubernetes import KUSTOMIZATIONS, Document, by_kind, render, workspace

# gRPC probes are GA from 1.27; 1.37: the newest schemas kubernetes-validate ships here.
KUBERNETES_VERSIONS = ("1.27", "1.37")
KSERVE = json.loads((Path(__file__).parent / "schemas" / "kserve.json").read_text())
OVERLAY = REPO_ROOT / "configs" / "services" / "overlays" / "kubernetes.yaml"


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Document]]:
    kubernetes = workspace(tmp_path_factory.mktemp("kubernetes"))
    return {name: render(kubernetes, name) for name in KUSTOMIZATIONS}


def strict(schema: Any) -> Any:
    """A CRD schema refusing unknown keys, as the API server does under kubectl's default
    strict field validation (keys it would otherwise drop silently)."""
    if isinstance(schema, list):
        return [strict(s) for s in schema]
    if not isinstance(schema, dict):
        return schema
    schema = {k: strict(v) for k, v in schema.items()}
    if "properties" in schema and "additionalProperties" not in schema \
            and not schema.get("x-kubernetes-preserve-unknown-fields"):
        schema["additionalProperties"] = False
    return schema


KSERVE_VALIDATORS = {kind: (entry["apiVersion"],
                            jsonschema.Draft7Validator(strict(entry["schema"])))
                     for kind, entry in KSERVE["kinds"].items()}


def problems(document: Document, version: str) -> list[str]:
    """What is wrong with one object, empty when it is valid."""
    kind = document["kind"]
    if kind in KSERVE_VALIDATORS:
        api_version, validator = KSERVE_VALIDATORS[kind]
        if document["apiVersion"] != api_version:
            return [f"apiVersion {document['apiVersion']}, the schema is {api_version}'s"]
        return [f"{'.'.join(map(str, e.path))}: {e.message}"
                for e in validator.iter_errors(document)]
    try:
        kubernetes_validate.validate(document, version, strict=True)
    except kubernetes_validate.ValidationError as exc:
        return [f"{'.'.join(map(str, exc.path))}: {exc.message}"]
    except kubernetes_validate.SchemaNotFoundError as exc:
        return [exc.message]
    return []


def name(document: Document) -> str:
    return f"{document['kind']}/{document['metadata']['name']}"


@pytest.mark.parametrize("version", KUBERNETES_VERSIONS)
@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_every_object_is_valid(rendered: dict[str, list[Document]], kustomization: str,
                               version: str) -> None:
    documents = rendered[kustomization]
    assert len(documents) >= 14
    errors = {name(d): p for d in documents if (p := problems(d, version))}
    assert not errors


@pytest.mark.parametrize(("kind", "path", "value"), [
    ("Deployment", ["spec", "template", "spec", "containers", 0, "livenessProbe", "grpc",
                    "tls"], True),                                    # no such key
    ("HorizontalPodAutoscaler", ["spec", "maxReplicas"], "six"),      # wrong type
    ("InferenceService", ["spec", "predictor", "model", "modelFromat"], {"name": "x"}),
    ("InferenceService", ["spec", "predictor", "onnx"], {}),          # cut from the schema
    ("ServingRuntime", ["spec", "containers", 0, "ports", 0, "containerPort"], "8001"),
])
def test_the_validation_refuses_a_broken_object(rendered: dict[str, list[Document]],
                                                kind: str, path: list[Any], value: Any) -> None:
    document = copy.deepcopy(next(d for d in rendered["kserve"] if d["kind"] == kind))
    node = document
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    assert problems(document, KUBERNETES_VERSIONS[-1])


def volume_sources(pod: Document) -> list[tuple[str, str]]:
    return [("ConfigMap", v["configMap"]["name"]) if "configMap" in v
            else ("Secret", v["secret"]["secretName"])
            for v in pod["volumes"] if "configMap" in v or "secret" in v]


def test_what_the_objects_name_exists(rendered: dict[str, list[Document]]) -> None:
    documents = rendered["kserve"]
    deployments = by_kind(documents, "Deployment")
    runtimes = by_kind(documents, "ServingRuntime")
    assert set(deployments) == {"detector", "asr", "llm", "tts", "policy"}
    pods = [d["spec"]["template"]["spec"] for d in deployments.values()]
    pods += [r["spec"] for r in runtimes.values()]
    for kind, source in {s for pod in pods for s in volume_sources(pod)}:
        assert source in by_kind(documents, kind), f"{kind} {source} is not made"
    for hpa in by_kind(documents, "HorizontalPodAutoscaler").values():
        assert hpa["spec"]["scaleTargetRef"]["name"] in deployments
    for service in by_kind(documents, "Service").values():
        template = deployments[service["metadata"]["name"]]["spec"]["template"]
        assert service["spec"]["selector"].items() <= template["metadata"]["labels"].items()
        assert service["spec"]["clusterIP"] == "None"  # headless: the gateway balances
        container_ports = {p["name"] for p in template["spec"]["containers"][0]["ports"]}
        assert {p["targetPort"] for p in service["spec"]["ports"]} <= container_ports
        assert "health" not in {p["name"] for p in service["spec"]["ports"]}
    for isvc in by_kind(documents, "InferenceService").values():
        assert isvc["spec"]["predictor"]["model"]["runtime"] in runtimes


def test_probes_ask_the_plaintext_health_port_and_pods_are_locked_down(
        rendered: dict[str, list[Document]]) -> None:
    health_port = int(read_yaml(OVERLAY)["server"]["health_listen"].rpartition(":")[2])
    documents = rendered["kserve"]
    pods = {n: d["spec"]["template"]["spec"]
            for n, d in by_kind(documents, "Deployment").items()}
    pods |= {n: r["spec"] for n, r in by_kind(documents, "ServingRuntime").items()}
    for name_, pod in pods.items():
        (container,) = pod["containers"]
        for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
            assert container[probe]["grpc"] == {"port": health_port}, (name_, probe)
        args = container["args"]
        assert "/etc/oricf/services/tls.yaml" in args, name_    # mTLS and a token
        assert "/etc/oricf/services/kubernetes.yaml" in args, name_
        context = container.get("securityContext", {})
        assert context["readOnlyRootFilesystem"] and not context["allowPrivilegeEscalation"]
        assert context["capabilities"] == {"drop": ["ALL"]}
        assert container["resources"]["requests"] and container["resources"]["limits"]
        user = pod.get("securityContext", context)
        assert user.get("runAsUser", context.get("runAsUser")) == 10001 and user["runAsNonRoot"]
    keys = {k for s in by_kind(documents, "Secret").values() for k in s["data"]}
    assert keys == {"ca.pem", "server.pem", "server.key", "tokens"}  # no client key, no CA key


def test_the_network_policy_admits_each_pods_grpc_port_and_its_metrics_to_prometheus(
        rendered: dict[str, list[Document]]) -> None:
    health_port = int(read_yaml(OVERLAY)["server"]["health_listen"].rpartition(":")[2])
    documents = rendered["kserve"]
    (policy,) = by_kind(documents, "NetworkPolicy").values()
    anyone, prometheus = policy["spec"]["ingress"]
    assert "from" not in anyone and prometheus["from"][0]["podSelector"]["matchLabels"] == {
        "app.kubernetes.io/name": "prometheus"}
    open_ports = {p["port"] for p in anyone["ports"]}
    metrics_ports = {p["port"] for p in prometheus["ports"]}
    containers = [d["spec"]["template"]["spec"]["containers"][0]
                  for d in by_kind(documents, "Deployment").values()]
    containers += [r["spec"]["containers"][0]
                   for r in by_kind(documents, "ServingRuntime").values()]
    for container in containers:
        ports = {p["name"]: p["containerPort"] for p in container["ports"]}
        grpc_port = next(port for name_, port in ports.items() if name_ not in
                         ("metrics", "health"))
        assert grpc_port in open_ports, container["name"]
        assert ports["metrics"] in metrics_ports, container["name"]
        assert health_port not in open_ports | metrics_ports   # the plaintext probe port
