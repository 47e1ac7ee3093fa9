"""`oricf up` as a real process on a detector-only deployment on a free port."""

from __future__ import annotations

import os
import re
import signal
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import grpc
import pytest

from oricf.cli import main as oricf_main
from oricf.config import config_dir
from oricf.launch import health
from tests.launch.helpers import (
    OricfCommand,
    alive,
    group_members,
    service_entry,
    shipped_pipeline,
    write_deployment,
    write_overlay,
)
from tests.support.data import video_path
from tests.support.processes import free_port

RUNNING = r"deployment \S+ running"


@contextmanager
def oricf_up(path: Path) -> Iterator[OricfCommand]:
    command = OricfCommand("up", str(path))
    try:
        yield command
    finally:
        command.kill()


def assert_all_gone(pids: list[int]) -> None:
    for pid in pids:
        assert not alive(pid), f"pid {pid} still running"
        assert group_members(pid) == [], f"processes left in group {pid}"


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_up_reaches_serving_and_stops_cleanly(tmp_path: Path, signum: int) -> None:
    port = free_port()
    path = write_deployment(tmp_path, {"services": {"detector": service_entry(port)},
                                       "stop_grace_s": 5})
    with oricf_up(path) as up:
        up.wait_for(RUNNING, timeout=120)
        assert health.status(f"127.0.0.1:{port}") == "SERVING"
        pids = up.started()["detector"]
        assert len(pids) == 1 and alive(pids[0])
        up.process.send_signal(signum)  # SIGINT: what Ctrl-C delivers
        assert up.finish(timeout=30) == 0
    assert_all_gone(pids)
    assert health.status(f"127.0.0.1:{port}", timeout=0.5) == "UNREACHABLE"
    # every line of the service comes with its name; the stop was a drain, not a kill
    assert "detector | " in up.output and "SERVING" in up.output
    assert "detector stopped (exit code 0)" in up.output


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_up_stops_while_the_models_load(tmp_path: Path, signum: int) -> None:
    port = free_port()
    path = write_deployment(tmp_path, {"services": {"detector": service_entry(port)},
                                       "stop_grace_s": 5})
    with oricf_up(path) as up:
        up.wait_for(r"started detector \(pid", timeout=60)
        pids = up.started()["detector"]
        up.process.send_signal(signum)
        assert up.finish(timeout=30) == 0
        assert_all_gone(pids)  # before oricf_up's clean-up kills whatever is left
    assert not re.search(RUNNING, up.output), up.output
    assert "Traceback" not in up.output, up.output


def test_services_of_a_killed_launcher_stop_by_themselves(tmp_path: Path) -> None:
    """SIGKILL leaves `oricf up` no chance to stop its services: they notice it is gone
    (oricf.lifeline) and stop, so none keeps its port."""
    port = free_port()
    path = write_deployment(tmp_path, {"services": {"detector": service_entry(port)}})
    with oricf_up(path) as up:
        up.wait_for(RUNNING, timeout=120)
        pids = up.started()["detector"]
        up.process.kill()
        up.finish(timeout=10)
        deadline = time.monotonic() + 30
        while any(alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert_all_gone(pids)  # before oricf_up's clean-up kills whatever is left
        assert health.status(f"127.0.0.1:{port}", timeout=0.5) == "UNREACHABLE"


def test_crashed_service_is_restarted_then_given_up(tmp_path: Path) -> None:
    port = free_port()
    entry = service_entry(port, restart={"policy": "on-failure", "max_restarts": 1,
                                         "delay_s": 0.2})
    path = write_deployment(tmp_path, {"services": {"detector": entry}})
    with oricf_up(path) as up:
        up.wait_for(RUNNING, timeout=120)
        first = up.started()["detector"][0]
        os.kill(first, signal.SIGKILL)
        up.wait_for(r"detector ended \(killed by SIGKILL\); restart 1 of 1", timeout=30)
        up.wait_for(r"started detector", timeout=30)
        second = up.started()["detector"][1]
        assert second != first
        deadline = time.monotonic() + 60
        while health.status(f"127.0.0.1:{port}") != "SERVING":
            assert time.monotonic() < deadline, up.output
            time.sleep(0.2)
        os.kill(second, signal.SIGKILL)
        up.wait_for(r"detector ended \(killed by SIGKILL\); not restarted", timeout=30)
        assert up.finish(timeout=30) == 1
    assert_all_gone([first, second])


def test_port_already_answering_is_refused_before_anything_starts(tmp_path: Path) -> None:
    # Another deployment's service on the port would otherwise pass the health check.
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        path = write_deployment(tmp_path, {"services": {"detector": service_entry(port)}})
        with oricf_up(path) as up:
            code = up.finish(timeout=60)
    assert code == 1
    assert f"127.0.0.1:{port} is already in use by another process" in up.output
    assert "started detector" not in up.output


def test_service_that_cannot_start_fails_the_launch(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))  # bound, not listening: only the service's bind fails
        port = taken.getsockname()[1]
        path = write_deployment(tmp_path, {"services": {"detector": service_entry(
            port, restart={"policy": "no"})}})
        with oricf_up(path) as up:
            code = up.finish(timeout=120)
    assert code == 1
    assert "detector ended while starting" in up.output
    assert "cannot listen" in up.output  # the service's own last words are shown
    assert_all_gone(up.started()["detector"])


def test_bad_deployment_is_refused_before_anything_starts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_deployment(tmp_path, {"services": {"detector": {"listen": "127.0.0.1:1",
                                                                 "replicas": 2}}})
    assert oricf_main(["up", str(path)]) == 2
    assert f"{path}: services.detector.replicas: unknown key" in capsys.readouterr().err


def test_invalid_service_config_is_refused_before_anything_starts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    service = tmp_path / "detector.yaml"
    service.write_text("server: {listen: '127.0.0.1:1'}\ndetection: {min_score: 7}\n")
    path = write_deployment(tmp_path, {"services": {"detector": {"config": str(service)}}})
    assert oricf_main(["up", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{service}: detection.min_score" in err
    assert "started detector" not in err


def test_unreachable_remote_service_fails_the_launch_in_time(tmp_path: Path) -> None:
    address = f"127.0.0.1:{free_port()}"  # nothing listens there
    placement = write_overlay(tmp_path, {"llm": {"address": address}})
    path = write_deployment(tmp_path, {"remote": ["llm"],
                                       "gateway": {"config": shipped_pipeline(),
                                                   "overlays": [str(placement)]},
                                       "startup_timeout_s": 2})
    with oricf_up(path) as up:
        assert up.finish(timeout=60) == 1
    assert "not SERVING after" in up.output and "llm (UNREACHABLE)" in up.output
    assert "gateway" not in up.started()  # never started without its services


def secured(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """configs/services/overlays/tls.yaml with certificates of this test (from `oricf
    certs`'s own function), and the client side: the deployment's `tls:`."""
    from oricf.launch.certs import make_certificates

    certs = tmp_path / "certs"
    make_certificates(certs, ["localhost", "127.0.0.1"])
    (certs / "tokens").write_text("t0ken\n")
    shipped = (config_dir() / "services" / "overlays" / "tls.yaml").read_text()
    overlay = tmp_path / "tls.yaml"
    overlay.write_text(shipped.replace("/etc/oricf/certs", str(certs)))
    client = {"ca": str(certs / "ca.pem"), "cert": str(certs / "client.pem"),
              "key": str(certs / "client.key")}
    return overlay, client


def test_up_serves_mtls_and_tokens_like_the_edge_deployment(tmp_path: Path) -> None:
    """configs/deployments/edge.yaml's shape on a free port, with test certificates: the
    launcher reaches SERVING through TLS health checks; plaintext, and a call without the
    token, get nowhere."""
    from oricf.tls import ClientTls, open_channel
    from oricf.v1 import detector_pb2, detector_pb2_grpc

    overlay, client = secured(tmp_path)
    port = free_port()
    entry = {**service_entry(port), "overlays": [str(overlay)]}
    path = write_deployment(tmp_path, {"services": {"detector": entry}, "tls": client,
                                       "stop_grace_s": 5})
    with oricf_up(path) as up:
        up.wait_for(RUNNING, timeout=120)
        address = f"127.0.0.1:{port}"
        tls = ClientTls.model_validate(client)
        assert health.status(address, tls=tls) == "SERVING"
        assert health.status(address) == "UNREACHABLE"  # plaintext gets nowhere
        with open_channel(address, tls) as channel, pytest.raises(grpc.RpcError) as refused:
            detector_pb2_grpc.DetectorStub(channel).Detect(
                detector_pb2.DetectRequest(), timeout=10)
        assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED
        up.process.send_signal(signal.SIGTERM)
        assert up.finish(timeout=30) == 0
    assert "t0ken" not in up.output


def test_up_refuses_to_start_without_the_certificates(tmp_path: Path) -> None:
    overlay, client = secured(tmp_path)
    (tmp_path / "certs" / "server.key").unlink()
    entry = {**service_entry(free_port()), "overlays": [str(overlay)]}
    path = write_deployment(tmp_path, {"services": {"detector": entry}, "tls": client})
    with oricf_up(path) as up:
        assert up.finish(timeout=60) == 1
    assert f"detector: {tmp_path}/certs/server.key: file not found" in up.output
    assert "started detector" not in up.output


def test_up_refuses_tls_services_it_could_not_health_check(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    overlay, client = secured(tmp_path)
    entry = {**service_entry(free_port()), "overlays": [str(overlay)]}
    path = write_deployment(tmp_path, {"services": {"detector": entry},
                                       "tls": {"ca": client["ca"]}})  # no client certificate
    assert oricf_main(["up", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: tls: detector serves TLS" in err
    assert "the health checks need the deployment's tls: ca, cert and key" in err
    assert "started detector" not in err


def test_gateway_uses_the_onboard_fallback_started_here_while_the_edge_is_down(
        tmp_path: Path) -> None:
    """Detector on the edge with an onboard fallback that the same deployment starts on
    another port: the fallback is wired to it, the edge stays the primary."""
    edge = "192.0.2.1:50051"  # TEST-NET-1: never answers
    port = free_port()
    placement = write_overlay(
        tmp_path, {"detector": {"address": edge, "fallback": "127.0.0.1:50051",
                                "deadline_ms": 500}},
        routes={"people": {"input": {"url": str(video_path()), "fps": 5, "loop": True}}})
    path = write_deployment(tmp_path, {
        "services": {"detector": service_entry(port)},
        "gateway": {"config": str(config_dir() / "pipelines" / "people_video.yaml"),
                    "overlays": [str(placement)]},
        "stop_grace_s": 5})
    with oricf_up(path) as up:
        up.wait_for(RUNNING, timeout=120)
        up.wait_for(rf"endpoint detector: primary {edge} failed \(\w+: .*\); using fallback "
                    rf"127.0.0.1:{port} until", timeout=60)
        up.wait_for(r'gateway +\| \{"route": "people".*"count": [1-9]', timeout=60)
        up.process.send_signal(signal.SIGTERM)
        assert up.finish(timeout=60) == 0
