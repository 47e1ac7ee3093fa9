"""The control operations, as one Protocol: a pipeline in this process (view.PipelineView)
and a running gateway over HTTP (client.ControlClient) implement it alike, so the MCP server
and the tests do not care which it is.

Values are JSON-able dicts; images travel as JPEG or PNG bytes, audio as WAV bytes. Errors:
InvalidInput (a caller's mistake: unknown product or route, bad image), NotReady (nothing to
show yet, a service down), Refused (the agent policy said no, with its reason).

Over HTTP each operation has one path, written once in PATHS: the control API's server
(oricf.gateway.api.server) serves them and the client calls them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Literal, Protocol

MAX_IMAGE_BYTES = 8 * 1024 * 1024
MAX_AUDIO_BYTES = 16 * 1024 * 1024
MAX_TEXT_CHARS = 4000

Json = dict[str, Any]


@dataclass(frozen=True)
class ApiPath:
    """An operation's HTTP method and path; `{name}` in a path is a parameter (Starlette's
    syntax, `{name:path}` taking one that may hold '/')."""

    http: Literal["GET", "POST"]
    path: str

    def url(self, **params: str) -> str:
        """The path with its parameters filled in (each already escaped by the caller)."""
        return re.sub(r"\{(\w+)(?::\w+)?\}", lambda m: params[m.group(1)], self.path)


# Operation (a method of Operations) -> its path. GET reads, POST runs a model or acts.
PATHS: dict[str, ApiPath] = {
    "products": ApiPath("GET", "/v1/products"),
    "read_product": ApiPath("GET", "/v1/products/{name:path}"),
    "look": ApiPath("GET", "/v1/look"),
    "status": ApiPath("GET", "/v1/status"),
    "policy": ApiPath("GET", "/v1/policy"),
    "detect": ApiPath("POST", "/v1/detect"),
    "infer": ApiPath("POST", "/v1/infer"),
    "ask": ApiPath("POST", "/v1/ask"),
    "transcribe": ApiPath("POST", "/v1/transcribe"),
    "say": ApiPath("POST", "/v1/say"),
    "check": ApiPath("POST", "/v1/check"),
    "publish": ApiPath("POST", "/v1/publish"),
}


class Operations(Protocol):
    def products(self) -> list[Json]:
        """Every data product: name, max_age_s, the route that writes it, written or not,
        and once written its value and age_s."""

    def read_product(self, name: str) -> Json:
        """value, age_s, stale, route."""

    def look(self, route: str | None = None) -> tuple[Json, bytes]:
        """The newest frame a camera route took, with what it found (detections, counts,
        track ids) and the frame as JPEG, boxes drawn."""

    def detect(self, image: bytes, route: str | None = None) -> Json:
        """A detection route's model on an image the caller passes (JPEG or PNG)."""

    def infer(self, route: str, image: bytes | None = None,
              tensors: dict[str, Any] | None = None) -> Json:
        """Any image route's model (Detect or Infer: detections or classes) on an image, or
        an Infer route's model on tensors ({name: {datatype, shape, data}})."""

    def ask(self, question: str) -> Json:
        """The pipeline's language model, with the route's context products as facts."""

    def transcribe(self, audio: bytes) -> Json:
        """Speech recognition on a WAV clip."""

    def say(self, text: str) -> Json:
        """Speech synthesis, where the pipeline has it."""

    def status(self) -> Json:
        """Endpoints (active address, fallback, failovers), routes (counts, latency), the
        agent's calls."""

    def policy(self) -> Json:
        """The agent policy's targets, as an agent is told them."""

    def check(self, target: str, message: Json) -> Json:
        """What `publish` would send (clamped), or Refused; sends nothing."""

    def publish(self, target: str, message: Json, approved: bool = False) -> Json:
        """A command within the agent policy, or Refused."""

    def close(self) -> None: ...
