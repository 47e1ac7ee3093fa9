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

from collections.abc import Iterable, Iterator, Mapping
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from oricf.audio import VadSettings
from oricf.config import (
    FilePath,
    Schema,
    check_address,
    read_with_overlays,
    resolve_path,
    validate,
)
from oricf.errors import ConfigError
from oricf.gateway.methods import METHODS
from oricf.gateway.replicas import check_target, several_addresses
from oricf.metrics import MetricsConfig
from oricf.models.declaration import ModelDeclaration, load_declaration
from oricf.tls import ClientTls, ServerTls, TokenSource

InputType = Literal["sensor_msgs/Image", "sensor_msgs/CompressedImage", "std_msgs/String",
                    "std_msgs/Int16MultiArray", "std_msgs/Int32"]
OutputType = Literal["std_msgs/Int32", "std_msgs/String", "sensor_msgs/Image"]
# The record field each input type fills (checked against `from`, templates).
INPUT_FIELDS: dict[str, str] = {
    "sensor_msgs/Image": "image", "sensor_msgs/CompressedImage": "image",
    "std_msgs/String": "text", "std_msgs/Int16MultiArray": "audio", "std_msgs/Int32": "value",
}
# Camera inputs: newest frame only, sensor_data QoS.
IMAGE_INPUTS = frozenset(t for t, f in INPUT_FIELDS.items() if f == "image")
# The keys of InputConfig that name a source; a route has exactly one.
SOURCE_KEYS = ("topic", "product", "url", "audio", "text")
# The keys of OutputConfig that name a sink; an output has exactly one.
SINK_KEYS = ("topic", "product", "jsonl", "text", "frames")


class ImageTransport(Schema):
    transport: Literal["raw", "jpeg"] = Field(
        "raw", description="raw pixels (onboard: no encode cost) or jpeg (remote: less bandwidth)")
    jpeg_quality: int = Field(80, ge=1, le=100)


class RetryConfig(Schema):
    """Retries of a call the service refused as busy (RESOURCE_EXHAUSTED), within its
    deadline: wait the service's pushback, or exponential backoff with jitter if longer."""

    attempts: int = Field(2, ge=0, le=10, description="retries after the first refusal")
    initial_backoff_ms: int = Field(50, ge=1, le=60_000)
    max_backoff_ms: int = Field(1000, ge=1, le=600_000)


class EndpointConfig(Schema):
    address: str = Field(description="host:port, or replicas to balance over: "
                                     "dns:///NAME:PORT, ipv4:IP:PORT,IP:PORT,... "
                                     "(gateway/replicas.py)")
    fallback: str | None = Field(None, description="used while the primary is unavailable")
    deadline_ms: int = Field(1000, gt=0, le=600_000, description="per call")
    probe_interval_s: float = Field(
        1.0, gt=0, le=60, description="health probe of the primary while on the fallback")
    image: ImageTransport = ImageTransport()
    retry: RetryConfig = RetryConfig()
    tls: ClientTls | None = Field(None, description="TLS to the service (mTLS with cert/key)")
    token: TokenSource | None = Field(None, description="bearer token sent with every call")

    @field_validator("address", "fallback")
    @classmethod
    def _target(cls, value: str | None) -> str | None:
        return None if value is None else check_target(value)

    @model_validator(mode="after")
    def _tls_name(self) -> EndpointConfig:
        listed = [t for t in (self.address, self.fallback) if t and several_addresses(t)]
        if self.tls is not None and self.tls.server_name is None and listed:
            raise ValueError(f"tls.server_name is needed with several addresses in one "
                             f"target ({listed[0]}): the name the replicas' certificate has")
        return self


class VadConfig(VadSettings):
    """How an audio input is cut into utterances: the same settings as the ASR service's
    `endpointing:`."""


class InputConfig(Schema):
    """Where a route's items come from: exactly one of topic, product, url, audio, text."""

    topic: str | None = None
    type: InputType | None = None
    product: str | None = Field(None, description="run on every new value of a data product")
    url: str | None = Field(
        None, description="a video: a file, rtsp://, http(s)://, or a device /dev/videoN")
    fps: float | None = Field(None, gt=0, le=240, description="url: at most this many frames/s")
    loop: bool = Field(False, description="url: a file starts again at its end (else the "
                                          "route ends)")
    audio: str | None = Field(
        None, description="utterances from an audio device ('default', a name or an index) "
                          "or a .wav file, cut by voice activity")
    text: str | None = Field(
        None, description="lines of text: '-' for standard input, or a channel's name")
    sample_rate: int = Field(16000, gt=0, le=384_000, description="audio: Hz")
    channels: int = Field(1, ge=1, le=32, description="audio: interleaved channels")
    vad: VadConfig | None = Field(None, description="audio: voice activity settings")
    keep: Literal["latest", "queue"] | None = Field(
        None, description="latest: newest only, older ones dropped (always for images); "
                          "queue: keep up to queue_size in order (default otherwise)")
    queue_size: int = Field(8, ge=1, le=1000)

    @field_validator("audio", mode="before")
    @classmethod
    def _wav_beside_yaml(cls, value: Any, info: Any) -> Any:
        """A .wav file resolves against the YAML file like every path; a device name stays."""
        if not isinstance(value, str) or not value.lower().endswith(".wav"):
            return value
        return str(resolve_path(value, info))

    @model_validator(mode="after")
    def _one_source(self) -> InputConfig:
        if sum(getattr(self, key) is not None for key in SOURCE_KEYS) != 1:
            raise ValueError(f"give exactly one of {', '.join(SOURCE_KEYS)}")
        if self.url is None and (self.fps is not None or self.loop):
            raise ValueError("fps, loop: only with url")
        if self.audio is None and self.vad is not None:
            raise ValueError("vad: only with audio")
        if self.topic is None and self.type is not None:
            raise ValueError("type: only with topic (the other inputs carry their own kind)")
        if self.topic is not None and self.type is None:
            raise ValueError("type: required with topic")
        if self.type in IMAGE_INPUTS and self.keep == "queue":
            raise ValueError("keep: camera inputs keep only the newest frame (latest)")
        return self

    @property
    def source(self) -> str:
        """The key that names this input's source: topic, product, url, audio or text."""
        return next(key for key in SOURCE_KEYS if getattr(self, key) is not None)

    @property
    def field(self) -> str:
        if self.topic is not None:
            return INPUT_FIELDS[str(self.type)]
        return {"url": "image", "audio": "audio", "text": "text"}.get(self.source, "value")

    @property
    def mode(self) -> Literal["latest", "queue"]:
        if self.keep is not None:
            return self.keep
        return "latest" if self.type in IMAGE_INPUTS or self.url is not None else "queue"


class ChannelConfig(Schema):
    """A line-based text channel on a TCP port: clients send questions as lines and receive
    the outputs written to the channel. TLS (mTLS with client_ca) and bearer tokens as for
    the services; with `auth`, a client's first line is `authorization: Bearer TOKEN`."""

    listen: str = Field(description="host:port; 127.0.0.1 keeps it on this machine")
    tls: ServerTls | None = None
    auth: TokenSource | None = None
    max_clients: int = Field(16, ge=1, le=1024)
    max_line_bytes: int = Field(4096, ge=16, le=1 << 20)

    @field_validator("listen")
    @classmethod
    def _host_port(cls, value: str) -> str:
        return check_address(value)


class ContextConfig(Schema):
    products: list[str] = Field(min_length=1)
    stale: Literal["omit", "mark"] = Field(
        "omit", description="a product older than its max_age_s: left out, or sent marked stale")


class DetectCall(Schema):
    """oricf.v1.Detector/Detect: an image -> detections, counts, annotated."""

    method: Literal["Detect"]
    service: str = Field(description="an endpoint name")
    labels: list[str] = Field(default_factory=list)
    min_score: float = Field(0.0, ge=0, le=1)
    annotate: bool = False


class TranscribeCall(Schema):
    """oricf.v1.SpeechRecognizer/Transcribe: audio -> transcript, duration_s."""

    method: Literal["Transcribe"]
    service: str = Field(description="an endpoint name")
    language: str = ""


class GenerateCall(Schema):
    """oricf.v1.LanguageModel/Generate: a prompt template with context -> answer."""

    method: Literal["Generate"]
    service: str = Field(description="an endpoint name")
    prompt: str = Field("{text}", description="template over the record's fields")
    max_tokens: int = Field(0, ge=0, le=4096)
    temperature: float | None = Field(None, ge=0, le=5)
    stop: list[str] = Field(default_factory=list)
    context: ContextConfig | None = None


class InferCall(Schema):
    """inference.GRPCInferenceService/ModelInfer on any Open Inference Protocol server: a
    declared model's pre-processing makes its input tensors, its post-processing turns the
    outputs into fields (detection: detections, counts; classification: classes, label,
    score)."""

    method: Literal["Infer"]
    service: str = Field(description="an endpoint name")
    model: FilePath = Field(description="the model's declaration (configs/models/*.yaml)")
    model_name: str | None = Field(
        None, description="its name on the server, if not the declaration's name")
    labels: list[str] = Field(default_factory=list, description="detection: keep only these")
    min_score: float | None = Field(None, gt=0, le=1,
                                    description="detection: default the declaration's")
    top_k: int | None = Field(None, ge=1, le=1000, description="classification")

    @cached_property
    def declaration(self) -> ModelDeclaration:
        return load_declaration(self.model)

    @model_validator(mode="after")
    def _usable_declaration(self) -> InferCall:
        try:
            task = self.declaration.task
        except ConfigError as exc:  # named here too, so the pipeline's file and key show
            raise ValueError(f"model: {exc}") from None
        if task is None:
            raise ValueError(f"model: {self.model} declares no task; the gateway needs one "
                             f"to turn its input into tensors and its outputs into fields")
        known = task.label_list()  # reads the labels file, so once
        unknown = sorted(set(self.labels) - set(known)) if known else []
        if unknown:
            raise ValueError(f"labels: the model has no label(s) {', '.join(unknown)}")
        if self.labels and task.kind != "detection":
            raise ValueError("labels: only for detection models")
        if self.top_k is not None and task.kind != "classification":
            raise ValueError("top_k: only for classification models")
        return self

    @property
    def server_model(self) -> str:
        return self.model_name or self.declaration.name


CallConfig = Annotated[DetectCall | TranscribeCall | GenerateCall | InferCall,
                       Field(discriminator="method")]


class CountStep(Schema):
    label: str | None = Field(None, description="count only this label (default: all)")
    into: str = "count"


class FilterStep(Schema):
    labels: list[str] = Field(default_factory=list)
    min_score: float = Field(0.0, ge=0, le=1)


class AnnotateStep(Schema):
    into: str = "annotated"


class TemplateStep(Schema):
    text: str
    into: str = "text"


class PostStep(Schema):
    """One post-processor: exactly one of the keys."""

    map_labels: dict[str, str] | None = None
    filter: FilterStep | None = None
    count: CountStep | None = None
    annotate: AnnotateStep | None = None
    template: TemplateStep | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> PostStep:
        if len(self.model_fields_set) != 1:
            raise ValueError("give exactly one of map_labels, filter, count, annotate, template")
        return self

    @property
    def kind(self) -> str:
        return next(iter(self.model_fields_set))

    @property
    def writes(self) -> str | None:
        step = getattr(self, self.kind)
        return getattr(step, "into", None)


class OutputConfig(Schema):
    topic: str | None = None
    type: OutputType | None = None
    product: str | None = None
    jsonl: str | None = Field(
        None, description="JSON lines: '-' for standard output, or a file (appended to)")
    text: str | None = Field(
        None, description="the value as a line of text: '-' for standard output, or a channel")
    frames: str | None = Field(
        None, description="images to a folder (numbered JPEGs), a .jpg/.png file (the newest "
                          "frame), or a video file (.mp4, .avi, .mkv)")
    max_age_s: float = Field(5.0, gt=0, description="product: older values count as stale")
    source: str = Field(alias="from", description="the record field to send")

    @model_validator(mode="after")
    def _one_sink(self) -> OutputConfig:
        if sum(getattr(self, key) is not None for key in SINK_KEYS) != 1:
            raise ValueError(f"give exactly one of {', '.join(SINK_KEYS)}")
        if self.topic is not None and self.type is None:
            raise ValueError("type: required with topic")
        return self


class RouteConfig(Schema):
    input: InputConfig
    call: CallConfig
    post: list[PostStep] = Field(default_factory=list)
    outputs: list[OutputConfig] = Field(min_length=1)


class PipelineConfig(Schema):
    node_name: str = Field("oricf_gateway", pattern=r"^[A-Za-z][A-Za-z0-9_]*$")
    stats_interval_s: float = Field(60.0, ge=0, description="log route statistics (0: never)")
    executor_threads: int = Field(
        1, ge=1, le=64, description="ROS executor threads; callbacks only hand off to the "
                                    "routes' worker threads, so 1 suffices")
    endpoints: dict[str, EndpointConfig] = Field(default_factory=dict)
    channels: dict[str, ChannelConfig] = Field(
        default_factory=dict, description="text channels that inputs and outputs name")
    routes: dict[str, RouteConfig] = Field(min_length=1)
    metrics: MetricsConfig | None = Field(
        None, description="serve Prometheus metrics at http://LISTEN/metrics (off if absent)")

    @property
    def uses_ros(self) -> bool:
        """Whether any route reads or writes a ROS topic (else the gateway runs without ROS)."""
        return any(r.input.topic is not None or any(o.topic for o in r.outputs)
                   for r in self.routes.values())

    def method_of(self, endpoint: str) -> str:
        """The method the routes call on an endpoint (one gRPC service per endpoint)."""
        for route in self.routes.values():
            if route.call.service == endpoint:
                return route.call.method
        return ""


def _route_problems(name: str, route: RouteConfig) -> Iterator[str]:
    """Outputs must name fields the route has (input, call and post-processor fields)."""
    fields = {route.input.field, *METHODS[route.call.method].fields(route.call)}
    for i, step in enumerate(route.post):
        if step.kind in ("map_labels", "filter", "count", "annotate") \
                and "detections" not in fields:
            yield (f"routes.{name}.post[{i}].{step.kind}: works on detections (method Detect, "
                   f"or Infer on a detection model)")
        if step.writes:
            fields.add(step.writes)
    for i, output in enumerate(route.outputs):
        if output.source not in fields:
            yield (f"routes.{name}.outputs[{i}].from: no field '{output.source}' in this route "
                   f"(fields: {', '.join(sorted(fields))})")


def _channel_problems(config: PipelineConfig) -> Iterator[str]:
    """Text inputs and outputs name a channel of `channels:` or '-' (standard in/out)."""
    for name, route in config.routes.items():
        texts = [("input.text", route.input.text)] + [
            (f"outputs[{i}].text", o.text) for i, o in enumerate(route.outputs)]
        for key, text in texts:
            if text not in (None, "-") and text not in config.channels:
                yield (f"routes.{name}.{key}: no channel '{text}' (channels: "
                       f"{', '.join(sorted(config.channels)) or 'none'}; or '-')")


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
        if service_of.setdefault(call.service, kind) != kind:
            yield (f"routes.{name}.call.service: endpoint '{call.service}' would serve both "
                   f"{service_of[call.service]} and {kind}")
        if route.input.product is not None and route.input.product not in produced:
            yield f"routes.{name}.input.product: no route outputs '{route.input.product}'"
        context = call.context if isinstance(call, GenerateCall) else None
        for i, product in enumerate(context.products if context else []):
            if product not in produced:
                yield f"routes.{name}.call.context.products[{i}]: no route outputs '{product}'"
        yield from _route_problems(name, route)


def parse_pipeline(data: Any, source: str, base_dir: Path | None = None) -> PipelineConfig:
    """Validates parsed YAML, then every cross-reference; errors name source and key."""
    if isinstance(data, Mapping) and "profiles" in data:
        raise ConfigError(f"{source}: profiles: removed; put placement in an overlay file "
                          f"(configs/pipelines/placement/) and pass it with --overlay")
    config = validate(data, PipelineConfig, source, base_dir)
    problems = [f"{source}: {problem}" for problem in
                (*_reference_problems(config), *_channel_problems(config))]
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
