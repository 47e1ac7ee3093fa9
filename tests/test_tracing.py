"""When a process traces, over which protocol, and the one line it says when it cannot."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from oricf import tracing
from oricf.errors import ConfigError
from oricf.services.runtime.config import ServerSettings
from oricf.tracing import TracingConfig, protocol, setup_tracing, wanted
from tests.gateway.test_pipeline import pipeline_config

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
