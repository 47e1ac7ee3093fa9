"""`task: {kind: policy}`: a learned control policy, observation in, a chunk of actions out.

    task:
      kind: policy
      state: {input: observation, size: 15}      # optional mean/std: (state - mean) / std
      action: {output: action, dim: 3, low: -1, high: 1}
      chunk: 1                                   # actions per answer, one per control step
      rate_hz: 60.606                            # the control rate the policy was trained at
      lead_steps: 0                              # the chunk's first action: steps after the
                                                 # observation (a policy acting ahead)
      committed: {input: committed, steps: 8}    # optional: the actions already queued
      images:                                    # optional: cameras, each an image input
        - {name: top, input: image, size: [32, 32], resize: stretch, color: rgb,
           scale: 0.00392156862745098}

The model file's shapes are checked against these at load (oricf.models.policy).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.models.image_input import ImageInput

MAX_SIZE = 1 << 16  # values in a state or an action chunk
MAX_LEAD = 1024  # steps ahead: far beyond any round trip a chunk could bridge
MAX_CAMERAS = 8
CAMERA_NAME = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"


class StateInput(Schema):
    """The robot's state vector (joint positions, velocities, ...) as one model input."""

    input: str | None = Field(None, description="the model input it feeds (default: first)")
    size: int = Field(ge=1, le=MAX_SIZE, description="values in the state vector")
    mean: list[float] | None = Field(None, description="normalisation: (state - mean) / std")
    std: list[float] | None = None

    @model_validator(mode="after")
    def _normalisation(self) -> StateInput:
        for key in ("mean", "std"):
            values = getattr(self, key)
            if values is not None and len(values) != self.size:
                raise ValueError(f"{key}: {len(values)} values, size is {self.size}")
        if self.std is not None and min(self.std) <= 0:
            raise ValueError("std: every value must be > 0")
        return self


class CameraInput(ImageInput):
    """One camera as a model input, by the name observations give its images under; made
    into the input's tensor as a detector's image is (resize, colour, scale, layout)."""

    name: str = Field(pattern=CAMERA_NAME, description="the camera's name in observations")


class CommittedInput(Schema):
    """The actions the robot has already committed to, as one model input (real-time
    chunking): `steps` actions from the observation's own step on, row-major; a step nothing
    is committed for is zeros."""

    input: str = Field(description="the model input they feed")
    steps: int = Field(ge=1, le=MAX_LEAD, description="actions, from the observation's step")


class ActionOutput(Schema):
    """The action the policy answers: its output, dimension and bounds (answers are clipped
    to them)."""

    output: str | None = Field(None, description="the model output (default: first)")
    dim: int = Field(ge=1, le=MAX_SIZE, description="values in one action")
    low: float | list[float] = Field(-1.0, description="lower bound, one or per value")
    high: float | list[float] = Field(1.0, description="upper bound, one or per value")

    def bounds(self) -> tuple[list[float], list[float]]:
        def each(value: float | list[float]) -> list[float]:
            return [float(value)] * self.dim if isinstance(value, (int, float)) else value
        return each(self.low), each(self.high)

    @model_validator(mode="after")
    def _bounds(self) -> ActionOutput:
        for key in ("low", "high"):
            value = getattr(self, key)
            if isinstance(value, list) and len(value) != self.dim:
                raise ValueError(f"{key}: {len(value)} values, dim is {self.dim}")
        low, high = self.bounds()
        if any(lo > hi for lo, hi in zip(low, high, strict=True)):
            raise ValueError("low: above high")
        return self


class PolicyTask(Schema):
    kind: Literal["policy"]
    state: StateInput
    images: list[CameraInput] = Field(
        default_factory=list, max_length=MAX_CAMERAS,
        description="camera inputs, each an image input of the model (none: the state only)")
    action: ActionOutput
    committed: CommittedInput | None = Field(
        None, description="feed the actions already committed (Observation.committed) to "
                          "this input: a policy trained to condition on them")
    chunk: int = Field(1, ge=1, le=1024, description="actions per answer, one per step")
    rate_hz: float = Field(gt=0, le=10_000, description="the control rate, steps per second")
    lead_steps: int = Field(
        0, ge=0, le=MAX_LEAD,
        description="the chunk's first action is for this many steps after the observation: "
                    "a policy trained to act ahead of a known round trip")

    @field_validator("images")
    @classmethod
    def _cameras(cls, images: list[CameraInput]) -> list[CameraInput]:
        names = [camera.name for camera in images]
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:
            raise ValueError(f"the name {', '.join(twice)} is given twice")
        if len(images) > 1 and any(camera.input is None for camera in images):
            raise ValueError("with more than one camera, each names its input")
        return images

    @model_validator(mode="after")
    def _chunk_size(self) -> PolicyTask:
        if self.chunk * self.action.dim > MAX_SIZE:
            raise ValueError(f"chunk: {self.chunk} x {self.action.dim} values is more than "
                             f"{MAX_SIZE}")
        return self
