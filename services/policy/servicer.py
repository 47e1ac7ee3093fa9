"""oricf.v1.Policy: observations become state vectors and camera images, the policy's chunks
become answers.

An answer's first action is for the step of the observation it answers plus the policy's
declared `lead_steps` (0: the policy acts on what it sees; more: a policy trained to act
ahead of a known round trip, its first action for the step the answer arrives at); the
robot compares that step and the echoed capture time with its own clock to know how old
the action is.

Camera images are decoded within the service's memory budget (`server.max_inflight_mb`, as
the detector's) and a pixel limit fitted to each camera's network input (`images.max_pixels`):
a few kilobytes of PNG must not cost a gigabyte for a 32x32 input. An ActStream holds a call
slot only while an observation is answered, and is closed after `stream_idle_s` without one
(services/runtime/streams.py).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import ExitStack

import grpc
import numpy as np

from oricf.errors import InvalidInput, Overloaded
from oricf.imaging import decode_image, decoded_bytes, image_size
from oricf.models.policy import PolicyModel, require_finite
from oricf.services.policy.config import PolicyConfig
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.errors import status_for
from oricf.services.runtime.info import model_info_response
from oricf.services.runtime.limits import MemoryBudget
from oricf.v1 import common_pb2, policy_pb2, policy_pb2_grpc

log = logging.getLogger(__name__)
MAX_STEP = 2**64 - 1  # steps are uint64 on the wire


class PolicyServicer(policy_pb2_grpc.PolicyServicer):
    def __init__(self, slot: ModelSlot[PolicyModel], config: PolicyConfig) -> None:
        self.slot = slot
        self.config = config
        self.budget = MemoryBudget(config.server.max_inflight_bytes,
                                   config.server.retry_after_ms)

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
            except (InvalidInput, Overloaded) as exc:  # one observation must not end it
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
        start_step = _start_step(request.step, policy.task.lead_steps)
        state = np.asarray(request.state, np.float32)
        committed = None
        if request.committed.actions:  # checked above: whole, finite actions
            dim = policy.task.action.dim
            committed = (int(request.committed.start_step) - int(request.step),
                         np.asarray(request.committed.actions, np.float32).reshape(-1, dim))
        with ExitStack() as held:  # the decoded images' bytes, held until the answer
            images = {name: self._decoded(held, policy, name, image)
                      for name, image in request.images.items()}
            inference = time.perf_counter()
            actions = policy.act(state, images, committed)
        inference_ms = (time.perf_counter() - inference) * 1e3
        chunk = policy_pb2.ActionChunk(
            start_step=start_step, observation_step=request.step,
            capture_time_ns=request.capture_time_ns, action_dim=actions.shape[1],
            actions=actions.ravel().tolist(), model=policy.name)
        chunk.timings.inference_ms = inference_ms
        chunk.timings.total_ms = (time.perf_counter() - started) * 1e3
        return chunk


    def _decoded(self, held: ExitStack, policy: PolicyModel, camera: str,
                 image: common_pb2.Image) -> np.ndarray:
        """The camera's image decoded, its size checked first (from the file's header or the
        raw fields) against the camera's pixel limit, and its decoding's bytes held in the
        budget until `held` closes."""
        max_pixels = self.config.images.limit(policy.input_pixels(camera))
        args = (image.data, image.encoding, image.width, image.height, max_pixels)
        try:
            width, height = image_size(*args)
            held.enter_context(self.budget.hold(decoded_bytes(width, height),
                                                f"a {width}x{height} image"))
            return decode_image(*args)
        except InvalidInput as exc:
            raise InvalidInput(f"images: camera {camera[:64]}: {exc}") from None


def _start_step(step: int, lead_steps: int) -> int:
    """The step of the answer's first action: the observation's plus the policy's lead."""
    if step > MAX_STEP - lead_steps:
        raise InvalidInput(f"step: {step} + the policy's lead_steps {lead_steps} is past the "
                           f"last step there is ({MAX_STEP})")
    return step + lead_steps


def _check_committed(committed: policy_pb2.CommittedActions, dim: int) -> None:
    """Committed actions are whole actions of finite values, for a policy that uses them
    and one that does not alike."""
    values = np.asarray(committed.actions, np.float32)
    if values.size % dim:
        raise InvalidInput(f"committed.actions: {values.size} values is not a whole number "
                           f"of actions of {dim}")
    require_finite(values, "committed.actions")
