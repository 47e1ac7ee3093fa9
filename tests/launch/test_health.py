"""The health probe that containers run, against a real detector service."""

from __future__ import annotations

import pytest

from oricf.launch import health
from tests.support.processes import free_port
from tests.support.services import running_service


def test_probe_says_serving_for_a_loaded_service(capsys: pytest.CaptureFixture[str]) -> None:
    with running_service("detector") as service:
        assert health.main([service.address]) == 0
        assert health.main([service.address, "--service", "oricf.v1.Detector"]) == 0
    assert f"{service.address}: SERVING" in capsys.readouterr().out


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
