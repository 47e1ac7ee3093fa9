"""A model service as one class: `Service`, which the runtime serves (handlers.py).

A service subclasses `Service` and names three things: `name` (`oricf serve NAME`, its
metrics' label), `proto` (the gRPC service it answers, from its `_pb2` module) and
`config_schema` (its YAML). Its lifecycle is a model's: the constructor resolves the config
and loads nothing, `load()` loads the weights (heavy imports there), `close()` frees them,
`info()` describes them. Each RPC of the proto is a method named after it in snake_case
(`Detect` -> `detect`, `ActStream` -> `act_stream`) that takes the request message (an
iterator of them for a client stream) and the `Call`, and returns the response (an iterator
of them for a server stream). It raises the domain errors of `oricf.errors`; it never
imports grpc.

The runtime does the rest, the same for every service: parsing and serializing the
messages, refusing each call (and each message of a client stream) with UNAVAILABLE until
`load()` has returned, mapping errors to status codes, GetModelInfo from `info()`, health
and reflection under the proto's name, the call limit, TLS, tokens, metrics, and on SIGTERM
the drain, the flush of the batchers made with `batched()`, and `close()`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Protocol, TypeVar

from oricf.models.info import ModelInfo
from oricf.services.runtime.batching import Batcher, BatchingSettings, RunBatch
from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.limits import MemoryBudget
from oricf.services.runtime.streams import MessageStreams
from oricf.store import ModelStore

if TYPE_CHECKING:
    from google.protobuf.descriptor import ServiceDescriptor

    from oricf.services.runtime.shared_memory import SharedMemoryRegistry

C = TypeVar("C", bound=ServiceConfig)
T = TypeVar("T")
R = TypeVar("R")


class Call(Protocol):
    """What a handler may ask of its call (grpc's ServicerContext is one)."""

    def time_remaining(self) -> float | None: ...

    def is_active(self) -> bool: ...

    def add_callback(self, callback: Callable[[], None]) -> bool: ...

    def set_trailing_metadata(self, trailing_metadata: Sequence[tuple[str, str]]) -> None: ...


class Service(Generic[C]):
    """Base of a model service; see the module's docstring."""

    name: ClassVar[str]
    proto: ClassVar[ServiceDescriptor]
    config_schema: ClassVar[type[ServiceConfig]]

    def __init__(self, config: C, store: ModelStore) -> None:
        self.config = config
        self.store = store
        # Decoded images and input tensors its calls hold at once (server.max_inflight_mb).
        self.budget = MemoryBudget(config.server.max_inflight_bytes,
                                   config.server.retry_after_ms)
        self.batchers: list[Batcher[Any, Any]] = []
        # Set to serve the Open Inference Protocol's system shared-memory RPCs beside its own.
        self.shared_memory: SharedMemoryRegistry | None = None

    def load(self) -> None:
        """Loads the weights and warms up; the runtime serves no RPC until this returns."""

    def close(self) -> None:
        """Frees the weights, after the calls in flight have drained."""

    def info(self) -> ModelInfo:
        raise NotImplementedError(f"{type(self).__name__}.info")

    @classmethod
    def message_streams(cls, config: Any) -> MessageStreams | None:
        """Its streaming RPCs answered message by message (streams.py): each holds a call
        slot only while a message is answered. None: a stream holds one while open."""
        return None

    @classmethod
    def streams(cls, methods: Sequence[str], idle_s: float, key: str) -> MessageStreams:
        """MessageStreams for the named RPCs of its proto."""
        return MessageStreams(frozenset(f"/{cls.proto.full_name}/{m}" for m in methods),
                              idle_s, key)

    def batched(self, settings: BatchingSettings, run_batch: RunBatch[T, R],
                part: str = "") -> Batcher[T, R]:
        """A batcher for calls of different callers to share one run_batch; the runtime
        runs what waits as the service drains and closes it before `close()`."""
        name = f"{self.name}/{part}" if part else self.name
        batcher: Batcher[T, R] = Batcher(name, settings, run_batch,
                                         self.config.server.retry_after_ms)
        self.batchers.append(batcher)
        return batcher
