"""The health probe that containers run, against a real detector service."""

from __future__ import annotations

import socket

import pytest

from oricf.launch import health
from tests.support.processes import free_port
from tests.support.services import RunningService, running_service


def test_probe_says_serving_for_a_loaded_service(capsys: pytest.CaptureFixture[str],
                                                 detector: RunningService) -> None:
    assert health.main([detector.address]) == 0
    assert health.main([detector.address, "--service", "oricf.v1.Detector"]) == 0
    assert f"{detector.address}: SERVING" in capsys.readouterr().out


def test_probe_fails_while_the_model_loads(capsys: pytest.CaptureFixture[str]) -> None:
    with running_service("detector", load=False) as service:
        assert health.main([service.address]) == 1
    assert "NOT_SERVING" in capsys.readouterr().out


def test_probe_fails_when_nothing_answers(monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    address = f"127.0.0.1:{free_port()}"
    monkeypatch.setenv("ORICF_HEALTH_ADDRESS", address)  # the container's default address
    assert health.main(["--timeout", "0.5"]) == 1
    assert f"{address}: UNREACHABLE" in capsys.readouterr().out


def test_free_ports_are_outside_the_range_outgoing_connections_take() -> None:
    """A connection's source port comes from the kernel's ephemeral range, so a port from
    there could be taken between free_port() and the service's bind."""
    low, high = health.ephemeral_ports()
    with socket.create_server(("127.0.0.1", 0)) as server, \
            socket.create_connection(server.getsockname()) as client:
        assert low <= client.getsockname()[1] <= high
    ports = [free_port() for _ in range(200)]
    assert all(health.FREE_PORTS_FROM <= port < low for port in ports)
    with socket.create_server(("127.0.0.1", ports[-1])):  # and free to listen on
        pass
