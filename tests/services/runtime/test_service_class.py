"""A model service is one class plus its YAML: a service written here alone (a numpy model
answering oricf.v1.Policy's Act, its schema, its YAML) is served by the shared runtime over
real gRPC with what the shipped services have: health around its load, reflection for
grpcurl, GetModelInfo, the call limit with pushback, and domain errors as status codes."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from concurrent import futures
from contextlib import contextmanager
from pathlib import Path

import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from pydantic import Field

from oricf.config import load_config
from oricf.errors import ConfigError, InvalidInput
from oricf.models.info import ModelInfo
from oricf.services.local import local_service
from oricf.services.runtime import Call, Service, ServiceConfig, ServiceHost
from oricf.services.runtime.limits import PUSHBACK_KEY
from oricf.store import ModelStore
from oricf.v1 import common_pb2, policy_pb2, policy_pb2_grpc
from tests.support.grpcurl import grpcurl
from tests.support.waiting import wait_for

YAML = """\
server:
  listen: 127.0.0.1:0
  max_concurrent_rpcs: 1
gain: 2.5
"""
HOLD = 99.0  # a state of this value holds its call until the test releases it


class GainConfig(ServiceConfig):
    gain: float = Field(gt=0, description="each action is the state times this")


class Gain(Service[GainConfig]):
    """A policy whose action is its state scaled: the model is a numpy diagonal."""

    name = "gain"
    proto = policy_pb2.DESCRIPTOR.services_by_name["Policy"]
    config_schema = GainConfig

    def __init__(self, config: GainConfig, store: ModelStore) -> None:
        super().__init__(config, store)
        self.release = threading.Event()
        self.held = threading.Event()

    def load(self) -> None:
        self.scale = np.float32(self.config.gain)

    def info(self) -> ModelInfo:
        return ModelInfo(model="gain", runtime="numpy",
                         parameters={"gain": f"{self.config.gain:g}"})

    def act(self, request: policy_pb2.Observation, call: Call) -> policy_pb2.ActionChunk:
        state = np.asarray(request.state, np.float32)
        if state.size == 0:
            raise InvalidInput("state: empty")
        if state[0] == HOLD:
            self.held.set()
            self.release.wait(30)
        actions = state * self.scale
        return policy_pb2.ActionChunk(observation_step=request.step, action_dim=state.size,
                                      actions=actions.tolist(), model="gain")


@pytest.fixture
def config(tmp_path: Path) -> GainConfig:
    path = tmp_path / "gain.yaml"
    path.write_text(YAML)
    return load_config(path, Gain.config_schema)


@contextmanager
def served(config: GainConfig, load: bool = True) -> Iterator[tuple[ServiceHost, grpc.Channel]]:
    """The service by the shared runtime on a free port, and a channel to it."""
    with local_service(Gain, config, load=load) as host, \
            grpc.insecure_channel(f"127.0.0.1:{host.port}") as channel:
        yield host, channel


def health(channel: grpc.Channel, name: str = "") -> int:
    request = health_pb2.HealthCheckRequest(service=name)
    return int(health_pb2_grpc.HealthStub(channel).Check(request, timeout=5).status)


def test_its_yaml_is_its_schema_with_unknown_keys_refused(tmp_path: Path) -> None:
    path = tmp_path / "gain.yaml"
    path.write_text(YAML + "gian: 3\n")
    with pytest.raises(ConfigError, match=r"gain\.yaml.*gian"):
        load_config(path, Gain.config_schema)


def test_health_and_answers_follow_the_load(config: GainConfig) -> None:
    with served(config, load=False) as (host, channel):
        stub = policy_pb2_grpc.PolicyStub(channel)
        assert health(channel, "oricf.v1.Policy") == health_pb2.HealthCheckResponse.NOT_SERVING
        with pytest.raises(grpc.RpcError) as refused:
            stub.Act(policy_pb2.Observation(state=[1.0]), timeout=5)
        assert refused.value.code() == grpc.StatusCode.UNAVAILABLE
        # GetModelInfo answers before the load, from info(), as the shipped services'.
        info = stub.GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=5)
        assert (info.service, info.model, info.parameters["gain"]) == ("gain", "gain", "2.5")

        host.load_model()
        assert health(channel) == health(channel, "oricf.v1.Policy") \
            == health_pb2.HealthCheckResponse.SERVING
        chunk = stub.Act(policy_pb2.Observation(state=[1.0, -2.0], step=7), timeout=5)
        assert (list(chunk.actions), chunk.observation_step) == ([2.5, -5.0], 7)


def test_errors_are_status_codes_and_missing_rpcs_unimplemented(config: GainConfig) -> None:
    with served(config) as (_, channel):
        stub = policy_pb2_grpc.PolicyStub(channel)
        with pytest.raises(grpc.RpcError) as bad:
            stub.Act(policy_pb2.Observation(), timeout=5)
        assert (bad.value.code(), bad.value.details()) == (
            grpc.StatusCode.INVALID_ARGUMENT, "state: empty")
        not_a_message = channel.unary_unary("/oricf.v1.Policy/Act")
        with pytest.raises(grpc.RpcError) as garbage:
            not_a_message(b"\xff\xff\xff", timeout=5)
        assert garbage.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        with pytest.raises(grpc.RpcError) as missing:
            list(stub.ActStream(iter([policy_pb2.Observation(state=[1.0])]), timeout=5))
        assert missing.value.code() == grpc.StatusCode.UNIMPLEMENTED


def test_the_call_limit_refuses_with_pushback_while_health_answers(config: GainConfig) -> None:
    with served(config) as (host, channel), futures.ThreadPoolExecutor(1) as pool:
        service = host.slot.peek()
        assert isinstance(service, Gain)
        stub = policy_pb2_grpc.PolicyStub(channel)
        held = pool.submit(stub.Act, policy_pb2.Observation(state=[HOLD]), timeout=30)
        try:
            wait_for(service.held.is_set)
            with pytest.raises(grpc.RpcError) as busy:
                stub.Act(policy_pb2.Observation(state=[1.0]), timeout=5)
            assert busy.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
            trailers = dict(busy.value.trailing_metadata() or ())
            assert int(trailers[PUSHBACK_KEY]) >= config.server.retry_after_ms
            assert health(channel) == health_pb2.HealthCheckResponse.SERVING
        finally:
            service.release.set()
        assert list(held.result().actions) == [HOLD * 2.5]


def test_grpcurl_finds_it_by_reflection_and_calls_it(config: GainConfig) -> None:
    with served(config) as (host, _):
        address = f"127.0.0.1:{host.port}"
        assert "oricf.v1.Policy" in grpcurl(address, "list").split()
        answer = json.loads(grpcurl(address, "oricf.v1.Policy/Act",
                                    data=json.dumps({"state": [2.0], "step": "3"})))
        assert (answer["actions"], answer["observation_step"]) == ([5.0], "3")
