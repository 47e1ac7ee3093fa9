"""One trace across the gateway and a service: a frame's route through a real detector over
a real gRPC channel, the spans kept by the SDK's in-memory exporter."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from opentelemetry.sdk.trace import ReadableSpan, TracerProvider
from opentelemetry.sdk.trace.export import SimpleSpanProcessor
from opentelemetry.sdk.trace.export.in_memory_span_exporter import InMemorySpanExporter
from opentelemetry.trace import SpanKind, StatusCode

from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from oricf.tracing import traced_with
from tests.gateway.test_pipeline import Outputs, pipeline_config
from tests.support.data import video_frames
from tests.support.services import running_service

ROUTE_SPANS = {"route people", "receive", "call Detect", "post", "publish"}
SERVICE_SPANS = {"oricf.v1.Detector/Detect", "decode", "preprocess", "inference",
                 "postprocess"}


@pytest.fixture()
def spans() -> Iterator[InMemorySpanExporter]:
    exporter = InMemorySpanExporter()
    provider = TracerProvider()
    provider.add_span_processor(SimpleSpanProcessor(exporter))
    with traced_with(provider):
        yield exporter
    provider.shutdown()


def traced_frame(address: str, change: dict[str, object] | None = None) -> None:
    pipeline = Pipeline(pipeline_config(address, change), Outputs())
    pipeline.start()
    try:
        frame = Frame.from_pixels(video_frames([0])[0])
        pipeline.submit("people", lambda: {"image": frame})
        assert pipeline.idle(10)
    finally:
        pipeline.stop()


def by_name(spans: tuple[ReadableSpan, ...]) -> dict[str, ReadableSpan]:
    return {span.name: span for span in spans}


def test_a_frame_is_one_trace_across_the_gateway_and_the_detector(
        spans: InMemorySpanExporter) -> None:
    spans.clear()
    with running_service("detector") as detector:
        traced_frame(detector.address)
    found = by_name(spans.get_finished_spans())
    assert found.keys() >= ROUTE_SPANS | SERVICE_SPANS
    route = found["route people"]
    assert route.parent is None
    assert {span.context.trace_id for span in found.values()} == {route.context.trace_id}
    # The service's span is the child of the gateway's call, through `traceparent`.
    call, served = found["call Detect"], found["oricf.v1.Detector/Detect"]
    assert served.kind == SpanKind.SERVER and served.parent is not None
    assert served.parent.span_id == call.context.span_id and served.parent.is_remote
    for step in ("decode", "preprocess", "inference", "postprocess"):
        assert found[step].parent is not None
        assert found[step].parent.span_id == served.context.span_id
    assert served.attributes is not None and served.attributes["rpc.grpc.status_code"] == 0


def test_a_failed_call_marks_both_sides(spans: InMemorySpanExporter) -> None:
    """A frame the detector refuses (a label it does not know): INVALID_ARGUMENT on the
    service's span and the route's."""
    spans.clear()
    with running_service("detector") as detector:
        traced_frame(detector.address, {"routes": {"people": {"call": {"labels": ["unicorn"]}}}})
    found = by_name(spans.get_finished_spans())
    served, route = found["oricf.v1.Detector/Detect"], found["route people"]
    assert served.status.status_code == StatusCode.ERROR
    assert served.status.description == "INVALID_ARGUMENT"
    assert route.status.status_code == StatusCode.ERROR
    assert served.context.trace_id == route.context.trace_id


def test_no_spans_and_no_trace_context_while_tracing_is_off() -> None:
    """Off (the default): the no-op tracer, and calls carry no `traceparent`."""
    from oricf import tracing

    assert not tracing.active()
    assert tracing.inject((("authorization", "Bearer x"),)) == (("authorization", "Bearer x"),)
