"""Deployment YAML: the shipped files, the schema's refusals, the commands it plans."""

from __future__ import annotations

import threading
import typing
from pathlib import Path

import pytest
import yaml

from oricf.config import config_dir, load_config
from oricf.demo.main import build_parser, pick_deployment
from oricf.errors import ConfigError
from oricf.gateway.config import load_pipeline
from oricf.launch.deployment import (
    ProcessPlan,
    ServiceName,
    connect_address,
    load_deployment,
    service_config_path,
)
from oricf.launch.launcher import Launcher
from oricf.services import SERVICES, load_spec
from tests.launch.helpers import shipped_pipeline, write_deployment, write_overlay

DEPLOYMENTS = sorted((config_dir() / "deployments").glob("*.yaml"))


def test_service_names_are_the_registry() -> None:
    assert set(typing.get_args(ServiceName)) == set(SERVICES)


@pytest.mark.parametrize("path", DEPLOYMENTS, ids=lambda p: p.name)
def test_shipped_deployments_validate_with_their_service_configs(path: Path) -> None:
    launcher = Launcher(load_deployment(path), sink=lambda name, line: None)
    services, gateway = launcher.plan()
    for plan in services:
        assert plan.argv[3:5] == ["serve", plan.name]
        assert Path(plan.argv[plan.argv.index("--config") + 1]).is_file()
    if gateway is not None:
        for flag, value in zip(gateway.argv, gateway.argv[1:], strict=False):
            if flag in ("--config", "--overlay"):
                assert Path(value).is_file(), value


@pytest.mark.parametrize("name", ["edge.yaml", "robot.yaml"])
def test_shipped_deployments_that_use_the_network_require_mtls_and_tokens(name: str) -> None:
    """The same files as compose/edge.yaml, and health checks with the client certificate."""
    certs = Path("/etc/oricf/certs")
    deployment = load_deployment(config_dir() / "deployments" / name)
    assert deployment.tls is not None
    assert (deployment.tls.ca, deployment.tls.cert, deployment.tls.key) == (
        certs / "ca.pem", certs / "client.pem", certs / "client.key")
    for service, entry in deployment.services.items():
        schema = load_spec(service).config_schema
        server = load_config(service_config_path(service, entry), schema, entry.overlays).server
        assert server.tls is not None and server.auth is not None, service
        assert (server.tls.cert, server.tls.key, server.tls.client_ca, server.auth.file) == (
            certs / "server.pem", certs / "server.key", certs / "ca.pem", certs / "tokens")
        assert server.reflection is False


def test_shipped_robot_deployment_starts_what_its_placement_puts_onboard() -> None:
    """Speech recognition, and the detector and language model as the edge's fallbacks: the
    placement overlay says where, the robot's listen addresses agree, nothing is rewired."""
    launcher, overlays = planned(config_dir() / "deployments" / "robot.yaml")
    placement = config_dir() / "pipelines" / "placement"
    assert [Path(o).resolve() for o in overlays] == [placement / "edge.yaml",
                                                     placement / "tls.yaml"]
    assert launcher.remote == {}  # fallbacks onboard: the gateway does not wait for the edge
    launcher.stop()


def test_shipped_local_deployment_is_everything_on_loopback() -> None:
    deployment = load_deployment(config_dir() / "deployments" / "local.yaml")
    # The services the reference pipeline calls; `models` (declared models) and `policy`
    # (a control policy) are opt-in.
    assert set(deployment.services) == set(SERVICES) - {"models", "policy"}
    assert deployment.gateway is not None
    assert all(s.listen and s.listen.startswith("127.0.0.1:")
               for s in deployment.services.values())


def overlays_of(gateway: ProcessPlan | None) -> list[str]:
    assert gateway is not None
    return [v for f, v in zip(gateway.argv, gateway.argv[1:], strict=False) if f == "--overlay"]


def planned(path: Path) -> tuple[Launcher, list[str]]:
    """The launcher after planning (nothing started) and its gateway's overlays."""
    launcher = Launcher(load_deployment(path), sink=lambda name, line: None)
    _, gateway = launcher.plan()
    return launcher, overlays_of(gateway)


def test_services_started_here_are_wired_in_by_their_listen_port(tmp_path: Path) -> None:
    onboard = write_overlay(tmp_path, {"detector": {"image": {"transport": "raw"}}})
    path = write_deployment(tmp_path, {
        "services": {"detector": {"listen": "0.0.0.0:50061"}, "asr": {}},
        "gateway": {"config": shipped_pipeline(), "overlays": [str(onboard)]}})
    launcher, overlays = planned(path)
    assert overlays[0] == str(onboard)  # the deployment's overlays first, then the wiring
    # asr listens where the pipeline says (its YAML's 127.0.0.1:50052): nothing to change
    assert yaml.safe_load(Path(overlays[-1]).read_text()) == {
        "endpoints": {"detector": {"address": "127.0.0.1:50061"}}}
    launcher.stop()  # nothing started: only the scratch folder goes


def test_an_onboard_fallback_started_here_leaves_the_edge_address(tmp_path: Path) -> None:
    edge = config_dir() / "pipelines" / "placement" / "edge.yaml"
    path = write_deployment(tmp_path, {
        "services": {"detector": {"listen": "127.0.0.1:50061"}},
        "gateway": {"config": shipped_pipeline(), "overlays": [str(edge)]}})
    launcher, overlays = planned(path)
    assert yaml.safe_load(Path(overlays[-1]).read_text()) == {
        "endpoints": {"detector": {"fallback": "127.0.0.1:50061"}}}
    merged = load_pipeline(shipped_pipeline(), overlays).endpoints["detector"]
    assert (merged.address, merged.fallback) == ("edge.local:50051", "127.0.0.1:50061")
    assert (merged.deadline_ms, merged.image.transport) == (800, "jpeg")  # still the edge's
    launcher.stop()


def test_remote_endpoints_are_waited_for_at_their_pipeline_address(tmp_path: Path) -> None:
    tls = {"ca": str(tmp_path / "ca.pem")}
    overlay = write_overlay(tmp_path, {"llm": {"address": "edge.example:50053", "tls": tls}})
    path = write_deployment(tmp_path, {
        "remote": ["llm"], "gateway": {"config": shipped_pipeline(), "overlays": [str(overlay)]}})
    launcher, overlays = planned(path)
    assert overlays == [str(overlay)]  # nothing started here, nothing to wire
    address, client = launcher.remote["llm"]
    assert address == "edge.example:50053"
    assert client is not None and client.ca == tmp_path / "ca.pem"
    launcher.stop()


@pytest.mark.parametrize(("endpoint", "message"), [
    ({"address": "edge.local:50051"},
     "services.detector: the gateway's endpoint 'detector' (address edge.local:50051; "),
    ({"address": "edge.local:50051", "fallback": "10.0.0.9:50051"},
     "never calls this machine, so the detector started here on 127.0.0.1:50061 would not "
     "be used: remove it from services, or make it the endpoint's fallback in an overlay "
     "(fallback: 127.0.0.1:50061)"),
    ({"address": "127.0.0.1:50051", "fallback": "localhost:50071"},
     "has both on this machine and neither is 127.0.0.1:50061"),
])
def test_a_started_service_the_pipeline_does_not_place_here_is_refused(
        tmp_path: Path, endpoint: dict[str, str], message: str) -> None:
    overlay = write_overlay(tmp_path, {"detector": endpoint})
    path = write_deployment(tmp_path, {
        "services": {"detector": {"listen": "127.0.0.1:50061"}},
        "gateway": {"config": shipped_pipeline(), "overlays": [str(overlay)]}})
    launcher = Launcher(load_deployment(path), sink=lambda name, line: None)
    with pytest.raises(ConfigError) as error:
        launcher.start(threading.Event())
    assert str(error.value).startswith(f"{path}: services.detector: ")
    assert message in str(error.value) and str(overlay) in str(error.value)
    assert launcher.services == []


def test_a_remote_endpoint_the_pipeline_lacks_is_refused(tmp_path: Path) -> None:
    path = write_deployment(tmp_path, {
        "remote": ["detector", "ocr"], "gateway": {"config": shipped_pipeline()}})
    with pytest.raises(ConfigError) as error:
        planned(path)
    assert str(error.value) == (f"{path}: remote[1]: the gateway's pipeline has no endpoint "
                                f"'ocr' ({shipped_pipeline()}; endpoints: asr, detector, llm)")


@pytest.mark.parametrize(("data", "message"), [
    ({"services": {"detector": {}}, "remote": ["detector"], "gateway": {"config": "x.yaml"}},
     "(top level): detector: both in services and in remote"),
    ({"services": {"detector": {}}, "remote": ["llm"]},
     "(top level): remote: only with a gateway"),
    ({"remote": {"asr": {"address": "edge:50052"}}, "gateway": {"config": "x.yaml"}},
     "remote: a list of the gateway's endpoint names to wait for; their addresses come from "
     "its pipeline and overlays (configs/pipelines/placement/), not from the deployment"),
    ({}, "nothing to run"),
    ({"services": {"camera": {}}}, "services.camera"),
    ({"services": {"detector": {"listen": "localhost"}}}, "services.detector.listen"),
    ({"services": {"asr": {"overlays": "tls.yaml"}}}, "services.asr.overlays"),
    ({"services": {"asr": {"restart": {"policy": "sometimes"}}}},
     "services.asr.restart.policy"),
    ({"services": {"asr": {}}, "stop_grace_s": -1}, "stop_grace_s"),
])
def test_bad_deployments_are_refused_naming_the_key(tmp_path: Path, data: dict[str, object],
                                                    message: str) -> None:
    path = write_deployment(tmp_path, data)
    with pytest.raises(ConfigError) as error:
        load_deployment(path)
    assert str(path) in str(error.value) and message in str(error.value)


def test_port_zero_is_refused_naming_the_service_config(tmp_path: Path) -> None:
    path = write_deployment(tmp_path, {"services": {"detector": {}}})
    service = tmp_path / "detector.yaml"
    service.write_text("server: {listen: '127.0.0.1:0'}\n")
    path = write_deployment(tmp_path, {"services": {"detector": {"config": str(service)}}})
    launcher = Launcher(load_deployment(path), sink=lambda name, line: None)
    with pytest.raises(ConfigError, match=r"detector.yaml: server.listen: port 0"):
        launcher.start(threading.Event())
    assert launcher.services == []


def test_connect_address_reaches_wildcard_listeners_on_loopback() -> None:
    assert connect_address("0.0.0.0:50051") == "127.0.0.1:50051"
    assert connect_address("[::]:50052") == "127.0.0.1:50052"
    assert connect_address("10.0.0.7:50053") == "10.0.0.7:50053"


def test_demo_edge_host_replaces_the_host_of_every_address_off_this_machine(
        tmp_path: Path) -> None:
    args = build_parser().parse_args(["--placement", "edge", "--edge-host", "10.1.2.3"])
    path, deployment = pick_deployment(args, tmp_path)
    assert path.name == "robot.yaml"
    assert deployment.gateway is not None
    pipeline = load_pipeline(deployment.gateway.config, deployment.gateway.overlays)
    endpoints = {n: (e.address, e.fallback) for n, e in pipeline.endpoints.items()}
    # The demo speaks through a synthesizer it starts on the robot, on a free port.
    tts_address, tts_fallback = endpoints.pop("tts")
    assert tts_address.startswith("127.0.0.1:") and tts_fallback is None
    assert endpoints == {
        "detector": ("10.1.2.3:50051", "127.0.0.1:50051"), "asr": ("127.0.0.1:50052", None),
        "llm": ("10.1.2.3:50053", "127.0.0.1:50053")}
