"""A declared policy, loaded: a state vector (and the images of its cameras) in, a chunk of
bounded actions out.

The model class of `oricf serve policy`. It checks what arrives (length, NaN, infinity;
every declared camera's image and no other), normalises the state as declared, makes each
image its input's tensor as the declaration says (as a detector's image), runs the model and
returns `chunk` actions of `dim` values each, clipped to the declared bounds; an answer that
is not finite is refused, never sent to a robot. The same two checks (finite inputs, a finite
answer) guard the policy where `oricf serve models` serves it over the Open Inference Protocol.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping

import numpy as np

from oricf.errors import ConfigError, InvalidInput
from oricf.models.declaration import ModelDeclaration
from oricf.models.declared import DeclaredModel
from oricf.models.image import to_tensor
from oricf.models.info import ModelInfo
from oricf.models.policy_shapes import camera_inputs, committed_input
from oricf.models.policy_task import CameraInput, PolicyTask
from oricf.models.tensors import DATATYPES, clip
from oricf.store import ModelStore

log = logging.getLogger(__name__)


def require_finite(values: np.ndarray, name: str) -> None:
    """InvalidInput naming the first value of `name` that is NaN or infinite."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InvalidInput(f"{name}[{bad[0]}] is {values[bad[0]]}: every value must be "
                           f"finite")


class PolicyFailed(InvalidInput):
    """The model answered NaN or infinity for a valid observation: nothing is sent."""


def require_finite_inputs(feeds: Mapping[str, np.ndarray]) -> None:
    """Every value of a policy's floating-point inputs finite, as the network takes it
    (InvalidInput naming the input and the first value that is not)."""
    for name, value in feeds.items():
        if value.dtype.kind == "f":
            require_finite(value.reshape(-1), f"input '{clip(name)}'")


def require_finite_answer(policy: str, outputs: Mapping[str, np.ndarray]) -> None:
    """PolicyFailed when a floating-point output holds NaN or infinity: a network that
    overflows (a state of 3.4e38 is finite, its products are not) gives no action."""
    for name, value in outputs.items():
        if value.dtype.kind == "f" and not np.all(np.isfinite(value)):
            raise PolicyFailed(f"policy {policy} answered NaN or infinity (output "
                               f"'{clip(name)}') for this observation; no action is given")


class PolicyModel:
    def __init__(self, declaration: ModelDeclaration, store: ModelStore) -> None:
        if not isinstance(declaration.task, PolicyTask):
            raise ConfigError(f"{declaration.source}: task.kind: the policy service serves "
                              f"policies (task: {{kind: policy, ...}})")
        self.task: PolicyTask = declaration.task
        self.model = DeclaredModel(declaration, store)
        self.name = declaration.name
        state = self.task.state
        self._mean = np.asarray(state.mean or np.zeros(state.size), np.float32)
        self._std = np.asarray(state.std or np.ones(state.size), np.float32)
        low, high = self.task.action.bounds()
        self.low, self.high = np.asarray(low, np.float32), np.asarray(high, np.float32)
        self._input = ""
        self._output = ""
        self._feed_shape: tuple[int, ...] = ()
        self._dtype = np.dtype(np.float32)
        # camera name -> (its settings, its model input, the network size (w, h))
        self._cameras: dict[str, tuple[CameraInput, str, tuple[int, int]]] = {}
        self._committed_input = ""  # the input the committed actions feed ("" : none)

    def load(self) -> None:
        self.model.load()  # checks the file's shapes against the task
        spec = self.model.inputs[0] if self.task.state.input is None \
            else self.model.input(self.task.state.input)
        self._input = spec.name
        self._output = self.task.action.output or self.model.outputs[0].name
        self._dtype = np.dtype(DATATYPES[spec.datatype].numpy)
        # One item: a batch of 1 when the input has a batch dimension.
        self._feed_shape = (1, self.task.state.size) if len(spec.shape) == 2 \
            else (self.task.state.size,)
        source = str(self.model.declaration.source)
        committed = committed_input(source, self.task, self.model.inputs)
        self._committed_input = "" if committed is None else committed.name
        found = camera_inputs(source, self.task,
                              [s for s in self.model.inputs if s is not committed], spec.name)
        settings = {camera.name: camera for camera in self.task.images}
        self._cameras = {name: (settings[name], input_spec.name, size)
                         for name, (input_spec, size) in found.items()}
        cameras = ", ".join(f"{name} {w}x{h}" for name, (_, _, (w, h)) in self._cameras.items())
        log.info("policy %s: state %d%s, action %d x %d at %.1f Hz, %d steps ahead", self.name,
                 self.task.state.size, f", cameras {cameras}" if cameras else "",
                 self.task.chunk, self.task.action.dim, self.task.rate_hz,
                 self.task.lead_steps)

    def close(self) -> None:
        self.model.close()

    def info(self) -> ModelInfo:
        info = self.model.info()
        task = self.task
        info.parameters.update(state_size=str(task.state.size), action_dim=str(task.action.dim),
                               chunk=str(task.chunk), rate_hz=f"{task.rate_hz:g}",
                               lead_steps=str(task.lead_steps))
        return info

    def check_state(self, state: np.ndarray) -> None:
        size = self.task.state.size
        if state.shape != (size,):
            raise InvalidInput(f"state: {state.size} values, policy {self.name} takes {size}")
        require_finite(state, "state")

    @property
    def cameras(self) -> list[str]:
        """The names of the cameras whose images every observation must carry."""
        return [camera.name for camera in self.task.images]

    def input_pixels(self, camera: str) -> int:
        """The pixels of the network's image for a declared camera (width x height)."""
        _, _, (width, height) = self._cameras[camera]
        return width * height

    def check_images(self, images: Mapping[str, object]) -> None:
        """Exactly the declared cameras (InvalidInput naming the missing or unknown one)."""
        missing = [name for name in self.cameras if name not in images]
        if missing:
            raise InvalidInput(f"images: no image from camera {missing[0]} (policy "
                               f"{self.name} sees {', '.join(self.cameras)})")
        unknown = sorted(set(images) - set(self.cameras))
        if unknown:
            raise InvalidInput(f"images: policy {self.name} has no camera "
                               f"{unknown[0][:64]!r} (its cameras: "
                               f"{', '.join(self.cameras) or 'none'})")

    def act(self, state: np.ndarray, images: Mapping[str, np.ndarray] | None = None,
            committed: tuple[int, np.ndarray] | None = None) -> np.ndarray:
        """[chunk, dim] actions for one state vector (float32, checked here), the image of
        each declared camera (BGR uint8, height x width x 3, as decode_image gives) and the
        actions already committed: (the step of the first after the observation's, [n, dim]
        finite values), for a policy that takes them (task.committed)."""
        state = np.asarray(state, np.float32)
        self.check_state(state)
        self.check_images(images or {})
        normalised = ((state - self._mean) / self._std).astype(self._dtype)
        feed: dict[str, np.ndarray] = {self._input: normalised.reshape(self._feed_shape)}
        for name, (camera, input_name, size) in self._cameras.items():
            feed[input_name] = _image_tensor((images or {})[name], camera, size, name)
        if self._committed_input and self.task.committed is not None:
            window = committed_window(committed, self.task.committed.steps,
                                      self.task.action.dim)
            feed[self._committed_input] = window.reshape(1, -1).astype(self._dtype)
        require_finite_inputs(feed)  # a finite state may overflow once normalised
        raw = np.asarray(self.model.infer(feed)[self._output], np.float32)
        require_finite_answer(self.name, {self._output: raw})
        actions = raw.reshape(self.task.chunk, self.task.action.dim)
        return np.clip(actions, self.low, self.high)


def _image_tensor(image: np.ndarray, camera: CameraInput, size: tuple[int, int],
                  name: str) -> np.ndarray:
    if not (isinstance(image, np.ndarray) and image.dtype == np.uint8 and image.ndim == 3
            and image.shape[2] == 3 and min(image.shape[:2]) >= 1):
        shape = getattr(image, "shape", None)
        raise InvalidInput(f"images: camera {name}: not a colour image (shape {shape})")
    tensor, _ = to_tensor(image, camera, size)
    return tensor


def committed_window(committed: tuple[int, np.ndarray] | None, steps: int, dim: int
                     ) -> np.ndarray:
    """[steps, dim]: row i the action committed for the observation's step + i, zeros where
    none is (before the first committed, after the last, or nothing sent)."""
    window = np.zeros((steps, dim), np.float32)
    if committed is None:
        return window
    offset, actions = committed
    actions = np.asarray(actions, np.float32).reshape(-1, dim)
    for row, action in enumerate(actions):
        step = offset + row
        if 0 <= step < steps:
            window[step] = action
    return window
