"""A policy task against its model file: the state input and the action output must be
what the declaration says, or the model is refused at load naming the file and the key."""

from __future__ import annotations

import math

from oricf.errors import ConfigError
from oricf.models.image import network_size
from oricf.models.policy_task import CameraInput, PolicyTask
from oricf.models.tensors import TensorSpec

FLOATS = ("FP16", "FP32", "FP64")


def _named(source: str, key: str, name: str | None, specs: list[TensorSpec],
           kind: str) -> TensorSpec:
    if not specs:
        raise ConfigError(f"{source}: {key}: the model has no {kind}s")
    wanted = name or specs[0].name
    for spec in specs:
        if spec.name == wanted:
            return spec
    raise ConfigError(f"{source}: {key}: the model has no {kind} '{wanted}' ({kind}s: "
                      f"{', '.join(s.name for s in specs)})")


def _values(shape: tuple[int, ...]) -> int | None:
    """Values per item: the product of the dimensions after the batch; None when one of
    them is free."""
    rest = shape[1:] if len(shape) > 1 else shape
    return None if any(d < 0 for d in rest) else math.prod(rest)


def check_policy(source: str, task: PolicyTask, inputs: list[TensorSpec],
                 outputs: list[TensorSpec]) -> None:
    """Raises ConfigError naming source (the declaration's file) and the task's key."""
    state = _named(source, "task.state.input", task.state.input, inputs, "input")
    committed = committed_input(source, task, inputs)
    camera_inputs(source, task, [s for s in inputs if s is not committed], state.name)
    if state.datatype not in FLOATS:
        raise ConfigError(f"{source}: task.state.input: '{state.name}' is {state.datatype}, "
                          f"a policy's state is floating point")
    size = _values(state.shape)
    if size is not None and size != task.state.size:
        raise ConfigError(f"{source}: task.state.size: {task.state.size}, the model input "
                          f"'{state.name}' takes {size} values (shape {list(state.shape)})")
    action = _named(source, "task.action.output", task.action.output, outputs, "output")
    if action.datatype not in FLOATS:
        raise ConfigError(f"{source}: task.action.output: '{action.name}' is "
                          f"{action.datatype}, a policy's action is floating point")
    values = _values(action.shape)
    if values is not None and values != task.chunk * task.action.dim:
        key = "task.action.dim" if task.chunk == 1 else "task.chunk"
        raise ConfigError(f"{source}: {key}: {task.chunk} x {task.action.dim} actions, the "
                          f"model output '{action.name}' gives {values} values (shape "
                          f"{list(action.shape)})")


def camera_inputs(source: str, task: PolicyTask, inputs: list[TensorSpec],
                  state: str) -> dict[str, tuple[TensorSpec, tuple[int, int]]]:
    """Each camera's model input and network size (width, height), by camera name; every
    input of the model is the state or one camera's, or ConfigError."""
    others = [spec for spec in inputs if spec.name != state]
    found: dict[str, tuple[TensorSpec, tuple[int, int]]] = {}
    for index, camera in enumerate(task.images):
        key = f"task.images[{index}]"
        if camera.input is None:
            if not others:
                raise ConfigError(f"{source}: {key}: the model has no input beyond the "
                                  f"state '{state}' for camera {camera.name}")
            spec = others[0]
        else:
            spec = _named(source, f"{key}.input", camera.input, others, "image input")
        found[camera.name] = (spec, _camera_size(source, key, camera, spec))
    used = {spec.name for spec, _ in found.values()}
    unfed = [spec.name for spec in others if spec.name not in used]
    if unfed:
        raise ConfigError(f"{source}: task.images: the model input {', '.join(unfed)} is "
                          f"neither the state nor a camera's (declare a camera for it)")
    return found


def _camera_size(source: str, key: str, camera: CameraInput,
                 spec: TensorSpec) -> tuple[int, int]:
    if spec.datatype != camera.datatype:
        raise ConfigError(f"{source}: {key}.datatype: {camera.datatype}, the model input "
                          f"'{spec.name}' is {spec.datatype}")
    shape = spec.shape
    channels = shape[1] if camera.layout == "nchw" else shape[-1] if shape else 0
    if len(shape) != 4 or channels not in (3, -1):
        raise ConfigError(f"{source}: {key}.layout: {camera.layout}, the model input "
                          f"'{spec.name}' is shaped {list(shape)}, not a batch of 3-channel "
                          f"images in that layout")
    try:
        size = network_size(camera, shape)
    except ValueError as exc:
        raise ConfigError(f"{source}: {key}.size: {exc}".replace("task.image.size",
                                                                  f"{key}.size")) from None
    height, width = (shape[2], shape[3]) if camera.layout == "nchw" else (shape[1], shape[2])
    if (width > 0 and width != size[0]) or (height > 0 and height != size[1]):
        raise ConfigError(f"{source}: {key}.size: {list(size)}, the model input "
                          f"'{spec.name}' takes {width}x{height} (shape {list(shape)})")
    return size


def committed_input(source: str, task: PolicyTask, inputs: list[TensorSpec]
                    ) -> TensorSpec | None:
    """The input the committed actions feed (floating point, steps x dim values), if any."""
    if task.committed is None:
        return None
    spec = _named(source, "task.committed.input", task.committed.input, inputs, "input")
    if spec.datatype not in FLOATS:
        raise ConfigError(f"{source}: task.committed.input: '{spec.name}' is {spec.datatype}, "
                          f"actions are floating point")
    values, wanted = _values(spec.shape), task.committed.steps * task.action.dim
    if values is not None and values != wanted:
        raise ConfigError(f"{source}: task.committed.steps: {task.committed.steps} x "
                          f"{task.action.dim} actions, the model input '{spec.name}' takes "
                          f"{values} values (shape {list(spec.shape)})")
    return spec
