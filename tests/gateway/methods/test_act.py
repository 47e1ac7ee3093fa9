"""The Act method on the real policy service: a state of the simulated Hopper in, the
policy's action out as a chunk placed by its start step; the actions already queued go with
the request; bad records and refused observations are clear errors. Against a policy that
answers with a million actions: refused as the answer arrives, memory kept."""

from __future__ import annotations

from collections.abc import Iterator

import grpc
import numpy as np
import pytest

from oricf.errors import InvalidInput
from oricf.gateway.components import METHODS
from oricf.gateway.control.queue import MAX_CHUNK
from oricf.gateway.endpoints import Endpoint, EndpointConfig
from oricf.gateway.methods.act import ActCall, Actions, actions
from oricf.gateway.products import ProductStore
from oricf.v1 import policy_pb2
from tests.gateway.sources.test_control import control_config
from tests.support.hostile_edge import hostile_edge
from tests.support.peak_memory import peak_growth
from tests.support.pybullet_sim import forward, reference_arrays
from tests.support.services import RunningService

MB = 1 << 20


@pytest.fixture
def act(policy: RunningService) -> Iterator[object]:
    endpoint = Endpoint("policy", EndpointConfig(address=policy.address, deadline_ms=2000),
                        METHODS["Act"])
    try:
        yield METHODS["Act"].open(ActCall(method="Act", service="policy"), endpoint,
                                  ProductStore())
    finally:
        endpoint.close()


def test_a_hopper_state_gets_the_policys_action(act: object, hopper_state: np.ndarray) -> None:
    state = hopper_state
    result = act({"state": state, "step": 41, "capture_time_ns": 5})  # type: ignore[operator]
    assert isinstance(result, Actions)
    assert (result.start_step, result.observation_step) == (41, 41)
    assert result.actions.shape == (1, 3)
    arrays = reference_arrays("HopperBulletEnv_v0")[0]
    expected = np.clip(forward(arrays, state.astype(np.float32)), -1.0, 1.0)
    assert result.actions[0] == pytest.approx(expected, abs=1e-5)


def test_committed_actions_go_with_the_request_and_bad_ones_are_refused(
        act: object, hopper_state: np.ndarray) -> None:
    state = hopper_state
    good = act({"state": state, "step": 3,  # type: ignore[operator]
                "committed": (4, np.zeros((2, 3)))})
    assert good.start_step == 3
    with pytest.raises(grpc.RpcError) as refused:
        act({"state": state, "step": 3,  # type: ignore[operator]
             "committed": (4, np.zeros((1, 2)))})
    assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "not a whole number of actions" in str(refused.value.details())


@pytest.mark.parametrize(("record", "message"), [
    ({}, "needs a state vector"),
    ({"state": np.zeros((2, 2))}, "needs a state vector"),
    ({"state": [1.0, 2.0]}, "needs a state vector"),
])
def test_a_record_without_a_state_vector_is_refused(act: object, record: dict[str, object],
                                                   message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        act(record)  # type: ignore[operator]


def test_a_state_the_policy_cannot_take_is_invalid_argument(
        act: object, hopper_state: np.ndarray) -> None:
    state = hopper_state
    state[2] = np.nan
    with pytest.raises(grpc.RpcError) as refused:
        act({"state": state, "step": 1})  # type: ignore[operator]
    assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    with pytest.raises(grpc.RpcError) as short:
        act({"state": state[:5], "step": 1})  # type: ignore[operator]
    assert short.value.code() == grpc.StatusCode.INVALID_ARGUMENT


def test_an_answer_of_more_actions_than_a_chunk_is_refused_before_it_is_converted() -> None:
    reply = policy_pb2.ActionChunk(action_dim=3, actions=[0.0] * 3 * (MAX_CHUNK + 1))
    with pytest.raises(InvalidInput, match=f"a chunk of {MAX_CHUNK + 1} actions"):
        actions(reply)


def test_an_answer_larger_than_a_chunk_is_refused_as_it_arrives() -> None:
    """A policy that answers 1,000,000 actions of 3 (12 MB, within gRPC's 64 MB): the
    channel of an endpoint a control input calls takes a chunk of its action_dim at most, so
    the call ends RESOURCE_EXHAUSTED before the answer is read, once (not retried as if the
    server were busy), and the process's memory does not swell with it."""
    huge = policy_pb2.ActionChunk(start_step=1, observation_step=1, action_dim=3,
                                  actions=np.zeros(3_000_000).tolist())
    with hostile_edge(lambda index, request: huge) as (address, edge):
        config = control_config(address)
        endpoint = Endpoint("hopper", config.endpoints["hopper"], METHODS["Act"],
                            reply_bytes=config.reply_bytes_of("hopper"))
        try:
            act = METHODS["Act"].open(config.routes["hopper"].call, endpoint, ProductStore())
            with peak_growth() as grown, pytest.raises(grpc.RpcError) as refused:
                act({"state": np.zeros(15), "step": 1})
            assert refused.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
            assert "larger than max" in str(refused.value.details())
            assert grown() < 64 * MB, f"the peak rose {grown() / MB:.0f} MB"
            assert (edge.calls, endpoint.retries) == (1, 0)
        finally:
            endpoint.close()
