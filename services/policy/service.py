"""The policy service: `oricf serve policy`, oricf.v1.Policy for any declared policy:
observations become state vectors and camera images, the policy's chunks become answers.

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

import numpy as np
from pydantic import Field

from oricf.config import FilePath, Schema, config_dir
from oricf.errors import InvalidInput
from oricf.imaging import MAX_PIXELS, decode_image, decoded_bytes, image_size
from oricf.models.declaration import load_declaration
from oricf.models.info import ModelInfo
from oricf.models.policy import PolicyModel, require_finite
from oricf.services.runtime import Call, Service, ServiceConfig
from oricf.services.runtime.errors import MESSAGE_REFUSALS, refusal
from oricf.services.runtime.streams import MessageStreams
from oricf.store import ModelStore
from oricf.v1 import common_pb2, policy_pb2

log = logging.getLogger(__name__)
MAX_STEP = 2**64 - 1  # steps are uint64 on the wire
# A camera's image may always be as large as a full-HD frame, and larger for a network that
# takes large images: up to this many times its input's pixels.
FULL_HD_PIXELS = 1920 * 1080
INPUT_MULTIPLE = 64


class CameraImageSettings(Schema):
    max_pixels: int | None = Field(
        None, ge=1, le=MAX_PIXELS,
        description="refuse larger camera images; default: fitted to each camera's input, "
                    f"the larger of 1920x1080 and {INPUT_MULTIPLE} times its pixels")

    def limit(self, input_pixels: int) -> int:
        """The most pixels an image of a camera whose network input has input_pixels."""
        if self.max_pixels is not None:
            return self.max_pixels
        return min(MAX_PIXELS, max(FULL_HD_PIXELS, INPUT_MULTIPLE * input_pixels))


class PolicyConfig(ServiceConfig):
    """configs/services/policy.yaml: the server, which declared policy it serves, how long a
    quiet stream stays open and how large a camera's images may be."""

    model: FilePath = Field(
        default_factory=lambda: config_dir() / "models" / "policies" / "hopper.yaml",
        description="a declared policy (task: {kind: policy}; configs/models/policies/*.yaml)")
    stream_idle_s: float = Field(
        10.0, gt=0, le=3600,
        description="an ActStream that sends no observation for this long is closed "
                    "(DEADLINE_EXCEEDED), so quiet streams cannot keep others out")
    images: CameraImageSettings = Field(
        default_factory=CameraImageSettings, description="camera images in observations")


class Policy(Service[PolicyConfig]):
    name = "policy"
    proto = policy_pb2.DESCRIPTOR.services_by_name["Policy"]
    config_schema = PolicyConfig

    def __init__(self, config: PolicyConfig, store: ModelStore) -> None:
        super().__init__(config, store)
        self.policy = PolicyModel(load_declaration(config.model), store)  # refuses non-policies

    def load(self) -> None:
        self.policy.load()

    def close(self) -> None:
        self.policy.close()

    def info(self) -> ModelInfo:
        return self.policy.info()

    @classmethod
    def message_streams(cls, config: PolicyConfig) -> MessageStreams:
        """ActStream: a robot's stream holds a call slot only while an observation is
        answered."""
        return cls.streams(["ActStream"], config.stream_idle_s, "stream_idle_s")

    def act_stream(self, requests: Iterator[policy_pb2.Observation],
                   call: Call) -> Iterator[policy_pb2.ActionChunk]:
        # An action takes tens of microseconds: each observation is answered before the
        # next is read, so a client that does not read its answers is pushed back by gRPC's
        # flow control instead of queueing here.
        for request in requests:
            try:
                yield self.act(request)
            except MESSAGE_REFUSALS as exc:  # one observation must not end it
                error = refusal(exc)
                log.debug("observation %d refused: %s", request.step, error.message)
                yield policy_pb2.ActionChunk(
                    observation_step=request.step, capture_time_ns=request.capture_time_ns,
                    model=self.policy.name, error=error)

    def act(self, request: policy_pb2.Observation,
            call: Call | None = None) -> policy_pb2.ActionChunk:
        started = time.perf_counter()
        policy = self.policy
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
            images = {name: self._decoded(held, name, image)
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

    def _decoded(self, held: ExitStack, camera: str, image: common_pb2.Image) -> np.ndarray:
        """The camera's image decoded, its size checked first (from the file's header or the
        raw fields) against the camera's pixel limit, and its decoding's bytes held in the
        budget until `held` closes."""
        max_pixels = self.config.images.limit(self.policy.input_pixels(camera))
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


SERVICE = Policy
