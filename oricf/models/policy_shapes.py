"""A policy task against its model file: the state input and the action output must be
what the declaration says, or the model is refused at load naming the file and the key."""

from __future__ import annotations

import math

from oricf.errors import ConfigError
from oricf.models.policy_task import PolicyTask
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
    others = [s.name for s in inputs if s.name != state.name]
    if others:
        raise ConfigError(f"{source}: task.images: the model has inputs beyond the state "
                          f"({', '.join(others)}); camera inputs are not supported yet")
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
