"""What every method provides, and the pieces methods share.

A method is one `Method` entry: its call schema (the route's `call:` keys, a pydantic class
whose `method` literal names it), the gRPC service an endpoint must serve for it and how to
ask whether a server is ready, the protocols it speaks (gRPC; some also the OpenAI-compatible
API), the typed result it returns (a dataclass: its fields are the fields the route's record
gains, checked against post steps and outputs when the pipeline loads), and `bind`, which
runs once per route and returns the function that turns one record into a result.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeAlias

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc
from pydantic import Field

from oricf.config import Schema
from oricf.errors import InvalidInput
from oricf.gateway.endpoints import Endpoint, Metadata, Ready
from oricf.gateway.products import ProductStore
from oricf.gateway.values import Frame, Record

Result: TypeAlias = Any  # a method's result dataclass
Invoke: TypeAlias = Callable[[Record], Result]
Binder: TypeAlias = Callable[[Any, Endpoint, ProductStore], Invoke]


class Skip(Exception):
    """Nothing to pass on for this message (e.g. silence transcribed to nothing)."""


@dataclass(frozen=True)
class Partial:
    """A piece of a result handed on before the call ends (a sentence of an answer still
    being generated, the audio of one sentence): its fields go at once to the outputs that
    take them. A method whose call streams returns an iterator of Partials ending with its
    result, in which those fields are None (so they are not sent twice)."""

    fields: dict[str, Any]


class CallBase(Schema):
    """The keys every call has: the endpoint it goes to."""

    service: str = Field(description="an endpoint name")


@dataclass(frozen=True)
class Method:
    name: str
    config: type[CallBase]                     # the schema of the route's `call:`
    service: str                               # the gRPC service the endpoint must serve
    stub: Callable[[grpc.Channel], Any]
    ready: Ready                               # the probe used to come back from a fallback
    result: Callable[[Any], type]              # call config -> its result dataclass
    bind: Binder                               # (call config, endpoint, products) -> invoke
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

    def fields(self, call: Any) -> tuple[str, ...]:
        """The record fields a call of this method adds."""
        return tuple(f.name for f in dataclasses.fields(self.result(call)))


def result_fields(result: Result) -> Record:
    """A result's fields as record entries (shallow: the values themselves, not copies)."""
    return {f.name: getattr(result, f.name) for f in dataclasses.fields(result)}


def health_check(service: str) -> Ready:
    """Ready when grpc.health.v1 says the service is SERVING (ORICF's own services)."""
    def ready(channel: grpc.Channel, timeout: float, metadata: Metadata = ()) -> bool:
        reply = health_pb2_grpc.HealthStub(channel).Check(
            health_pb2.HealthCheckRequest(service=service), timeout=timeout,
            metadata=metadata)
        return bool(reply.status == health_pb2.HealthCheckResponse.SERVING)

    return ready


def input_frame(record: Record, method: str) -> Frame:
    frame = record.get("image")
    if not isinstance(frame, Frame):
        raise InvalidInput(f"{method} needs an image input")
    return frame
