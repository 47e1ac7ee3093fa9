"""One trace across the gateway and a service: a frame's route through a real detector over
a real gRPC channel, the spans kept by the SDK's in-memory exporter."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from opentelemetry.sdk.trace import ReadableSpan, TracerProvider
from opentelemetry.sdk.trace.export import SimpleSpanProcessor
from opentelemetry.sdk.trace.export.in_memory_span_exporter import InMemorySpanExporter
from opentelemetry.trace import SpanContext, SpanKind, StatusCode, get_current_span

from oricf import tracing
from oricf.audio import encode_wav, synthesize
from oricf.gateway.config import InputConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sources.audio_source import AudioSource
from oricf.gateway.values import Frame
from oricf.tracing import traced_with
from oricf.v1 import detector_pb2, detector_pb2_grpc
from tests.gateway.test_pipeline import Outputs, pipeline_config
from tests.support.data import video_frames
from tests.support.services import RunningService, running_service
from tests.support.speech import QUESTION
from tests.support.waiting import wait_for

ROUTE_SPANS = {"route people", "receive", "call Detect", "post", "publish"}
SERVICE_SPANS = {"oricf.v1.Detector/Detect", "decode", "preprocess", "inference",
                 "postprocess"}


@pytest.fixture(scope="module")
def spans() -> Iterator[InMemorySpanExporter]:
    """Tracing on for this module's tests, into memory."""
    exporter = InMemorySpanExporter()
    provider = TracerProvider()
    provider.add_span_processor(SimpleSpanProcessor(exporter))
    with traced_with(provider):
        yield exporter
    provider.shutdown()


@pytest.fixture(scope="module")
def traced_detector(spans: InMemorySpanExporter) -> Iterator[RunningService]:
    """A detector started while tracing is on: it has the tracing interceptor."""
    with running_service("detector") as detector:
        yield detector


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
        spans: InMemorySpanExporter, traced_detector: RunningService) -> None:
    spans.clear()
    traced_frame(traced_detector.address)
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
        parent = found[step].parent
        assert parent is not None and parent.span_id == served.context.span_id
    assert served.attributes is not None and served.attributes["rpc.grpc.status_code"] == 0


def test_a_failed_call_marks_both_sides(spans: InMemorySpanExporter,
                                        traced_detector: RunningService) -> None:
    """A frame the detector refuses (a label it does not know): INVALID_ARGUMENT on the
    service's span and the route's."""
    spans.clear()
    traced_frame(traced_detector.address,
                 {"routes": {"people": {"call": {"labels": ["unicorn"]}}}})
    found = by_name(spans.get_finished_spans())
    served, route = found["oricf.v1.Detector/Detect"], found["route people"]
    assert served.status.status_code == StatusCode.ERROR
    assert served.status.description == "INVALID_ARGUMENT"
    assert route.status.status_code == StatusCode.ERROR
    assert served.context.trace_id == route.context.trace_id


def test_a_streamed_call_is_one_span_with_its_frames_decoding_as_children(
        spans: InMemorySpanExporter, traced_detector: RunningService) -> None:
    spans.clear()
    frame = Frame.from_pixels(video_frames([0])[0])
    request = detector_pb2.DetectRequest(image=frame.to_proto())
    stub = detector_pb2_grpc.DetectorStub(traced_detector.channel)
    with tracing.tracer().start_as_current_span("caller") as caller:
        replies = list(stub.DetectStream(iter([request, request]), timeout=30,
                                         metadata=tracing.inject(())))
    assert len(replies) == 2
    finished = spans.get_finished_spans()
    served = next(s for s in finished if s.name == "oricf.v1.Detector/DetectStream")
    assert served.parent is not None and served.parent.span_id == caller.get_span_context().span_id
    decodes = [s for s in finished if s.name == "decode"]
    assert len(decodes) == 2  # in the stream's reader thread, still the call's children
    assert all(d.parent is not None and d.parent.span_id == served.context.span_id
               for d in decodes)


def test_no_spans_and_no_trace_context_while_tracing_is_off() -> None:
    """Off (the default): the no-op tracer, and calls carry no `traceparent`."""
    with traced_with(None):
        assert not tracing.active()
        assert tracing.inject((("authorization", "Bearer x"),)) == (
            ("authorization", "Bearer x"),)


def test_a_route_fed_by_a_product_joins_the_trace_of_the_route_that_put_it(
        spans: InMemorySpanExporter, traced_detector: RunningService, tts: RunningService,
        tmp_path: Path) -> None:
    """people puts a sentence as a product; say speaks it (a streamed call, to the session's
    speech service): one trace, say's route the child of people's publish step, the first
    audio an event on its call."""
    spans.clear()
    config = pipeline_config(traced_detector.address, {
        "endpoints": {"tts": {"address": tts.address}},
        "routes": {"say": {"input": {"product": "summary"},
                           "call": {"service": "tts", "method": "Synthesize"},
                           "outputs": [{"wav": str(tmp_path / "said.wav"),
                                        "from": "speech"}]},
                   "people": {"outputs": [{"product": "summary", "from": "summary"}]}}})
    pipeline = Pipeline(config, Outputs())
    pipeline.start()
    try:
        frame = Frame.from_pixels(video_frames([0])[0])
        pipeline.submit("people", lambda: {"image": frame})
        wait_for(lambda: pipeline.routes["say"].stats.ok == 1 and pipeline.idle(0.1), 30,
                 "the summary spoken")
    finally:
        pipeline.stop()
    finished = spans.get_finished_spans()
    people = next(s for s in finished if s.name == "route people")
    say = next(s for s in finished if s.name == "route say")
    publish = next(s for s in finished if s.name == "publish"
                   and s.parent is not None and s.parent.span_id == people.context.span_id)
    assert say.context.trace_id == people.context.trace_id
    assert say.parent is not None and say.parent.span_id == publish.context.span_id
    call = next(s for s in finished if s.name == "call Synthesize")
    assert call.context.trace_id == people.context.trace_id
    assert [event.name for event in call.events] == ["first piece"]


def test_each_utterance_cut_from_audio_is_the_root_of_its_question(
        spans: InMemorySpanExporter, tmp_path: Path) -> None:
    """A spoken question in a WAV file: the audio source hands the utterance to its route
    inside an `utterance cut` span, which the route's span then takes as its parent."""
    spans.clear()
    silence = np.zeros(4000, dtype=np.int16)
    path = tmp_path / "question.wav"
    path.write_bytes(encode_wav(np.concatenate([silence, synthesize(QUESTION), silence]),
                                16000))
    submitted: list[SpanContext] = []
    ended = threading.Event()
    source = AudioSource("speech", InputConfig(audio=str(path)),
                         lambda load: submitted.append(get_current_span().get_span_context()),
                         lambda route: ended.set())
    source.start()
    assert ended.wait(60)
    cuts = [s for s in spans.get_finished_spans() if s.name == "utterance cut"]
    assert len(cuts) == len(submitted) == 1
    assert cuts[0].context.span_id == submitted[0].span_id and cuts[0].parent is None
    assert cuts[0].attributes is not None
    assert float(cuts[0].attributes["oricf.audio_s"]) > 0.5  # type: ignore[arg-type]
