"""What the runtime needs of a model, and the slot that holds it while it loads.

Model classes never import grpc: they load, infer and close; the servicer translates.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from oricf.errors import NotReady
from oricf.models.info import ModelInfo

if TYPE_CHECKING:
    from oricf.services.runtime.batching import Batcher

log = logging.getLogger(__name__)

__all__ = ["Model", "ModelInfo", "ModelSlot"]


class Model(Protocol):
    def load(self) -> None:
        """Loads weights and warms up; heavy imports belong here, not at module level."""

    def close(self) -> None:
        """Releases the weights."""

    def info(self) -> ModelInfo: ...


M = TypeVar("M", bound=Model)


class ModelSlot(Generic[M]):
    """Holds a model and says whether it may be used yet (NotReady until loaded), and the
    batchers that feed it: they drain before it closes."""

    def __init__(self, model: M) -> None:
        self._model = model
        self._ready = threading.Event()
        self._closing = False
        self.load_seconds = 0.0
        self.batchers: list[Batcher[Any, Any]] = []

    def attach(self, batcher: Batcher[Any, Any]) -> None:
        self.batchers.append(batcher)

    def flush(self) -> None:
        """The service is draining: batches run with what waits, without waiting to fill."""
        for batcher in self.batchers:
            batcher.flush()

    @property
    def ready(self) -> bool:
        return self._ready.is_set()

    def get(self) -> M:
        if not self._ready.is_set():
            state = "shutting down" if self._closing else "still loading its model"
            raise NotReady(f"the service is {state}; retry shortly")
        return self._model

    def peek(self) -> M:
        """The model whether loaded or not (for its description)."""
        return self._model

    def load(self) -> float:
        started = time.perf_counter()
        self._model.load()
        self.load_seconds = time.perf_counter() - started
        self._ready.set()
        return self.load_seconds

    def close(self) -> None:
        self._closing = True
        self._ready.clear()
        for batcher in self.batchers:
            batcher.close()
        self._model.close()
