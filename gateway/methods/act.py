"""Act: an observation of the robot -> the chunk of actions a learned policy answers it with,
on ORICF's policy service (oricf.v1.Policy, `oricf serve policy`). A control loop
(oricf.gateway.sources.control) fills the record: `state` (the state vector), `step` (the
robot's control step it was captured at), `capture_time_ns` (its clock then) and, for
real-time chunking, `committed` (the actions already queued, from which step), and `images`
(each camera's newest frame, by the policy's camera name; sent as the endpoint's `image`
settings say: raw as they came, or JPEG for a link that is short of bandwidth). The result's
`actions` are row-major `[chunk, action_dim]`, the first for `start_step`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.components import CallBase, Invoke, Method
from oricf.gateway.endpoints import Endpoint, GrpcTarget
from oricf.gateway.methods.base import health_check
from oricf.gateway.products import ProductStore
from oricf.gateway.values import Frame, Record
from oricf.v1 import policy_pb2, policy_pb2_grpc


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
    values = np.asarray(reply.actions, np.float64)
    if reply.action_dim == 0 or values.size % reply.action_dim:
        raise InvalidInput(f"the policy answered {values.size} values, not whole actions of "
                           f"{reply.action_dim}")
    return Actions(values.reshape(-1, reply.action_dim), int(reply.start_step),
                   int(reply.observation_step))


def bind(call: ActCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    def invoke(record: Record) -> Actions:
        image = endpoint.config.image
        request = observation(record, image.transport, image.jpeg_quality)

        def over_grpc(target: GrpcTarget, timeout: float) -> Actions:
            return actions(target.invoke("Act", request, timeout))

        return endpoint.run({"grpc": over_grpc})

    return invoke


def result(call: Any) -> type:
    return Actions


METHOD = Method("Act", ActCall, "oricf.v1.Policy", policy_pb2_grpc.PolicyStub,
                health_check("oricf.v1.Policy"), result, bind, rank=5)
