"""The pipeline YAML (configs/pipelines/*.yaml): endpoints, routes, data products.

    endpoints:            # one per model service the routes call
      detector:
        address: 127.0.0.1:50051
        fallback: 10.0.0.2:50051     # optional: used while the primary is down
        deadline_ms: 500
        image: {transport: raw}      # raw | jpeg (+ jpeg_quality) for remote endpoints
    routes:               # input -> call -> post-processors -> outputs
      people:
        input: {topic: camera/image_raw, type: sensor_msgs/Image}
        call: {service: detector, method: Detect, labels: [person], min_score: 0.35}
        post: [{count: {label: person, into: count}}]
        outputs:
          - {topic: /human_counter, type: std_msgs/Int32, from: count}
          - {product: people_count, from: count, max_age_s: 5}

Placement (onboard or edge) is said in one place: an overlay file merged on top (`--overlay
configs/pipelines/placement/edge.yaml`) that sets the endpoints' addresses, fallbacks,
deadlines, image transport and TLS; no code changes. Every cross-reference (an endpoint, a
data product, a record field) is checked at load time.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Optional, Union

from pydantic import Field, PrivateAttr, create_model, model_validator

from oricf.config import Schema, read_with_overlays, validate
from oricf.errors import ConfigError
from oricf.gateway.actuation.policy import AgentPolicy
from oricf.gateway.channels.server import ChannelConfig
from oricf.gateway.components import METHODS, SINKS, SOURCES, STEPS, CallBase, Method, Step
from oricf.gateway.endpoints import EndpointConfig
from oricf.gateway.listeners import ControlConfig, LiveViewConfig
from oricf.metrics import MetricsConfig
from oricf.tracing import TracingConfig


class ComponentKeys(Schema):
    """A schema whose keys are the registered components' own, added by create_model once
    the registry has found them: a type checker cannot know them, so any key reads as Any."""

    if TYPE_CHECKING:
        def __init__(self, **keys: Any) -> None: ...

        def __getattr__(self, key: str) -> Any: ...


def with_options(name: str, base: type[Schema], kinds: Iterable[Any]) -> Any:
    """`base` with every registered kind's options (their keys, each optional) as one flat
    schema, keeping the error paths users' files were always told."""
    return create_model(name, __base__=(base, *(kind.options for kind in kinds)),
                        __module__=__name__)


class InputBase(ComponentKeys):
    """Where a route's items come from: exactly one of the registered sources' keys
    (oricf.gateway.sources), with that source's other keys, and how items wait."""

    keep: Literal["latest", "queue"] | None = Field(
        None, description="latest: newest only, older ones dropped (always for images); "
                          "queue: keep up to queue_size in order (default otherwise)")
    queue_size: int = Field(8, ge=1, le=1000)

    @model_validator(mode="after")
    def _one_source(self) -> InputBase:
        if sum(getattr(self, key) is not None for key in SOURCES) != 1:
            raise ValueError(f"give exactly one of {', '.join(SOURCES)}")
        for key, kind in SOURCES.items():
            stray = None if key == self.source else kind.stray(self)
            if stray is not None:
                raise ValueError(stray)
        SOURCES[self.source].check(self)
        return self

    @property
    def source(self) -> str:
        """The key that names this input's source (topic, product, url, audio, text...)."""
        return next(key for key in SOURCES if getattr(self, key) is not None)

    @property
    def field(self) -> str:
        """The record field this input's items fill."""
        return SOURCES[self.source].field(self)

    @property
    def mode(self) -> Literal["latest", "queue"]:
        if self.keep is not None:
            return self.keep
        return "latest" if SOURCES[self.source].latest(self) else "queue"



if TYPE_CHECKING:
    InputConfig = InputBase
else:
    InputConfig = with_options("InputConfig", InputBase, SOURCES.values())


class OutputBase(ComponentKeys):
    """A route output: exactly one of the registered sinks' keys (oricf.gateway.sinks), and
    the record field it sends."""

    source: str = Field(alias="from", description="the record field to send")

    @model_validator(mode="after")
    def _one_sink(self) -> OutputBase:
        if sum(getattr(self, key) is not None for key in SINKS) != 1:
            raise ValueError(f"give exactly one of {', '.join(SINKS)}")
        SINKS[self.sink].check(self)
        return self

    @property
    def sink(self) -> str:
        """The key that names this output's sink."""
        return next(key for key in SINKS if getattr(self, key) is not None)



if TYPE_CHECKING:
    OutputConfig = OutputBase
else:
    OutputConfig = with_options("OutputConfig", OutputBase, SINKS.values())


class PostStepBase(ComponentKeys):
    """One post step: exactly one of the registered steps' keys (oricf.gateway.post)."""

    @model_validator(mode="after")
    def _exactly_one(self) -> PostStepBase:
        if len(self.model_fields_set) != 1:
            raise ValueError(f"give exactly one of {', '.join(STEPS)}")
        return self

    @property
    def kind(self) -> str:
        return next(iter(self.model_fields_set))

    def build(self) -> Step:
        return STEPS[self.kind].build(getattr(self, self.kind))



if TYPE_CHECKING:
    PostStep = PostStepBase
else:
    PostStep = create_model(
        "PostStep", __base__=PostStepBase, __module__=__name__,
        **{key: (Optional[kind.settings], None) for key, kind in STEPS.items()})  # noqa: UP045


def call_schema(methods: Iterable[Method]) -> Any:
    """A route's `call:` over these methods: its `method` key picks the schema, so a key of
    another method is refused, and an error's path names the method
    (`routes.x.call.Detect.max_tokens`)."""
    return Annotated[Union[tuple(method.config for method in methods)],  # noqa: UP007
                     Field(discriminator="method")]


if TYPE_CHECKING:  # the registered methods' call schemas, known once they are found
    class CallConfig(CallBase):
        method: str

        def __getattr__(self, key: str) -> Any: ...
else:
    CallConfig = call_schema(METHODS.values())


class RouteConfig(Schema):
    input: InputConfig
    call: CallConfig
    post: list[PostStep] = Field(default_factory=list)
    outputs: list[OutputConfig] = Field(default_factory=list)

    @model_validator(mode="after")
    def _has_outputs(self) -> RouteConfig:
        if not self.outputs and not SOURCES[self.input.source].acts:
            raise ValueError("outputs: at least one (only a control input acts on its own)")
        return self


class PipelineConfig(Schema):
    node_name: str = Field("oricf_gateway", pattern=r"^[A-Za-z][A-Za-z0-9_]*$")
    stats_interval_s: float = Field(60.0, ge=0, description="log route statistics (0: never)")
    executor_threads: int = Field(
        1, ge=1, le=64, description="ROS executor threads; callbacks only hand off to the "
                                    "routes' worker threads, so 1 suffices")
    executor: Literal["python", "events"] = Field(
        "python", description="python: rclpy's executors, written in Python; events: rclpy's "
        "EventsExecutor (C++, one thread; experimental in rclpy), which takes a fraction of "
        "the CPU per message: for a control loop ticked by its state at tens of Hz")
    endpoints: dict[str, EndpointConfig] = Field(default_factory=dict)
    channels: dict[str, ChannelConfig] = Field(
        default_factory=dict, description="text channels that inputs and outputs name")
    routes: dict[str, RouteConfig] = Field(min_length=1)
    metrics: MetricsConfig | None = Field(
        None, description="serve Prometheus metrics at http://LISTEN/metrics (off if absent)")
    control: ControlConfig | None = Field(
        None, description="the local control API (`oricf mcp --attach`; off if absent)")
    agent: AgentPolicy | None = Field(
        None, description="what an agent may send, where, how fast (none if absent)")
    foxglove: LiveViewConfig | None = Field(
        None, description="serve the live view over the Foxglove WebSocket protocol (off if "
                          "absent; docs/live-view.md)")
    tracing: TracingConfig | None = Field(
        None, description="OpenTelemetry traces over OTLP (docs/tracing.md; also on when "
                          "OTEL_EXPORTER_OTLP_ENDPOINT is set)")

    _origin: str = PrivateAttr("pipeline")  # the files it was read from, for errors

    @model_validator(mode="after")
    def _one_events_thread(self) -> PipelineConfig:
        if self.executor == "events" and self.executor_threads != 1:
            raise ValueError(f"executor_threads: {self.executor_threads}, but the events "
                             f"executor runs on one thread")
        return self

    @property
    def origin(self) -> str:
        """The file (and overlays) the pipeline was read from, as errors name it."""
        return self._origin

    @property
    def uses_ros(self) -> bool:
        """Whether any route reads or writes a ROS topic, or a placement reads the battery
        from one (else the gateway runs without ROS)."""
        return any(SOURCES[r.input.source].ros or any(SINKS[o.sink].ros for o in r.outputs)
                   for r in self.routes.values()) or any(
            e.placement is not None and e.placement.battery_topic is not None
            for e in self.endpoints.values())

    def step_of(self, endpoint: str) -> float | None:
        """The control period (s) of the route that calls an endpoint at a rate, if one."""
        for route in self.routes.values():
            rate = SOURCES[route.input.source].rate_hz(route.input)
            if route.call.service == endpoint and rate is not None:
                return 1.0 / rate
        return None

    def reply_bytes_of(self, endpoint: str) -> int | None:
        """The most bytes one answer of an endpoint may take: the largest its routes'
        methods take, None when one of them does not bound it."""
        sizes = [METHODS[route.call.method].reply_bytes(route.input)
                 for route in self.routes.values() if route.call.service == endpoint]
        bounded = [size for size in sizes if size is not None]
        return max(bounded) if bounded and len(bounded) == len(sizes) else None

    def method_of(self, endpoint: str) -> str:
        """The method the routes call on an endpoint (one gRPC service per endpoint)."""
        for route in self.routes.values():
            if route.call.service == endpoint:
                return route.call.method
        return ""


def route_fields(name: str, route: RouteConfig) -> Iterator[str]:
    """Problems with the fields a route's templates, post steps and outputs name: each must
    be one the route has by then (its input's, its method's result's, or an earlier step's)."""
    call = route.call
    method = METHODS[call.method]
    source = SOURCES[route.input.source]
    fields = {"route", route.input.field, *source.more_fields(route.input), *method.fields(call)}
    yield from _missing(f"routes.{name}.call", method.reads(call), fields)
    for i, post in enumerate(route.post):
        step = post.build()
        yield from _missing(f"routes.{name}.post[{i}]", {post.kind: set(step.reads)}, fields)
        if step.writes:
            fields.add(step.writes)
    for i, output in enumerate(route.outputs):
        if output.source not in fields:
            yield (f"routes.{name}.outputs[{i}].from: no field '{output.source}' in this route "
                   f"(fields: {', '.join(sorted(fields))})")


def _missing(where: str, reads: dict[str, set[str]], fields: set[str]) -> Iterator[str]:
    for key, names in reads.items():
        for missing in sorted(names - fields):
            yield (f"{where}.{key}: no field '{missing}' in this route at this point "
                   f"(fields: {', '.join(sorted(fields))})")


def _channel_problems(config: PipelineConfig) -> Iterator[str]:
    """Inputs and outputs name a text channel of `channels:` or '-' (standard in/out)."""
    for name, route in config.routes.items():
        source = SOURCES[route.input.source]
        texts = [(f"input.{source.key}", source.channel(route.input))] + [
            (f"outputs[{i}].{o.sink}", SINKS[o.sink].channel(o))
            for i, o in enumerate(route.outputs)]
        for key, text in texts:
            if text not in (None, "-") and text not in config.channels:
                yield (f"routes.{name}.{key}: no channel '{text}' (channels: "
                       f"{', '.join(sorted(config.channels)) or 'none'}; or '-')")
    for name, target in (config.agent.targets.items() if config.agent else ()):
        for key in ("channel", "approval_channel"):
            channel = getattr(target, key)
            if channel is not None and channel not in config.channels:
                yield (f"agent.targets.{name}.{key}: no channel '{channel}' (channels: "
                       f"{', '.join(sorted(config.channels)) or 'none'})")


def _reference_problems(config: PipelineConfig) -> Iterator[str]:
    """Endpoints, data products and fields that routes name must exist."""
    produced = {o.product for r in config.routes.values() for o in r.outputs if o.product}
    topic_types: dict[str, str] = {}
    for name, route in config.routes.items():
        for i, output in enumerate(route.outputs):
            if output.topic and topic_types.setdefault(output.topic, str(output.type)) \
                    != output.type:
                yield (f"routes.{name}.outputs[{i}].type: {output.topic} is already "
                       f"{topic_types[output.topic]} in another output")
    service_of: dict[str, str] = {}
    for name, route in config.routes.items():
        call = route.call
        if call.service not in config.endpoints:
            yield (f"routes.{name}.call.service: no endpoint '{call.service}' "
                   f"(endpoints: {', '.join(sorted(config.endpoints)) or 'none'})")
        kind = METHODS[call.method].service
        yield from _protocol_problems(name, call.method, config.endpoints.get(call.service))
        if service_of.setdefault(call.service, kind) != kind:
            yield (f"routes.{name}.call.service: endpoint '{call.service}' would serve both "
                   f"{service_of[call.service]} and {kind}")
        if route.input.product is not None and route.input.product not in produced:
            yield f"routes.{name}.input.product: no route outputs '{route.input.product}'"
        for key, products in METHODS[call.method].products(call).items():
            for i, product in enumerate(products):
                if product not in produced:
                    yield f"routes.{name}.call.{key}[{i}]: no route outputs '{product}'"
        yield from route_fields(name, route)


def _budget_problems(config: PipelineConfig) -> Iterator[str]:
    """A latency budget in steps needs a control input calling the endpoint."""
    for name, endpoint in config.endpoints.items():
        placement = endpoint.placement
        if placement is not None and placement.latency_budget_steps is not None \
                and config.step_of(name) is None:
            yield (f"endpoints.{name}.placement.latency_budget_steps: no control input calls "
                   f"this endpoint (give latency_budget_ms)")


def _protocol_problems(route: str, method: str, endpoint: EndpointConfig | None
                       ) -> Iterator[str]:
    """The endpoint's servers must speak a protocol the method has calls in."""
    if endpoint is None:
        return
    spoken = METHODS[method].protocols
    for slot, target in endpoint.targets.items():
        if target.protocol not in spoken:
            yield (f"routes.{route}.call.service: the endpoint's {slot} speaks "
                   f"{target.protocol}, which {method} does not (it speaks "
                   f"{', '.join(sorted(spoken))})")


def parse_pipeline(data: Any, source: str, base_dir: Path | None = None) -> PipelineConfig:
    """Validates parsed YAML, then every cross-reference; errors name source and key."""
    config = validate(data, PipelineConfig, source, base_dir)
    config._origin = source
    problems = [f"{source}: {problem}" for problem in
                (*_reference_problems(config), *_channel_problems(config),
                 *_budget_problems(config))]
    if problems:
        raise ConfigError("\n".join(problems))
    return config


def load_pipeline(path: Path | str, overlays: Iterable[Path | str] = (), *,
                  sets: Iterable[str] = ()) -> PipelineConfig:
    """The pipeline file, overlays merged on top in order, then `--set KEY=VALUE`
    assignments."""
    path = Path(path)
    data, sources = read_with_overlays(path, overlays, sets)
    return parse_pipeline(data, " + ".join(sources), path.parent)
