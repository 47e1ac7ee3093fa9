"""When a process traces, over which protocol, the one line it says when it cannot, and a
stop that a broken traces' backend never holds up."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import grpc
import pytest

from oricf import tracing
from oricf.errors import ConfigError
from oricf.services.runtime.config import ServerSettings
from oricf.tracing import TracingConfig, protocol, setup_tracing, wanted
from oricf.v1.common_pb2 import GetModelInfoRequest
from oricf.v1.policy_pb2_grpc import PolicyStub
from tests.gateway.test_pipeline import pipeline_config
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.waiting import wait_for

SDK_MODULES = ("opentelemetry.sdk", "opentelemetry.sdk.resources", "opentelemetry.sdk.trace",
               "opentelemetry.sdk.trace.export")


def test_off_by_default_on_by_the_standard_variables_or_the_yaml_key() -> None:
    assert not wanted(None, {})
    assert not wanted(TracingConfig(), {})
    assert wanted(None, {"OTEL_EXPORTER_OTLP_ENDPOINT": "http://127.0.0.1:4318"})
    assert wanted(None, {"OTEL_EXPORTER_OTLP_TRACES_ENDPOINT": "http://127.0.0.1:4318/v1/traces"})
    assert wanted(TracingConfig(enabled=True), {})
    # The SDK's own switch wins over both.
    assert not wanted(TracingConfig(enabled=True), {"OTEL_SDK_DISABLED": "true",
                                                    "OTEL_EXPORTER_OTLP_ENDPOINT": "http://x"})


def test_the_protocol_is_the_standard_variables_choice() -> None:
    assert protocol({}) == "http/protobuf"
    assert protocol({"OTEL_EXPORTER_OTLP_PROTOCOL": "grpc"}) == "grpc"
    assert protocol({"OTEL_EXPORTER_OTLP_PROTOCOL": "grpc",
                     "OTEL_EXPORTER_OTLP_TRACES_PROTOCOL": "http/protobuf"}) == "http/protobuf"
    with pytest.raises(ConfigError, match=r"http/json.*'grpc' or 'http/protobuf'"):
        protocol({"OTEL_EXPORTER_OTLP_PROTOCOL": "http/json"})


def test_the_yaml_key_of_a_service_and_its_unknown_keys() -> None:
    assert ServerSettings.model_validate({"tracing": {"enabled": True}}).tracing == \
        TracingConfig(enabled=True)
    with pytest.raises(ValueError, match="endpoint"):
        ServerSettings.model_validate({"tracing": {"endpoint": "x"}})


def test_asked_for_without_the_sdk_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OTEL_EXPORTER_OTLP_ENDPOINT", "http://127.0.0.1:4318")
    monkeypatch.delenv("OTEL_SDK_DISABLED", raising=False)
    for name in SDK_MODULES:  # as in an environment without the `tracing` extra
        monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(ConfigError) as caught:
        setup_tracing("oricf-test")
    message = str(caught.value)
    assert "\n" not in message and "pip install 'oricf[tracing]'" in message
    assert not tracing.active()


def test_not_asked_for_does_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in tracing.ENDPOINT_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert not setup_tracing("oricf-test")
    assert not tracing.active()


def test_the_yaml_key_alone_turns_traces_on() -> None:
    """In a process of its own (traces are on for a process' life): no OTEL_ variable, the
    key; the gRPC exporter as the protocol variable says."""
    env = {key: value for key, value in os.environ.items() if not key.startswith("OTEL_")}
    env["OTEL_EXPORTER_OTLP_PROTOCOL"] = "grpc"
    script = ("import sys; from oricf.tracing import TracingConfig, active, setup_tracing; "
              "on = setup_tracing('oricf-test', TracingConfig(enabled=True)); "
              "print(on, active(), *(f'opentelemetry.exporter.otlp.proto.{p}.trace_exporter' "
              "in sys.modules for p in ('grpc', 'http')))")
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, timeout=60, check=True)
    assert done.stdout.split() == ["True", "True", "True", "False"]  # gRPC's exporter only


def test_the_yaml_key_of_a_pipeline() -> None:
    config = pipeline_config("127.0.0.1:1", {"tracing": {"enabled": True}})
    assert config.tracing == TracingConfig(enabled=True)
    assert pipeline_config("127.0.0.1:1").tracing is None


# A stop with a traces' backend that is broken: bounded, whatever the exporter does. Its
# requests are given 30 s (OTEL_EXPORTER_OTLP_TIMEOUT, as for a slow backend far away),
# which the SDK alone would wait out at exit. A bound on a hang, not a timing.
STOP_BOUND_S = 10.0
EXPORT_TIMEOUT_S = "30"
ASK = """
endpoints:
  llm: {address: "127.0.0.1:1", deadline_ms: 1000}
channels:
  questions: {listen: "127.0.0.1:PORT"}
routes:
  ask:
    input: {text: questions}
    call: {service: llm, method: Generate, prompt: "{text}", max_tokens: 4}
    outputs:
      - {text: questions, from: answer}
"""


class SilentEndpoint:
    """A TCP listener that accepts connections and never answers on them."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.accepted: list[socket.socket] = []
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def _accept(self) -> None:
        with contextlib.suppress(OSError):  # closed
            while True:
                self.accepted.append(self.sock.accept()[0])

    def close(self) -> None:
        self.sock.close()
        for peer in self.accepted:
            peer.close()


@contextlib.contextmanager
def broken_backend(kind: str) -> Iterator[tuple[int, SilentEndpoint | None]]:
    """(port, the listener if it accepts): one that accepts and never answers, or a closed
    port that refuses."""
    if kind == "refusing":
        yield free_port(), None
        return
    silent = SilentEndpoint()
    try:
        yield silent.port, silent
    finally:
        silent.close()


def traced_env(port: int, protocol: str) -> dict[str, str]:
    env = {key: value for key, value in os.environ.items() if not key.startswith("OTEL_")}
    return {**env, "OTEL_EXPORTER_OTLP_ENDPOINT": f"http://127.0.0.1:{port}",
            "OTEL_EXPORTER_OTLP_PROTOCOL": protocol, "OTEL_EXPORTER_OTLP_TIMEOUT": EXPORT_TIMEOUT_S}


def stopped_within_bound(process: subprocess.Popen[str]) -> str:
    """SIGTERM, then the exit (code 0) within STOP_BOUND_S; the process's output."""
    process.send_signal(signal.SIGTERM)
    started = time.monotonic()
    code = process.wait(timeout=60)
    took = time.monotonic() - started
    assert process.stdout is not None
    log = process.stdout.read()
    assert code == 0, log
    assert took < STOP_BOUND_S, f"{took:.1f} s from SIGTERM to exit\n{log}"
    return log


def ask(port: int, process: subprocess.Popen[str]) -> str:
    """A question on the gateway's text channel, once it listens: its answer line."""
    def listening() -> bool:
        assert process.poll() is None, "the gateway exited"
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1):
            return True
        return False

    wait_for(listening, 60, "the gateway's text channel")
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        sock.sendall(b"How many people do you see?\n")
        return sock.makefile("r", encoding="utf-8").readline()


@pytest.mark.parametrize("kind", ["silent", "refusing"])
def test_a_gateway_stops_promptly_whatever_its_traces_backend_does(
        kind: str, tmp_path: Path) -> None:
    """A route's span waits for export (its call failed: no language model) when the
    gateway, exporting over OTLP/HTTP, gets SIGTERM."""
    channel = free_port()
    pipeline = tmp_path / "ask.yaml"
    pipeline.write_text(ASK.replace("PORT", str(channel)))
    with broken_backend(kind) as (port, silent), oricf_process(
            "gateway", "--config", str(pipeline),
            env=traced_env(port, "http/protobuf")) as gateway:
        assert ask(channel, gateway).startswith("error:")
        log = stopped_within_bound(gateway)
    assert f"traces of oricf-gateway go over OTLP (http/protobuf) to http://127.0.0.1:{port}" \
        in log, log
    assert silent is None or silent.accepted, "the exporter never tried the endpoint"


@pytest.mark.parametrize("kind", ["silent", "refusing"])
def test_a_service_stops_promptly_whatever_its_traces_backend_does(kind: str) -> None:
    """A call's span waits for export when the policy service, exporting over OTLP/gRPC,
    gets SIGTERM."""
    address = f"127.0.0.1:{free_port()}"
    with broken_backend(kind) as (port, silent), oricf_process(
            "serve", "policy", "--listen", address, env=traced_env(port, "grpc")) as service:
        wait_serving(address, timeout=120, process=service)
        with grpc.insecure_channel(address) as channel:
            PolicyStub(channel).GetModelInfo(GetModelInfoRequest(), timeout=30)
        log = stopped_within_bound(service)
    assert f"traces of oricf-policy go over OTLP (grpc) to http://127.0.0.1:{port}" in log, log
    assert silent is None or silent.accepted, "the exporter never tried the endpoint"
