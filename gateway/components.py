"""The gateway's components and how they are found: sources, methods, post steps, sinks.

A component is one module in its kind's package (oricf.gateway.sources, .methods, .post,
.sinks) that declares, at module level, what it is: `COMPONENT = StepKind(...)` (or
SourceKind, SinkKind) or `METHOD = Method(...)`. The declaration says the component's YAML
key, its settings schema (pydantic), the record fields it reads and writes, and how it is
built. Each package's `COMPONENTS` names its component modules, one line each; the kind's
`Registry` imports those the first time it is asked and keeps their declarations (a listed
module that is missing or declares nothing, or two that declare one key, are errors naming
them). The list is explicit so that loading the schema imports the declarations and nothing
else: a component whose implementation needs a device, a network stream or a codec keeps it
in a module of its own, which its `open` (or `build`) imports when a pipeline runs.

The pipeline schema (oricf.gateway.config) builds its unions from the registries, so the core
(config, pipeline, route, worker, this module) imports no component; pyproject's import
contracts check that. A route's `call:` is a discriminated union on `method` (a pydantic
`Field(discriminator=...)` over the registered call schemas). A route's `input:`, each of its
`outputs[]` and each `post[]` step is one flat mapping in which exactly one key names the
component (`{url: ..., fps: 5}`, `{count: {label: person}}`): those are built with
pydantic.create_model from the components' settings as optional fields plus an "exactly one"
rule, rather than as a tagged union (pydantic.Discriminator + Tag), because a tagged union puts
its tag into every error's path (`input.url.fps`); the built models keep the paths users' files
were always told (`routes.people.post[0].count.label`, `routes.x.input: ...`).
"""

from __future__ import annotations

import dataclasses
import importlib
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar, Generic, Protocol, TypeAlias, TypeVar

import grpc
from pydantic import Field

from oricf.config import Schema
from oricf.gateway.channels.server import Channels
from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.endpoints import Endpoint, Ready
from oricf.gateway.products import ProductStore
from oricf.gateway.speaking import Speaking
from oricf.gateway.values import Record


class ComponentError(RuntimeError):
    """The components of a kind cannot be registered (two modules declare one key)."""


S = TypeVar("S")


class Step(ABC, Generic[S]):
    """A post step built for one route from its settings (the `{key: settings}` of its
    `post:` entry), once per route: the record fields it reads, the one it writes (if any,
    set by each step from its settings), and `run`, what it does to each record. A step that
    keeps state between records (a tracker) keeps it here, safe for the threads a route's
    records come from."""

    reads: frozenset[str]
    writes: str | None = None

    def __init__(self, settings: S) -> None:
        self.settings = settings

    @abstractmethod
    def run(self, record: Record) -> None:
        """Reads its fields of the record and writes its own."""


@dataclass(frozen=True)
class StepKind:
    """A post step: `{key: settings}` in a route's `post:` list."""

    key: str
    settings: Any                        # its schema (a pydantic class, or a type like dict)
    step: type[Step[Any]]                # its class, built from the settings once per route
    rank: int = 100                      # where it is listed among the steps (messages, docs)

    def build(self, settings: Any) -> Step[Any]:
        """The step of one route, from its validated settings."""
        return self.step(settings)


class Builds(Protocol):
    def build(self) -> Step[Any]: ...


class PostSteps:
    """A route's post steps, built once from its `post:` list, run in order on each record
    (after its call, before its outputs)."""

    def __init__(self, steps: Iterable[Builds]) -> None:
        self.steps = [step.build() for step in steps]

    def run(self, record: Record) -> None:
        for step in self.steps:
            step.run(record)


class TopicIo(Protocol):
    """ROS topics for components that read and write them themselves (a control loop): the
    ROS node's, given by the shell, so that no component imports rclpy."""

    def subscribe(self, topic: str, type_: str, take: Callable[[Any], None]) -> None:
        """Calls `take(message)` with each message, newest only (depth 1)."""

    def publisher(self, topic: str, type_: str) -> Callable[[dict[str, Any]], None]:
        """A function that publishes a message given as nested fields."""


class Emitter:
    """Where a pipeline's outputs go, one value at a time: its outlets
    (oricf.gateway.outlets.Outlets), the ROS node's topic publishers, a replay's recording,
    or what a test or a benchmark collects. This one sends nowhere; `speaking` is the state of
    the speech its outputs play, if they play any, and `speakers` what they play it on."""

    speaking: Speaking | None = None

    def emit(self, output: Any, value: Any, record: Record) -> None:
        """Sends `value` to `output` (an OutputConfig); `record` is the whole record it came
        from (an annotated image takes the input's header from it)."""

    @property
    def speakers(self) -> Mapping[str, Any]:
        """The speakers its outputs play on, by device (for /metrics)."""
        return NO_SPEAKERS


NO_SPEAKERS: Mapping[str, Any] = MappingProxyType({})


@dataclass
class ComponentContext:
    """What a pipeline gives the components it builds (its sources and sinks)."""

    config: Any              # the PipelineConfig (oricf.gateway.config, built on this module)
    channels: Channels       # the pipeline's text channels
    speaking: Speaking       # whether a speaker plays, and barge-in
    # Where topic outputs go: the ROS node's publishers, or in a replay the recording.
    ros: Emitter | None = None
    topics: TopicIo | None = None    # the ROS node's topics, for sources that use them
    # The pipeline's control loops by route (its /metrics and status read them).
    loops: dict[str, ControlLoop] = dataclasses.field(default_factory=dict)


class Sink(ABC):
    """Where an output's values go (one object per output key in a pipeline)."""

    # The speakers it plays on, by device (a speech output's, for /metrics).
    speakers: Mapping[str, Any] = NO_SPEAKERS

    @abstractmethod
    def send(self, output: Any, value: Any, record: Record) -> None: ...

    @abstractmethod
    def close(self) -> None: ...


def no_rules(settings: Any) -> None:
    """A component whose settings need no check beyond their schema."""


def names_no_channel(settings: Any) -> str | None:
    """A component that reads or writes no text channel of the pipeline's `channels:`."""
    return None


@dataclass(frozen=True)
class SinkKind:
    """An output: `{key: ..., from: field}` in a route's `outputs:` list."""

    key: str
    # Its keys in an output, its own key among them, each optional (None when not given):
    # the output schema takes the fields of every sink's options.
    options: type[Schema]
    open: Callable[[ComponentContext], Sink] | None  # None: the pipeline keeps it (products)
    check: Callable[[Any], None] = no_rules          # rules on the whole output, if its key
    ros: bool = False                                # sent through the ROS node (a topic)
    channel: Callable[[Any], str | None] = names_no_channel  # the text channel it writes
    rank: int = 100


class Source(Protocol):
    """A route's input that runs on a thread of its own (not a ROS topic)."""

    route: str

    def start(self) -> None: ...

    def stop(self, timeout: float = 5.0) -> None: ...


Loader = Callable[[], Record]
Submit = Callable[[Loader], None]   # hands a route an item, as a loader that builds its record
OnEnd = Callable[[str], None]       # told the route's name when its source ended for good
# (route name, its input, submit, on_end, the pipeline's context) -> the source, not started
OpenSource = Callable[[str, Any, Submit, OnEnd, ComponentContext], Source]


def nothing_stray(input_config: Any) -> str | None:
    return None


@dataclass(frozen=True)
class SourceKind:
    """A route's input: `{key: ..., other keys of its own}` as a route's `input:`."""

    key: str
    # Its keys in an input, its own key among them, each optional (None when not given):
    # the input schema takes the fields of every source's options.
    options: type[Schema]
    field: Callable[[Any], str]                   # input -> the record field its items fill
    open: OpenSource | None     # None: fed by the ROS node or a replay (topic), or the pipeline
    check: Callable[[Any], None] = no_rules       # rules on the whole input, if its key
    stray: Callable[[Any], str | None] = nothing_stray  # its options on another's input
    latest: Callable[[Any], bool] = lambda input_config: False  # newest only by default
    # The record fields its items carry beside `field` (a camera topic's message header).
    more_fields: Callable[[Any], frozenset[str]] = lambda input_config: frozenset()
    ros: bool = False                             # read through the ROS node (a topic)
    channel: Callable[[Any], str | None] = names_no_channel  # the text channel it reads
    acts: bool = False      # sends its route's answers on its own (a control loop's actions)
    # The rate it ticks at (a control loop), for an endpoint's latency budget in steps.
    rate_hz: Callable[[Any], float | None] = lambda input_config: None
    rank: int = 100


Result: TypeAlias = Any  # a method's result dataclass


class Skip(Exception):
    """Nothing to pass on for this message (e.g. silence transcribed to nothing)."""


@dataclass(frozen=True)
class Partial:
    """A piece of a result handed on before the call ends (a sentence of an answer still
    being generated, the audio of one sentence): its fields go at once to the outputs that
    take them. A method whose call streams returns an iterator of Partials ending with its
    result, in which those fields are None (so they are not sent twice)."""

    fields: dict[str, Any]


# A streaming call's Partials, ending with its result: a generator, which the route closes
# when it stops reading early (a barge-in, an error), so the call's stream ends too.
Stream: TypeAlias = Generator[Partial | Result, None, None]


class CallBase(Schema):
    """The keys every call has: the endpoint it goes to."""

    service: str = Field(description="an endpoint name")


CallT = TypeVar("CallT", bound=CallBase)


class MethodCall(ABC, Generic[CallT]):
    """A method bound to one route, with the lifecycle of Triton's python_backend model
    (initialize / execute / finalize) and KServe's Model (load / predict): built once per
    route from its validated call settings, the endpoint it calls and the pipeline's data
    products; `execute` (also what calling it does) turns one record into a result; `close`
    lets go of what it holds (shared memory registered with a server), before the endpoint
    closes. Routes and the operations view call it from several threads at once, so what
    it keeps between calls is made safe for that.

    `result` is its typed result (a dataclass whose fields the record gains); a method whose
    call settings choose the result overrides `result_type`."""

    result: ClassVar[type]

    def __init__(self, call: CallT, endpoint: Endpoint, products: ProductStore) -> None:
        self.call = call
        self.endpoint = endpoint
        self.products = products

    @classmethod
    def result_type(cls, call: Any) -> type:
        """The result dataclass of a call with these settings."""
        return cls.result

    @abstractmethod
    def execute(self, record: Record) -> Result | Stream:
        """One record -> its result, or (a streaming call) Partials ending with it."""

    def __call__(self, record: Record) -> Result | Stream:
        return self.execute(record)

    def close(self) -> None:
        """Lets go of what the call holds; most hold nothing."""


@dataclass(frozen=True)
class Method:
    """A method a route calls: `call: {method: NAME, service: ENDPOINT, ...}`. Its call
    schema is a CallBase subclass whose `method` literal is its name; `calls` is its
    MethodCall class, which each route builds once and runs every record through; its typed
    result is a dataclass whose fields the route's record gains (checked against post steps
    and outputs when the pipeline loads)."""

    name: str
    config: type[CallBase]                     # the schema of the route's `call:`
    service: str                               # the gRPC service the endpoint must serve
    stub: Callable[[grpc.Channel], Any]
    ready: Ready                               # the probe used to come back from a fallback
    calls: type[MethodCall[Any]]               # (call config, endpoint, products) -> the call
    image_transport: bool = False              # sends camera frames (endpoint.image applies)
    # What the control API and barge-in find a route by, so they name no method.
    answers: bool = False                      # answers a question in text (ask)
    hears: bool = False                        # turns speech into text (transcribe)
    speaks: bool = False                       # turns text into speech (say, barge-in)
    takes_tensors: bool = False                # tensors straight to its model (infer)
    # The protocols its calls can go in (an endpoint's targets must speak one of them).
    protocols: frozenset[str] = frozenset({"grpc"})
    # The record fields the call's templates name, by the key that holds the template.
    reads: Callable[[Any], dict[str, set[str]]] = lambda call: {}
    # The data products the call reads as context, by the key that names them.
    products: Callable[[Any], dict[str, list[str]]] = lambda call: {}
    # The most bytes one answer may take, from the route's input (None: the channel's own
    # limit): the endpoint's gRPC channel refuses a larger answer before reading it.
    reply_bytes: Callable[[Any], int | None] = lambda input_config: None
    rank: int = 100                            # where it is listed (schema, messages, docs)

    @property
    def key(self) -> str:
        """Its name, as a route's `call.method` gives it."""
        return self.name

    def result(self, call: Any) -> type:
        """The result dataclass of a call with these settings."""
        return self.calls.result_type(call)

    def fields(self, call: Any) -> tuple[str, ...]:
        """The record fields a call of this method adds."""
        return tuple(f.name for f in dataclasses.fields(self.result(call)))

    def open(self, call: Any, endpoint: Endpoint, products: ProductStore) -> MethodCall[Any]:
        """The method bound to a route: its call settings, the endpoint, the data products."""
        return self.calls(call, endpoint, products)


def result_fields(result: Result) -> Record:
    """A result's fields as record entries (shallow: the values themselves, not copies)."""
    return {f.name: getattr(result, f.name) for f in dataclasses.fields(result)}


class Declared(Protocol):
    @property
    def key(self) -> str: ...

    @property
    def rank(self) -> int: ...


K = TypeVar("K", bound=Declared)


class Registry(Mapping[str, K], Generic[K]):
    """The components of one kind by key, in rank order, loaded on first use: the modules
    that `package`'s COMPONENTS tuple names, each defining `attr` at module level."""

    def __init__(self, package: str, attr: str, kind: type[Any]) -> None:
        self.package = package
        self._attr = attr
        self._kind = kind
        self._found: dict[str, K] | None = None
        self._lock = threading.RLock()

    def _components(self) -> dict[str, K]:
        with self._lock:
            if self._found is None:
                self._found = self._load()
            return self._found

    def modules(self) -> tuple[str, ...]:
        """The component modules the package lists (full names), without importing them."""
        names = vars(importlib.import_module(self.package)).get("COMPONENTS")
        if not isinstance(names, tuple) or not all(isinstance(n, str) for n in names):
            raise ComponentError(f"{self.package}.COMPONENTS: give a tuple of module names")
        return tuple(f"{self.package}.{name}" for name in names)

    def _load(self) -> dict[str, K]:
        found: dict[str, tuple[K, str]] = {}
        for name in self.modules():
            declared = self._declaration(name)
            if declared.key in found:
                raise ComponentError(f"'{declared.key}' is declared by both "
                                     f"{found[declared.key][1]} and {name}")
            found[declared.key] = (declared, name)
        ordered = sorted(found.values(), key=lambda item: (item[0].rank, item[0].key))
        return {declared.key: declared for declared, _ in ordered}

    def _declaration(self, name: str) -> K:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise  # the module is there; something it imports is not
            raise ComponentError(f"{self.package}.COMPONENTS names {name}, which does "
                                 f"not exist") from None
        declared = getattr(module, self._attr, None)
        if declared is None:
            raise ComponentError(f"{self.package}.COMPONENTS names {name}, which declares "
                                 f"no {self._attr}")
        if not isinstance(declared, self._kind):
            raise ComponentError(f"{name}.{self._attr} is no {self._kind.__name__}")
        return declared

    def __getitem__(self, key: str) -> K:
        return self._components()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._components())

    def __len__(self) -> int:
        return len(self._components())


STEPS: Registry[StepKind] = Registry("oricf.gateway.post", "COMPONENT", StepKind)
SINKS: Registry[SinkKind] = Registry("oricf.gateway.sinks", "COMPONENT", SinkKind)
SOURCES: Registry[SourceKind] = Registry("oricf.gateway.sources", "COMPONENT", SourceKind)
METHODS: Registry[Method] = Registry("oricf.gateway.methods", "METHOD", Method)
