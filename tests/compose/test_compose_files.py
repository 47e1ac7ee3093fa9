"""The compose files against the Compose specification (its JSON schema, from the model
store), and against the repository: mounted configs exist, published ports are the ports
the services listen on, baked models are the ones the services load, and every service
requires mTLS and a token, which its health check and the robot's gateway present."""

from __future__ import annotations

import itertools
import json
import os
import re
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from oricf.config import REPO_ROOT, config_dir, read_yaml
from oricf.gateway.config import load_pipeline
from oricf.models.declaration import load_declaration
from oricf.store import ModelStore

COMPOSE = REPO_ROOT / "compose"
FILES = [COMPOSE / "edge.yaml", COMPOSE / "robot.yaml"]
CONTAINER_CONFIGS = "/etc/oricf"
CERTS = "/etc/oricf/certs"                       # where the deployment's certificates are
CERTS_MOUNT = "${ORICF_CERTS:-./certs}:/etc/oricf/certs:ro"
VARIABLE = re.compile(r"\$\{(\w+)(?::-([^}]*))?\}")


def validator() -> jsonschema.Draft201909Validator:
    schema = json.loads(ModelStore().path("compose-spec").read_text())
    return jsonschema.Draft201909Validator(schema)


def load(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(path.read_text())
    return data


def with_defaults(text: str) -> str:
    """${VAR:-default} -> default, as compose does with VAR unset."""
    return VARIABLE.sub(lambda m: m.group(2) or "", text)


def mounts(service: dict[str, Any]) -> dict[str, Path]:
    """Container path -> host path (resolved against compose/) of each bind mount."""
    result = {}
    for volume in service.get("volumes", []):
        host, container = with_defaults(volume).split(":")[:2]
        result[container] = (COMPOSE / host).resolve()
    return result


def model_services(data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {name: s for name, s in data["services"].items() if s["command"][0] == "serve"}


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_compose_file_follows_the_compose_specification(path: Path) -> None:
    errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}"
              for e in validator().iter_errors(load(path))]
    assert errors == []


def test_the_schema_refuses_what_compose_refuses() -> None:
    data = load(COMPOSE / "edge.yaml")
    data["services"]["detector"]["restart_policy"] = "always"  # not a service key
    data["services"]["asr"]["ports"] = [{"target": "fifty"}]
    messages = [e.message for e in validator().iter_errors(data)]
    assert any("restart_policy" in m for m in messages), messages
    assert any("fifty" in m for m in messages), messages


# Host paths other than configs that a service may mount (the gateway: DDS shared memory;
# the certificates, tested below).
SYSTEM_MOUNTS = {"/dev/shm:/dev/shm", CERTS_MOUNT}


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_mounted_config_exists_and_is_read_only(path: Path) -> None:
    for name, service in load(path)["services"].items():
        volumes = [v for v in service.get("volumes", []) if v not in SYSTEM_MOUNTS]
        for volume in volumes:
            assert volume.endswith(":ro"), f"{name}: {volume} is writable"
        for container, host in mounts({"volumes": volumes}).items():
            assert host.exists(), f"{name}: {host} (mounted at {container}) is missing"
            assert config_dir().resolve() in host.parents, f"{name}: {host} is not a config"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_config_a_command_names_is_mounted(path: Path) -> None:
    for name, service in load(path)["services"].items():
        command = [with_defaults(part) for part in service["command"]]
        named = [v for f, v in itertools.pairwise(command)
                 if f in ("--config", "--overlay")]
        assert named, f"{name}: no config named"
        for container_path in named:
            host = resolve_in_mounts(mounts(service), container_path)
            assert host is not None and host.is_file(), f"{name}: {container_path}"


def resolve_in_mounts(table: dict[str, Path], container_path: str) -> Path | None:
    for container, host in table.items():
        if container_path == container:
            return host
        if container_path.startswith(container + "/"):
            return host / container_path[len(container) + 1:]
    return None


def test_published_ports_and_health_checks_match_the_listen_ports() -> None:
    services = model_services(load(COMPOSE / "edge.yaml"))
    assert set(services) == {"detector", "asr", "llm", "tts", "policy"}
    for name, service in services.items():
        assert service["command"][:2] == ["serve", name]
        config_path = service["command"][service["command"].index("--config") + 1]
        host_config = resolve_in_mounts(mounts(service), config_path)
        assert host_config == (config_dir() / "services" / f"{name}.yaml").resolve()
        # the shipped YAML keeps to loopback; the container listens on every interface
        assert read_yaml(host_config)["server"]["listen"].startswith("127.0.0.1:")
        listen = service["command"][service["command"].index("--listen") + 1]
        host, _, port = listen.rpartition(":")
        assert host == "0.0.0.0", f"{name}: a container must listen on every interface"
        assert port == read_yaml(host_config)["server"]["listen"].rpartition(":")[2]
        metrics = service["command"][service["command"].index("--metrics-listen") + 1]
        mport = metrics.rpartition(":")[2]
        # gRPC on the network (mTLS); Prometheus metrics published to this host only
        assert service["ports"] == [f"{port}:{port}", f"127.0.0.1:{mport}:{mport}"]
        assert service["healthcheck"]["test"][1:5] == [
            "/opt/oricf/venv/bin/python", "-m", "oricf.launch.health", f"127.0.0.1:{port}"]
        assert service["restart"] in ("always", "unless-stopped", "on-failure")


def test_images_bake_the_models_the_services_load() -> None:
    services = model_services(load(COMPOSE / "edge.yaml"))
    store = ModelStore()
    for name, service in services.items():
        baked = service["build"]["args"]["MODELS"].split()
        for model in baked:
            store.entry(model)  # raises for a name the catalog lacks
        path = config_dir() / "services" / f"{name}.yaml"
        config = read_yaml(path)
        if "voices" in config:  # speech synthesis: the catalog entries of its voices
            models = [v["model"] for v in config["voices"].values() if "model" in v]
            assert models and set(models) <= set(baked), f"{name}: a voice the image lacks"
            continue
        model = config["model"]
        if isinstance(model, str):  # a declared model: the catalog entry of its weights
            container = str(Path("/etc/oricf/services") / model)
            mounted = resolve_in_mounts(mounts(service), os.path.normpath(container))
            assert mounted is not None and mounted.is_file(), f"{name}: {model} not mounted"
            weights = load_declaration(path.parent / model).weights
            assert weights is not None and weights.catalog is not None
            model = {"name": weights.catalog}
        assert model["name"] in baked, f"{name} loads a model the image lacks"


def test_the_image_converts_the_baked_weights_that_need_it() -> None:
    """The services' user cannot write the image's store: a declared model whose weights
    are converted (the policy service's) must be converted during the build."""
    text = (COMPOSE / "Dockerfile").read_text()
    models_stage = text.split("\nFROM ")[2]
    assert models_stage.startswith("${BASE_IMAGE} AS models")
    pull = models_stage.index("oricf models pull $MODELS")
    assert models_stage.index("convert_models.py $MODELS") > pull
    assert "COPY configs/models/ /opt/oricf/configs/models/" in models_stage
    assert "COPY compose/convert_models.py " in models_stage
    rules = (COMPOSE / "Dockerfile.dockerignore").read_text().splitlines()
    assert "!compose/convert_models.py" in rules  # in the build context


def test_dockerfile_follows_the_container_rules() -> None:
    text = (COMPOSE / "Dockerfile").read_text()
    instructions = re.findall(r"^(ENTRYPOINT|CMD|USER|HEALTHCHECK|ARG BASE_IMAGE)(.*)$", text,
                              re.MULTILINE)
    found = {key: value.strip() for key, value in instructions}
    assert found["ARG BASE_IMAGE"] == "=python:3.11-slim"
    json.loads(found["ENTRYPOINT"])  # exec form: JSON arrays, no shell between
    json.loads(found["CMD"])         # the HEALTHCHECK line's CMD is on its next line
    assert found["USER"] not in ("root", "0")
    # fixed ids: the deployment gives the keys and token to group 10001 (compose/edge.yaml)
    assert "--uid 10001 --gid 10001" in text and "groupadd --system --gid 10001" in text
    healthcheck = text[text.index("HEALTHCHECK"):].split("CMD", 1)[1].strip()
    assert json.loads(healthcheck.splitlines()[0]) == [
        "/opt/oricf/venv/bin/python", "-m", "oricf.launch.health"]


def test_robot_gateway_uses_the_host_network_and_no_model_health_check() -> None:
    gateway = load(COMPOSE / "robot.yaml")["services"]["gateway"]
    assert gateway["network_mode"] == "host" and gateway["ipc"] == "host"
    assert "/dev/shm:/dev/shm" in gateway["volumes"]
    assert gateway["healthcheck"] == {"disable": True}
    assert gateway["build"]["args"]["EXTRAS"] == "ros"


def flags(command: list[str]) -> dict[str, str | None]:
    """--flag value pairs of a command line (None for a flag without a value)."""
    result: dict[str, str | None] = {}
    for i, part in enumerate(command):
        if part.startswith("--"):
            following = command[i + 1] if i + 1 < len(command) else "--"
            result[part] = None if following.startswith("--") else following
    return result


def test_every_service_requires_mtls_and_a_token_and_serves_no_reflection() -> None:
    for name, service in model_services(load(COMPOSE / "edge.yaml")).items():
        assert CERTS_MOUNT in service["volumes"], f"{name}: certificates not mounted read-only"
        given = flags(service["command"])
        assert given.get("--tls-cert") == f"{CERTS}/server.pem", name
        assert given.get("--tls-key") == f"{CERTS}/server.key", name
        assert given.get("--tls-client-ca") == f"{CERTS}/ca.pem", name
        assert given.get("--auth-token-file") == f"{CERTS}/tokens", name
        assert "--no-reflection" in given, name


def test_health_checks_present_the_client_certificate() -> None:
    for name, service in model_services(load(COMPOSE / "edge.yaml")).items():
        given = flags(service["healthcheck"]["test"])
        assert given.get("--tls-ca") == f"{CERTS}/ca.pem", name
        assert given.get("--tls-cert") == f"{CERTS}/client.pem", name
        assert given.get("--tls-key") == f"{CERTS}/client.key", name


def test_robot_gateway_presents_the_certificate_and_token_of_the_same_folder() -> None:
    gateway = load(COMPOSE / "robot.yaml")["services"]["gateway"]
    assert CERTS_MOUNT in gateway["volumes"]
    assert gateway["group_add"] == ["10001"]   # the group the keys and token are given to
    overlays = [with_defaults(v) for f, v in itertools.pairwise(gateway["command"])
                if f == "--overlay"]
    host_files = [resolve_in_mounts(mounts(gateway), overlay) for overlay in overlays]
    assert all(host is not None for host in host_files)
    pipeline = load_pipeline(config_dir() / "pipelines" / "people_qa.yaml",
                             [host for host in host_files if host is not None])
    for name, endpoint in pipeline.endpoints.items():
        assert endpoint.tls is not None and endpoint.token is not None, name
        assert endpoint.token.file is not None
        paths = [endpoint.tls.ca, endpoint.tls.cert, endpoint.tls.key, endpoint.token.file]
        assert [str(p) for p in paths] == [f"{CERTS}/{f}" for f in
                                           ("ca.pem", "client.pem", "client.key", "tokens")]


def test_certificates_stay_out_of_git_and_images() -> None:
    ignored = (COMPOSE / "certs" / ".gitignore").read_text().split()
    assert "*" in ignored and "!.gitignore" in ignored
    lines = (COMPOSE / "Dockerfile.dockerignore").read_text().splitlines()
    rules = [line for line in lines if line and not line.startswith("#")]
    assert rules[0] == "*" and not any("certs" in rule for rule in rules)  # build context
