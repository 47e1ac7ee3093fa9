"""oricf.v1.Policy: observations become state vectors and camera images, the policy's chunks
become answers.

An answer's first action is for the step of the observation it answers plus the policy's
declared `lead_steps` (0: the policy acts on what it sees; more: a policy trained to act
ahead of a known round trip, its first action for the step the answer arrives at); the
robot compares that step and the echoed capture time with its own clock to know how old
the action is.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import grpc
import numpy as np

from oricf.errors import InvalidInput
from oricf.imaging import decode_image
from oricf.models.policy import PolicyModel, require_finite
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.errors import status_for
from oricf.services.runtime.info import model_info_response
from oricf.v1 import common_pb2, policy_pb2, policy_pb2_grpc

log = logging.getLogger(__name__)


class PolicyServicer(policy_pb2_grpc.PolicyServicer):
    def __init__(self, slot: ModelSlot[PolicyModel]) -> None:
        self.slot = slot

    def Act(self, request: policy_pb2.Observation,
            context: grpc.ServicerContext) -> policy_pb2.ActionChunk:
        return self.act(request)

    def ActStream(self, request_iterator: Iterator[policy_pb2.Observation],
                  context: grpc.ServicerContext) -> Iterator[policy_pb2.ActionChunk]:
        # An action takes tens of microseconds: each observation is answered before the
        # next is read, so a client that does not read its answers is pushed back by gRPC's
        # flow control instead of queueing here.
        for request in request_iterator:
            try:
                yield self.act(request)
            except InvalidInput as exc:  # one bad observation must not end the stream
                code, message = status_for(exc)
                log.debug("observation %d refused: %s", request.step, message)
                yield policy_pb2.ActionChunk(
                    observation_step=request.step, capture_time_ns=request.capture_time_ns,
                    model=self.slot.peek().name,
                    error=common_pb2.Error(code=code.value[0], message=message))

    def GetModelInfo(self, request: common_pb2.GetModelInfoRequest,
                     context: grpc.ServicerContext) -> common_pb2.GetModelInfoResponse:
        return model_info_response("policy", self.slot)

    def act(self, request: policy_pb2.Observation) -> policy_pb2.ActionChunk:
        started = time.perf_counter()
        policy = self.slot.get()
        policy.check_images(request.images)  # names first: nothing unknown is decoded
        _check_committed(request.committed, policy.task.action.dim)
        state = np.asarray(request.state, np.float32)
        images = {name: _decoded(name, image) for name, image in request.images.items()}
        inference = time.perf_counter()
        committed = None
        if request.committed.actions:  # checked above: whole, finite actions
            dim = policy.task.action.dim
            committed = (int(request.committed.start_step) - int(request.step),
                         np.asarray(request.committed.actions, np.float32).reshape(-1, dim))
        actions = policy.act(state, images, committed)
        inference_ms = (time.perf_counter() - inference) * 1e3
        chunk = policy_pb2.ActionChunk(
            start_step=request.step + policy.task.lead_steps, observation_step=request.step,
            capture_time_ns=request.capture_time_ns, action_dim=actions.shape[1],
            actions=actions.ravel().tolist(), model=policy.name)
        chunk.timings.inference_ms = inference_ms
        chunk.timings.total_ms = (time.perf_counter() - started) * 1e3
        return chunk


def _decoded(camera: str, image: common_pb2.Image) -> np.ndarray:
    try:
        return decode_image(image.data, image.encoding, image.width, image.height)
    except InvalidInput as exc:
        raise InvalidInput(f"images: camera {camera[:64]}: {exc}") from None


def _check_committed(committed: policy_pb2.CommittedActions, dim: int) -> None:
    """Committed actions are whole actions of finite values, for a policy that uses them
    and one that does not alike."""
    values = np.asarray(committed.actions, np.float32)
    if values.size % dim:
        raise InvalidInput(f"committed.actions: {values.size} values is not a whole number "
                           f"of actions of {dim}")
    require_finite(values, "committed.actions")
