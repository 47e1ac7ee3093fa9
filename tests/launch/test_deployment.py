"""Deployment YAML: the shipped files, the schema's refusals, the commands it plans."""

from __future__ import annotations

import threading
import typing
from pathlib import Path

import pytest
import yaml

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.launch.demo import build_parser, pick_deployment
from oricf.launch.deployment import ServiceName, connect_address, load_deployment
from oricf.launch.launcher import Launcher
from oricf.services import REGISTRY
from tests.launch.helpers import shipped_pipeline, write_deployment

DEPLOYMENTS = sorted((config_dir() / "deployments").glob("*.yaml"))


def test_service_names_are_the_registry() -> None:
    assert set(typing.get_args(ServiceName)) == set(REGISTRY)


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


def test_shipped_local_deployment_is_everything_on_loopback() -> None:
    deployment = load_deployment(config_dir() / "deployments" / "local.yaml")
    # The services the reference pipeline calls; `models` (declared models) is opt-in.
    assert set(deployment.services) == set(REGISTRY) - {"models"}
    assert deployment.gateway is not None
    assert all(s.listen and s.listen.startswith("127.0.0.1:")
               for s in deployment.services.values())


def test_gateway_gets_every_service_address_through_an_overlay(tmp_path: Path) -> None:
    path = write_deployment(tmp_path, {
        "services": {"detector": {"listen": "0.0.0.0:50061"}},
        "remote": {"llm": {"address": "edge.example:50053"}},
        "gateway": {"config": shipped_pipeline(), "overlays": [shipped_pipeline()],
                    "profile": "edge"}})
    launcher = Launcher(load_deployment(path), sink=lambda name, line: None)
    _, gateway = launcher.plan()
    assert gateway is not None
    overlays = [v for f, v in zip(gateway.argv, gateway.argv[1:], strict=False)
                if f == "--overlay"]
    assert overlays[0] == shipped_pipeline()  # the deployment's overlays first, then ours
    generated = yaml.safe_load(Path(overlays[-1]).read_text())
    assert generated == {"endpoints": {"detector": {"address": "127.0.0.1:50061"},
                                       "llm": {"address": "edge.example:50053"}}}
    assert gateway.argv[-2:] == ["--profile", "edge"]
    launcher.stop()  # nothing started: only the scratch folder goes


@pytest.mark.parametrize(("data", "message"), [
    ({"services": {"detector": {}}, "remote": {"detector": {"address": "h:1"}}},
     "(top level): detector: both in services and in remote"),
    ({}, "nothing to run"),
    ({"services": {"camera": {}}}, "services.camera"),
    ({"services": {"detector": {"listen": "localhost"}}}, "services.detector.listen"),
    ({"remote": {"asr": {"address": "edge:99999"}}, "gateway": {"config": "x.yaml"}},
     "remote.asr.address"),
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


def test_demo_edge_host_replaces_the_host_of_every_remote_service() -> None:
    args = build_parser().parse_args(["--placement", "edge", "--edge-host", "127.0.0.1"])
    path, deployment = pick_deployment(args)
    assert path.name == "robot.yaml"
    assert {n: r.address for n, r in deployment.remote.items()} == {
        "detector": "127.0.0.1:50051", "asr": "127.0.0.1:50052", "llm": "127.0.0.1:50053"}
