"""`oricf serve policy`: pybullet's trained Hopper policy served as oricf.v1.Policy over a
real channel, asked with observations of the real simulated Hopper; the same declaration over
the Open Inference Protocol; every bad observation refused clearly, the service unharmed."""

from __future__ import annotations

import math
import re
import threading
from collections.abc import Iterator

import grpc
import numpy as np
import pytest
import yaml
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.config import REPO_ROOT
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.v1 import common_pb2, policy_pb2, policy_pb2_grpc
from tests.support.pybullet_sim import forward, hopper, reference_arrays
from tests.support.services import RunningService, running_service

HOPPER = REPO_ROOT / "configs" / "models" / "policies" / "hopper.yaml"
STEPS = 12  # a short closed loop: enough to leave the rest pose


@pytest.fixture
def stub(policy: RunningService) -> policy_pb2_grpc.PolicyStub:
    return policy_pb2_grpc.PolicyStub(policy.channel)


@pytest.fixture(scope="module")
def arrays() -> dict[str, np.ndarray]:
    return reference_arrays("HopperBulletEnv_v0")[0]


def expected(arrays: dict[str, np.ndarray], observation: np.ndarray) -> np.ndarray:
    return np.clip(forward(arrays, observation), -1.0, 1.0)  # the declared bounds


def observe(step: int, state: np.ndarray, **fields: object) -> policy_pb2.Observation:
    return policy_pb2.Observation(step=step, capture_time_ns=1_000 + step, state=state.tolist(),
                                  **fields)


def test_act_answers_a_real_hopper_observation_with_the_policys_action(
        stub: policy_pb2_grpc.PolicyStub, arrays: dict[str, np.ndarray]) -> None:
    env = hopper(seed=0)
    env.reset()
    state, *_ = env.step(np.zeros(3))
    chunk = stub.Act(observe(7, np.asarray(state, np.float32)), timeout=10)
    assert (chunk.start_step, chunk.observation_step, chunk.capture_time_ns) == (7, 7, 1_007)
    assert (chunk.action_dim, chunk.model) == (3, "pybullet-hopper")
    np.testing.assert_allclose(chunk.actions, expected(arrays, np.asarray(state, np.float32)),
                               atol=1e-5)
    assert chunk.timings.total_ms >= chunk.timings.inference_ms > 0


def test_act_stream_drives_the_simulated_hopper(stub: policy_pb2_grpc.PolicyStub,
                                                arrays: dict[str, np.ndarray]) -> None:
    env = hopper(seed=1)
    state = np.asarray(env.reset(), np.float32)
    sent: list[np.ndarray] = []

    def observations() -> Iterator[policy_pb2.Observation]:
        for step in range(STEPS):
            sent.append(state)
            yield observe(step, state)
            answered.wait(timeout=30)  # a closed loop: each observation follows an action
            answered.clear()

    answered = threading.Event()
    total = 0.0
    for step, chunk in enumerate(stub.ActStream(observations(), timeout=30)):
        assert chunk.observation_step == step and not chunk.HasField("error")
        action = np.asarray(chunk.actions, np.float32)
        np.testing.assert_allclose(action, expected(arrays, sent[step]), atol=1e-5)
        observation, reward, done, _ = env.step(action)
        state = np.asarray(observation, np.float32)
        total += reward
        answered.set()
    assert len(sent) == STEPS and not done
    assert total > 0  # alive bonus and forward progress: the policy hops


def test_model_info_reports_the_policys_declaration(stub: policy_pb2_grpc.PolicyStub) -> None:
    info = stub.GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=10)
    assert (info.service, info.model) == ("policy", "pybullet-hopper")
    assert info.sha256 == "d8f4b122df13d96a3fc8315dbc0de529c20e46a1bcfb98f3d956e15758dd9986"
    assert dict(info.parameters) == {"threads": "1", "task": "policy", "state_size": "15",
                                     "action_dim": "3", "chunk": "1", "rate_hz": "60.606",
                                     "lead_steps": "0"}


@pytest.fixture(scope="module")
def ahead(tmp_path_factory: pytest.TempPathFactory) -> Iterator[policy_pb2_grpc.PolicyStub]:
    """The Hopper declared to act 8 steps ahead."""
    declaration = yaml.safe_load(HOPPER.read_text())
    declaration["task"]["lead_steps"] = 8
    path = tmp_path_factory.mktemp("ahead") / "hopper-ahead.yaml"
    path.write_text(yaml.safe_dump(declaration))
    with running_service("policy", {"model": str(path)}) as service:
        yield policy_pb2_grpc.PolicyStub(service.channel)


def test_a_policy_declared_to_act_ahead_answers_chunks_starting_that_many_steps_later(
        ahead: policy_pb2_grpc.PolicyStub, arrays: dict[str, np.ndarray]) -> None:
    chunk = ahead.Act(observe(7, GOOD), timeout=10)
    streamed = list(ahead.ActStream(iter([observe(3, GOOD), observe(4, GOOD)]), timeout=10))
    info = ahead.GetModelInfo(common_pb2.GetModelInfoRequest(), timeout=10)
    assert (chunk.start_step, chunk.observation_step, chunk.capture_time_ns) == (15, 7, 1_007)
    assert [(c.start_step, c.observation_step) for c in streamed] == [(11, 3), (12, 4)]
    np.testing.assert_allclose(chunk.actions, expected(arrays, GOOD), atol=1e-5)
    assert info.parameters["lead_steps"] == "8"


def test_a_step_whose_first_action_would_be_past_the_last_step_is_invalid_argument(
        ahead: policy_pb2_grpc.PolicyStub) -> None:
    last = 2**64 - 1  # the largest uint64

    def at(step: int) -> policy_pb2.Observation:
        return policy_pb2.Observation(step=step, state=GOOD.tolist())

    with pytest.raises(grpc.RpcError) as err:
        ahead.Act(at(last - 3), timeout=10)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert err.value.details() == (f"step: {last - 3} + the policy's lead_steps 8 is past "
                                   f"the last step there is ({last})")
    chunks = list(ahead.ActStream(iter([at(last), at(last - 8)]), timeout=10))
    assert [c.HasField("error") for c in chunks] == [True, False]
    assert chunks[1].start_step == last


GOOD = np.linspace(-0.5, 0.5, 15).astype(np.float32)
BAD = {
    "nan": (observe(1, np.where(np.arange(15) == 4, math.nan, GOOD)), r"state\[4\] is nan"),
    "infinity": (observe(1, np.where(np.arange(15) == 0, math.inf, GOOD)),
                 r"state\[0\] is inf: every value must be finite"),
    "short": (observe(1, GOOD[:14]), "state: 14 values, policy pybullet-hopper takes 15"),
    "empty": (policy_pb2.Observation(step=1), "state: 0 values"),
    "long": (observe(1, np.zeros(100_000, np.float32)), "state: 100000 values"),
    "image": (observe(1, GOOD, images={"wrist": common_pb2.Image(data=b"x")}),
              "images: policy pybullet-hopper has no camera 'wrist' \\(its cameras: none\\)"),
    "partial action": (observe(1, GOOD, committed=policy_pb2.CommittedActions(
        start_step=2, actions=[0.1] * 4)), "committed.actions: 4 values is not a whole"),
    "nan committed": (observe(1, GOOD, committed=policy_pb2.CommittedActions(
        actions=[0.1, math.nan, 0.2])), r"committed.actions\[1\] is nan"),
    # Finite as float32; the network's products are not.
    "overflowing": (observe(1, np.full(15, 3.4e38, np.float32)), "NaN or infinity"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_observations_are_invalid_argument(stub: policy_pb2_grpc.PolicyStub,
                                               policy: RunningService, case: str) -> None:
    request, message = BAD[case]
    with pytest.raises(grpc.RpcError) as err:
        stub.Act(request, timeout=10)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert re.search(message, err.value.details())
    health = health_pb2_grpc.HealthStub(policy.channel).Check(health_pb2.HealthCheckRequest(),
                                                              timeout=10)
    assert health.status == health_pb2.HealthCheckResponse.SERVING


def test_a_bad_observation_in_a_stream_is_answered_with_an_error_and_the_stream_goes_on(
        stub: policy_pb2_grpc.PolicyStub, arrays: dict[str, np.ndarray]) -> None:
    requests = [observe(0, GOOD), BAD["nan"][0], observe(2, GOOD[:3]), observe(3, GOOD)]
    chunks = list(stub.ActStream(iter(requests), timeout=10))
    assert [c.observation_step for c in chunks] == [0, 1, 2, 3]
    assert [c.HasField("error") for c in chunks] == [False, True, True, False]
    assert chunks[1].error.code == grpc.StatusCode.INVALID_ARGUMENT.value[0]
    assert "state[4] is nan" in chunks[1].error.message and not chunks[1].actions
    np.testing.assert_allclose(chunks[3].actions, expected(arrays, GOOD), atol=1e-5)


def test_quiet_streams_leave_the_service_to_other_callers() -> None:
    """As many streams as the service takes calls, each quiet after one observation: a call
    from another client is still answered, and one stream more is refused at once. A service
    of its own: it holds every slot."""
    with running_service("policy") as policy:
        streams_fill_the_service(policy, policy_pb2_grpc.PolicyStub(policy.channel))


def streams_fill_the_service(policy: RunningService, stub: policy_pb2_grpc.PolicyStub) -> None:
    limit = policy.host.config.server.max_concurrent_rpcs
    released = threading.Event()

    def one_then_quiet(step: int) -> Iterator[policy_pb2.Observation]:
        yield observe(step, GOOD)
        released.wait(timeout=30)

    with grpc.insecure_channel(policy.address) as quiet:
        robots = policy_pb2_grpc.PolicyStub(quiet)
        streams = [robots.ActStream(one_then_quiet(i), timeout=60) for i in range(limit)]
        try:
            assert sorted(next(s).observation_step for s in streams) == list(range(limit))
            assert stub.Act(observe(99, GOOD), timeout=10).observation_step == 99
            with pytest.raises(grpc.RpcError) as err:
                list(robots.ActStream(iter([observe(100, GOOD)]), timeout=10))
        finally:
            released.set()
        assert [len(list(s)) for s in streams] == [0] * limit  # then each ends cleanly
    assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert f"({limit} streams open)" in err.value.details()


@pytest.fixture
def oip(policy_models: RunningService) -> oip_grpc.GRPCInferenceServiceStub:
    """The Hopper declaration in `oricf serve models`."""
    return oip_grpc.GRPCInferenceServiceStub(policy_models.channel)


def test_the_same_declaration_is_served_over_the_open_inference_protocol(
        oip: oip_grpc.GRPCInferenceServiceStub, arrays: dict[str, np.ndarray]) -> None:
    request = infer_request("pybullet-hopper", {"observation": GOOD.reshape(1, 15)})
    outputs = response_outputs(oip.ModelInfer(request, timeout=10))
    # Raw tensors: the model's own output, before the policy service's bounds.
    np.testing.assert_allclose(outputs["action"][0], forward(arrays, GOOD), atol=1e-5)


@pytest.mark.parametrize(("value", "message"), [
    (math.nan, r"input 'observation'\[4\] is nan: every value must be finite"),
    (math.inf, r"input 'observation'\[4\] is inf"),
    (-math.inf, r"input 'observation'\[4\] is -inf"),
    (3.4e38, r"policy pybullet-hopper answered NaN or infinity \(output 'action'\)"),
])
def test_the_open_inference_protocol_refuses_what_the_policy_service_refuses(
        oip: oip_grpc.GRPCInferenceServiceStub, value: float, message: str) -> None:
    state = np.where(np.arange(15) == 4, np.float32(value), GOOD).astype(np.float32)
    with pytest.raises(grpc.RpcError) as err:
        oip.ModelInfer(infer_request("pybullet-hopper", {"observation": state.reshape(1, 15)}),
                       timeout=10)
    assert err.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert re.search(message, err.value.details()), err.value.details()
