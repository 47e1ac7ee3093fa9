"""Property-based fuzzing of a control loop's parts with what a hostile or broken robot and
edge can send: state messages of any length with NaN, infinity and huge values; camera
messages whose sizes, steps and encodings lie; chunks of
any shape and values, for any step, late, early, repeated, answering steps asked or never
asked (far ahead: 10**6, 2**40), refused by their caller; and the loop's own ticks in any
order. Whatever arrives, every action that goes out is finite, the right length and within
the target's bounds, none is played further after its observation than the horizon, every
state the policy is sent is finite as sent (float32: 1e300 is finite as float64 only), the
queue stays bounded, only the typed refusals are raised, and afterwards the loop asks again
and plays an honest answer."""

from __future__ import annotations

import contextlib
from types import SimpleNamespace
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.control.observation import CameraPart, MissingState, Observation, StatePart
from oricf.gateway.control.parts import camera_frame
from oricf.gateway.control.queue import MAX_AHEAD, MAX_CHUNK, ActionQueue, BadChunk, Origin
from oricf.gateway.control.target import ActionTarget, ActionTargetConfig
from oricf.gateway.methods.act import observation as observation_sent
from oricf.gateway.values import Frame

DIM = 3
BOUNDS = [(-1.0, 1.0)] * DIM
SAFE = np.zeros(DIM)
HORIZON = 12
DEADLINE = 5
hostile = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([1e308, -1e308, 0.0, float("nan"), float("inf")]))
# Finite as float64, infinite as the float32 a policy is sent (float32's largest: 3.4e38).
beyond_float32 = st.sampled_from([1e300, -1e300, 3.5e38, -1e39])


def state_message() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.builds(lambda data: SimpleNamespace(data=data), st.lists(hostile, max_size=40)),
        st.builds(lambda data: SimpleNamespace(data=data),
                  st.lists(st.floats(-10, 10), min_size=DIM * 2, max_size=DIM * 2)),
        # the right length, so that its values, not its length, are what is refused
        st.builds(lambda data: SimpleNamespace(data=data),
                  st.lists(st.one_of(st.floats(-10, 10), beyond_float32),
                           min_size=DIM * 2, max_size=DIM * 2)),
        st.just(SimpleNamespace(data="not numbers")),
        st.just(SimpleNamespace()))


def camera_message() -> st.SearchStrategy[Any]:
    """sensor_msgs/Image (or CompressedImage) fields as rclpy gives them, often lying."""
    sizes = st.one_of(st.integers(0, 8), st.sampled_from([2**31 - 1, 70_000]))
    raw = st.builds(lambda w, h, step, encoding, data: (
        "sensor_msgs/Image", SimpleNamespace(width=w, height=h, step=step, encoding=encoding,
                                             data=data)),
        sizes, sizes, st.integers(0, 40), st.sampled_from(["bgr8", "rgb8", "mono8", "yuv", ""]),
        st.binary(max_size=200))
    compressed = st.builds(lambda fmt, data: (
        "sensor_msgs/CompressedImage", SimpleNamespace(format=fmt, data=data)),
        st.sampled_from(["jpeg", "png", "bgr8; jpeg compressed bgr8", "tiff", ""]),
        st.binary(max_size=200))
    return st.one_of(raw, compressed, st.just(("sensor_msgs/Image", SimpleNamespace())))


def chunk() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.builds(np.array, st.lists(st.lists(hostile, min_size=DIM, max_size=DIM),
                                     max_size=20)),
        st.integers(0, 5).flatmap(lambda width: st.builds(np.array, st.lists(
            st.lists(hostile, min_size=width, max_size=width), max_size=5))),
        st.builds(lambda n: np.zeros((n, DIM)), st.sampled_from([0, 1, MAX_CHUNK + 1])),
        st.builds(np.array, st.lists(st.floats(-5, 5), max_size=7)))


event = st.one_of(
    st.tuples(st.just("state"), state_message()),
    st.tuples(st.just("image"), camera_message()),
    st.tuples(st.just("tick"), st.integers(0, 3)),
    # the observation answered: any step, one never asked far ahead, or the last asked (None)
    st.tuples(st.just("answer"), chunk(),
              st.one_of(st.integers(-5, 50), st.integers(-MAX_AHEAD * 2, MAX_AHEAD * 2)),
              st.one_of(st.integers(-5, 50), st.sampled_from([10**6, 2**40]), st.none())),
    st.tuples(st.just("fail"), st.integers(-5, 50)),
    st.tuples(st.just("refuse"), st.integers(-5, 50)),
)


@settings(max_examples=400, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(event, max_size=40), st.sampled_from(["skip", "shift"]),
       st.sampled_from(["latest", "weighted", "ensemble"]))
def test_whatever_arrives_only_finite_bounded_actions_go_out(
        events: list[Any], late: str, merge: str) -> None:
    sent: list[dict[str, Any]] = []
    target = ActionTarget(ActionTargetConfig(topic="/a", bounds=BOUNDS), sent.append, SAFE)
    queue = ActionQueue(DIM, late, merge, horizon=HORIZON)  # type: ignore[arg-type]
    loop = ControlLoop(queue, SAFE, request_at=2, deadline=DEADLINE, hold_steps=1,
                       send_committed=True, max_in_flight=2)
    observation = Observation([StatePart(topic="/s", type="std_msgs/Float64MultiArray",
                                         size=DIM * 2)], DIM * 2, max_age_ms=1e6,
                              cameras=[CameraPart(name="top", topic="/c")],
                              # either type of message on the one camera, as it names it
                              image_of=lambda _, typed: camera_frame(*typed))
    step = 0
    asked = 0
    for kind, *args in events:
        if kind == "state":
            with contextlib.suppress(MissingState):
                observation.take(0, args[0], received_ns=1)
        elif kind == "image":
            with contextlib.suppress(MissingState):  # as the control input takes it
                observation.take_image(0, args[0], received_ns=1)
        elif kind == "tick":
            for _ in range(args[0] + 1):
                try:
                    observed = observation.assemble(2)
                except MissingState:
                    pass
                else:
                    request = loop.ask(step, observed.state, observed.received_ns,
                                       observed.images)
                    if request is not None:  # what the policy would be sent
                        wire = observation_sent({"state": request.state, "step": step})
                        assert np.isfinite(np.asarray(wire.state)).all()
                    for image in (request.images or {}).values() if request else ():
                        assert isinstance(image, Frame) and image.data
                    if request is not None:
                        asked = request.step
                target._last_sent = -np.inf  # every tick's action is looked at, not rated
                tick = loop.act(step)
                assert tick.origin is None or tick.step - tick.origin.step <= HORIZON
                target.send(tick.action)
                step += 1
        elif kind == "answer":
            with contextlib.suppress(BadChunk):
                loop.deliver(args[0], args[1], Origin(asked if args[2] is None else args[2]),
                             now=step - 1)
        elif kind == "fail":
            loop.failed(args[0])
        else:
            loop.refuse(args[0])
        assert loop.queue.remaining(step) <= HORIZON
    assert loop.queue.counts.ticks == step
    answered_after(loop, step)
    for message in sent:
        values = np.asarray(message["data"])
        assert values.shape == (DIM,) and np.isfinite(values).all()
        assert (np.abs(values) <= 1.0).all()
    target.close()


def answered_after(loop: ControlLoop, step: int) -> None:
    """Once what was queued and asked has run out (the horizon and the deadline passed), the
    loop asks, and plays the answer to what it asked: nothing that came before silences it."""
    for _ in range(HORIZON + DEADLINE + 2):
        loop.act(step)
        step += 1
    request = loop.ask(step, np.zeros(DIM * 2))
    assert request is not None
    honest = np.full((4, DIM), 0.5)
    assert loop.deliver(honest, request.step, Origin(request.step), now=step - 1) == 4
    assert loop.act(step).action.tolist() == [0.5] * DIM
