"""Act: an observation of the robot -> the chunk of actions a learned policy answers it with,
on ORICF's policy service (oricf.v1.Policy, `oricf serve policy`). A control loop
(oricf.gateway.control.source) fills the record: `state` (the state vector), `step` (the
robot's control step it was captured at), `capture_time_ns` (its clock then) and, for
real-time chunking, `committed` (the actions already queued, from which step), and `images`
(each camera's newest frame, by the policy's camera name; sent as the endpoint's `image`
settings say: raw as they came, or JPEG for a link that is short of bandwidth). The result's
`actions` are row-major `[chunk, action_dim]`, the first for `start_step`.

An answer is bounded before it is read: the channel of an endpoint a control input calls
takes no message larger than a chunk of MAX_CHUNK actions of its `action_dim` (gRPC refuses
a larger one as RESOURCE_EXHAUSTED as it arrives), and no answer of more actions than that
is made into an array.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.components import CallBase, Method, MethodCall
from oricf.gateway.control.queue import MAX_CHUNK
from oricf.gateway.endpoints import GrpcTarget
from oricf.gateway.methods.base import ServingHealth
from oricf.gateway.values import Frame, Record
from oricf.v1 import policy_pb2, policy_pb2_grpc

# An answer's fields beside its actions (steps, times, the model's name, timings): generous.
REPLY_FIELDS_BYTES = 64 * 1024


class ActCall(CallBase):
    """oricf.v1.Policy/Act: state, step, capture_time_ns -> actions, start_step,
    observation_step."""

    method: Literal["Act"]


@dataclass(frozen=True)
class Actions:
    actions: np.ndarray       # [chunk, action_dim], float64
    start_step: int           # the step the first action is for
    observation_step: int     # the step of the observation it answers


def observation(record: Record, transport: str = "raw",
                jpeg_quality: int = 80) -> policy_pb2.Observation:
    state = record.get("state")
    if not isinstance(state, np.ndarray) or state.ndim != 1:
        raise InvalidInput("Act needs a state vector (a control input)")
    request = policy_pb2.Observation(step=int(record.get("step", 0)),
                                     capture_time_ns=int(record.get("capture_time_ns", 0)),
                                     state=state.astype(np.float32).tolist())
    committed = record.get("committed")
    if committed is not None:
        start, rows = committed
        request.committed.start_step = int(start)
        request.committed.actions.extend(np.asarray(rows, np.float32).ravel().tolist())
    for name, frame in (record.get("images") or {}).items():
        if not isinstance(frame, Frame):
            raise InvalidInput(f"images: camera {name}: not an image")
        request.images[name].CopyFrom(frame.to_proto(transport, jpeg_quality))
    return request


def actions(reply: policy_pb2.ActionChunk) -> Actions:
    if reply.error.message:
        raise InvalidInput(f"the policy refused the observation: {reply.error.message}")
    count, dim = len(reply.actions), reply.action_dim
    if dim == 0 or count % dim:
        raise InvalidInput(f"the policy answered {count} values, not whole actions of {dim}")
    if count // dim > MAX_CHUNK:
        raise InvalidInput(f"the policy answered a chunk of {count // dim} actions (at most "
                           f"{MAX_CHUNK})")
    # One value at a time into the array: np.asarray would make a Python float of each first.
    values = np.fromiter(reply.actions, np.float64, count=count)
    return Actions(values.reshape(-1, dim), int(reply.start_step), int(reply.observation_step))


def reply_bytes(input_config: Any) -> int | None:
    """The largest answer a control input takes: a chunk of MAX_CHUNK actions of its
    action_dim (float32 values) and the answer's other fields. None for any other input."""
    control = getattr(input_config, "control", None)
    if control is None:
        return None
    return MAX_CHUNK * int(control.action_dim) * 4 + REPLY_FIELDS_BYTES


class Act(MethodCall[ActCall]):
    """A route's Act: the observation as the endpoint's image settings say."""

    result = Actions

    def execute(self, record: Record) -> Actions:
        image = self.endpoint.config.image
        request = observation(record, image.transport, image.jpeg_quality)
        return self.endpoint.run({"grpc": partial(self._over_grpc, request)})

    @staticmethod
    def _over_grpc(request: policy_pb2.Observation, target: GrpcTarget, timeout: float
                   ) -> Actions:
        return actions(target.invoke("Act", request, timeout))


METHOD = Method("Act", ActCall, "oricf.v1.Policy", policy_pb2_grpc.PolicyStub,
                ServingHealth("oricf.v1.Policy"), Act, reply_bytes=reply_bytes, rank=5)
