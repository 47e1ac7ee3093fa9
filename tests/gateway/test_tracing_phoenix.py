"""Traces in a real OpenTelemetry backend: Arize Phoenix, receiving OTLP over gRPC and HTTP.

`oricf gateway` plays a three-frame video to `oricf serve detector`, each process in its
own right: the detector exports over OTLP/gRPC, the gateway over OTLP/HTTP, as the standard
variables tell them. Each frame is then found in Phoenix as one trace holding both
processes' spans. A spoken question (a WAV file) goes through the speech, language and
speech-synthesis services, each a process exporting over gRPC, and is found as one trace
with every stage. Phoenix is heavy (hundreds of MB), so it lives in a virtual environment
of its own that scripts/phoenix.sh makes: `scripts/phoenix.sh && scripts/test.sh -m
tracing` (docs/testing.md).
"""

from __future__ import annotations

import json
import os
import subprocess
import urllib.request
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from opentelemetry.exporter.otlp.proto.http.trace_exporter import OTLPSpanExporter
from opentelemetry.sdk.resources import SERVICE_NAME, Resource
from opentelemetry.sdk.trace import TracerProvider
from opentelemetry.sdk.trace.export import BatchSpanProcessor

from oricf.audio import encode_wav, synthesize
from oricf.gateway.components import Emitter
from oricf.gateway.config import PipelineConfig, parse_pipeline
from oricf.gateway.host.gateway import Gateway
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import AudioClip
from oricf.tracing import traced_with
from tests.support.data import video_frames
from tests.support.processes import free_port, oricf_process, wait_serving
from tests.support.speech import QUESTION
from tests.support.waiting import wait_for

pytestmark = pytest.mark.tracing

CACHE = Path(os.environ.get("ORICF_CACHE", Path.home() / ".cache/oricf"))
PHOENIX = Path(os.environ.get("ORICF_PHOENIX", CACHE / "phoenix-venv/bin/phoenix"))
GATEWAY_SPANS = {"route people", "receive", "call Detect", "post", "publish"}
DETECTOR_SPANS = {"oricf.v1.Detector/Detect", "decode", "preprocess", "inference",
                  "postprocess"}
FRAMES = 3


@pytest.fixture(scope="module")
def phoenix(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, str]]:
    """A Phoenix server on free ports: (its HTTP address, its OTLP/gRPC address)."""
    if not PHOENIX.exists():
        pytest.fail(f"{PHOENIX} is missing: run scripts/phoenix.sh (or set ORICF_PHOENIX)")
    http, grpc_port = free_port(), free_port()
    env = {**os.environ, "PHOENIX_HOST": "127.0.0.1", "PHOENIX_PORT": str(http),
           "PHOENIX_GRPC_PORT": str(grpc_port),
           "PHOENIX_WORKING_DIR": str(tmp_path_factory.mktemp("phoenix"))}
    log = (tmp_path_factory.getbasetemp() / "phoenix.log").open("w")
    server = subprocess.Popen([str(PHOENIX), "serve"], env=env, stdout=log,
                              stderr=subprocess.STDOUT, start_new_session=True)
    try:
        base = f"http://127.0.0.1:{http}"
        wait_for(lambda: server.poll() is not None or _answers(f"{base}/healthz"), 300,
                 "Phoenix answering /healthz")
        assert server.poll() is None, f"Phoenix exited: {log.name}"
        yield base, f"http://127.0.0.1:{grpc_port}"
    finally:
        server.terminate()
        server.wait(timeout=30)
        log.close()


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as reply:
            return bool(reply.status == 200)
    except OSError:
        return False


def spans_in(base: str) -> list[dict[str, Any]]:
    url = f"{base}/v1/projects/default/spans?limit=1000"
    try:
        with urllib.request.urlopen(url, timeout=10) as reply:
            return list(json.load(reply)["data"])
    except OSError:
        return []  # no project yet: nothing has arrived


def short_video(path: Path) -> Path:
    frames = video_frames(list(range(FRAMES)))
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10, (width, height))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def pipeline_file(folder: Path, detector: str) -> Path:
    pipeline = {
        "endpoints": {"detector": {"address": detector, "deadline_ms": 5000}},
        "routes": {"people": {
            # fps: the route takes every frame (the newest-frame rule drops none)
            "input": {"url": str(short_video(folder / "three.avi")), "fps": 2},
            "call": {"service": "detector", "method": "Detect", "labels": ["person"]},
            "post": [{"count": {"label": "person", "into": "count"}}],
            "outputs": [{"jsonl": str(folder / "counts.jsonl"), "from": "count"}]}}}
    path = folder / "pipeline.yaml"
    path.write_text(json.dumps(pipeline))
    return path


def traces(spans: list[dict[str, Any]]) -> dict[str, set[str]]:
    """trace id -> the names of its spans."""
    found: dict[str, set[str]] = {}
    for span in spans:
        found.setdefault(span["context"]["trace_id"], set()).add(span["name"])
    return found


def test_each_frame_is_one_trace_across_the_gateway_and_the_detector(
        phoenix: tuple[str, str], tmp_path: Path) -> None:
    base, otlp_grpc = phoenix
    port = free_port()
    over_grpc = {"OTEL_EXPORTER_OTLP_ENDPOINT": otlp_grpc, "OTEL_EXPORTER_OTLP_PROTOCOL": "grpc",
                 "OTEL_BSP_SCHEDULE_DELAY": "200"}
    over_http = {"OTEL_EXPORTER_OTLP_ENDPOINT": base, "OTEL_EXPORTER_OTLP_PROTOCOL":
                 "http/protobuf", "OTEL_BSP_SCHEDULE_DELAY": "200"}
    with oricf_process("serve", "detector", "--listen", f"127.0.0.1:{port}",
                       env=over_grpc) as detector:
        wait_serving(f"127.0.0.1:{port}", process=detector)
        with oricf_process("gateway", "--config",
                           str(pipeline_file(tmp_path, f"127.0.0.1:{port}")),
                           env=over_http) as gateway:
            assert gateway.wait(timeout=120) == 0  # the video's end ends the gateway
        counts = (tmp_path / "counts.jsonl").read_text().splitlines()
        assert len(counts) == FRAMES
        whole = GATEWAY_SPANS | DETECTOR_SPANS
        wait_for(lambda: sum(names >= whole for names in traces(spans_in(base)).values())
                 == FRAMES, 60, f"{FRAMES} traces with every span in Phoenix")


QUESTION_SPANS = {"utterance cut", "route speech", "call Transcribe",
                  "oricf.v1.SpeechRecognizer/Transcribe", "route answer", "call Generate",
                  "oricf.v1.LanguageModel/GenerateStream", "route voice", "call Synthesize",
                  "oricf.v1.SpeechSynthesizer/SynthesizeStream"}


def question_pipeline(folder: Path, addresses: dict[str, str]) -> PipelineConfig:
    """mic_questions.yaml's question path with a WAV file for the microphone and another for
    the speaker."""
    silence = np.zeros(4000, dtype=np.int16)
    (folder / "question.wav").write_bytes(
        encode_wav(np.concatenate([silence, synthesize(QUESTION), silence]), 16000))
    return parse_pipeline({
        "endpoints": {name: {"address": address, "deadline_ms": 60000}
                      for name, address in addresses.items()},
        "routes": {
            "speech": {"input": {"audio": str(folder / "question.wav")},
                       "call": {"service": "asr", "method": "Transcribe", "language": "en"},
                       "outputs": [{"product": "transcript", "from": "transcript"}]},
            "answer": {"input": {"product": "transcript"},
                       "call": {"service": "llm", "method": "Generate", "prompt": "{value}",
                                "max_tokens": 32, "sentences": True},
                       "outputs": [{"product": "answer_sentence", "from": "sentence"}]},
            "voice": {"input": {"product": "answer_sentence"},
                      "call": {"service": "tts", "method": "Synthesize"},
                      "outputs": [{"wav": str(folder / "said.wav"), "from": "speech"}]}}},
        "question pipeline")


@contextmanager
def gateway_traced_over_http(base: str) -> Iterator[TracerProvider]:
    """This process as the gateway, its spans to Phoenix over OTLP/HTTP."""
    provider = TracerProvider(resource=Resource.create({SERVICE_NAME: "oricf-gateway"}))
    provider.add_span_processor(BatchSpanProcessor(OTLPSpanExporter(f"{base}/v1/traces")))
    with traced_with(provider):
        yield provider
    provider.shutdown()  # flushes


def test_a_spoken_question_is_one_trace_from_the_utterance_to_the_speech(
        phoenix: tuple[str, str], tmp_path: Path) -> None:
    """asr, llm and tts in processes of their own (OTLP/gRPC), the gateway here (OTLP/HTTP):
    one trace holds every stage of the question, the first sentence and the first audio as
    events on their calls."""
    base, otlp_grpc = phoenix
    over_grpc = {"OTEL_EXPORTER_OTLP_ENDPOINT": otlp_grpc, "OTEL_EXPORTER_OTLP_PROTOCOL": "grpc",
                 "OTEL_BSP_SCHEDULE_DELAY": "200"}
    addresses = {name: f"127.0.0.1:{free_port()}" for name in ("asr", "llm", "tts")}
    with ExitStack() as services:
        for name, address in addresses.items():
            process = services.enter_context(
                oricf_process("serve", name, "--listen", address, env=over_grpc))
            wait_serving(address, process=process)
        with gateway_traced_over_http(base):
            gateway = Gateway(question_pipeline(tmp_path, addresses))
            gateway.configure()
            try:
                gateway.activate()
                wait_for(lambda: gateway.pipeline.routes["voice"].stats.ok >= 1
                         and gateway.pipeline.idle(0.1), 240, "the answer spoken")
            finally:
                gateway.close()

        def whole() -> list[dict[str, Any]]:
            spans = spans_in(base)
            return [s for s in spans if s["context"]["trace_id"] in {
                trace for trace, names in traces(spans).items() if names >= QUESTION_SPANS}]

        wait_for(lambda: whole(), 60, "the question's trace with every stage in Phoenix")
    spans = whole()
    assert len({s["context"]["trace_id"] for s in spans}) == 1
    for call in ("call Generate", "call Synthesize"):
        events = [e["name"] for s in spans if s["name"] == call for e in s.get("events", [])]
        assert "first piece" in events, (call, events)


def test_a_call_over_http_carries_the_trace_to_the_services_openai_api(
        phoenix: tuple[str, str], tmp_path: Path) -> None:
    """The gateway's `protocol: openai` endpoint sends `traceparent` in its HTTP headers; the
    speech service's OpenAI-compatible API makes its span of the request a child of the
    route's call."""
    base, otlp_grpc = phoenix
    over_grpc = {"OTEL_EXPORTER_OTLP_ENDPOINT": otlp_grpc, "OTEL_EXPORTER_OTLP_PROTOCOL": "grpc",
                 "OTEL_BSP_SCHEDULE_DELAY": "200"}
    address, http = f"127.0.0.1:{free_port()}", free_port()
    with oricf_process("serve", "asr", "--listen", address, "--http-listen",
                       f"127.0.0.1:{http}", env=over_grpc) as asr:
        wait_serving(address, process=asr)
        config = parse_pipeline({
            "endpoints": {"asr": {"protocol": "openai", "address": f"http://127.0.0.1:{http}/v1",
                                  "model": "whisper-tiny-en", "deadline_ms": 60000}},
            "routes": {"speech": {
                "input": {"topic": "/audio", "type": "std_msgs/Int16MultiArray"},
                "call": {"service": "asr", "method": "Transcribe", "language": "en"},
                "outputs": [{"jsonl": str(tmp_path / "said.jsonl"), "from": "transcript"}]}}},
            "asr over HTTP")
        with gateway_traced_over_http(base):
            pipeline = Pipeline(config, Emitter())
            pipeline.start()
            try:
                clip = AudioClip(synthesize(QUESTION).astype("<i2").tobytes(), 16000, 1)
                pipeline.submit("speech", lambda: {"audio": clip})
                assert pipeline.idle(60)
            finally:
                pipeline.stop()
            assert pipeline.routes["speech"].stats.ok == 1

        def linked() -> bool:
            spans = spans_in(base)
            calls = {s["context"]["span_id"]: s["context"]["trace_id"] for s in spans
                     if s["name"] == "call Transcribe"}
            return any(s["name"] == "POST /v1/audio/transcriptions"
                       and calls.get(s.get("parent_id")) == s["context"]["trace_id"]
                       for s in spans)

        wait_for(linked, 60, "the service's HTTP span under the gateway's call in Phoenix")
