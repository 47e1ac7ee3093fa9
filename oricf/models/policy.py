"""A declared policy, loaded: a state vector in, a chunk of bounded actions out.

The model class of `oricf serve policy`. It checks what arrives (length, NaN, infinity),
normalises the state as declared, runs the model and returns `chunk` actions of `dim`
values each, clipped to the declared bounds; an answer that is not finite is refused, never
sent to a robot.
"""

from __future__ import annotations

import logging

import numpy as np

from oricf.errors import ConfigError, InvalidInput
from oricf.models.declaration import ModelDeclaration
from oricf.models.declared import DeclaredModel
from oricf.models.info import ModelInfo
from oricf.models.policy_task import PolicyTask
from oricf.models.tensors import DATATYPES
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
        log.info("policy %s: state %d, action %d x %d at %.1f Hz, %d steps ahead", self.name,
                 self.task.state.size, self.task.chunk, self.task.action.dim,
                 self.task.rate_hz, self.task.lead_steps)

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

    def act(self, state: np.ndarray) -> np.ndarray:
        """[chunk, dim] actions for one state vector (float32, checked here)."""
        state = np.asarray(state, np.float32)
        self.check_state(state)
        feed = ((state - self._mean) / self._std).astype(self._dtype).reshape(self._feed_shape)
        raw = self.model.infer({self._input: feed})[self._output]
        actions = np.asarray(raw, np.float32).reshape(self.task.chunk, self.task.action.dim)
        if not np.all(np.isfinite(actions)):
            raise PolicyFailed(f"policy {self.name} answered NaN or infinity for this "
                               f"observation; no action is given")
        return np.clip(actions, self.low, self.high)
