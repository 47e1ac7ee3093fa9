"""Property-based fuzzing of every RPC of every service over real channels: random bytes and
random-but-well-formed messages (each field drawn from hostile values: huge, empty, negative,
NaN, fake image headers). Whatever arrives, a service answers with a status that names a
client mistake or a limit, never INTERNAL or UNKNOWN, never hangs, stays within a bounded
amount of memory, and is SERVING afterwards. Over 800 requests in all by default, twice as
many with ORICF_FUZZ_SCALE=1."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import ExitStack
from typing import Any

import grpc
import pytest
from google.protobuf.descriptor import Descriptor, FieldDescriptor, ServiceDescriptor
from grpc_health.v1 import health_pb2, health_pb2_grpc
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oricf.audio import wav_header
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.v1 import detector_pb2, language_pb2, policy_pb2, speech_pb2, synthesis_pb2
from tests.support.camera_policy import CAMERA
from tests.support.fuzzing import examples
from tests.support.services import RunningService, running_service

EXAMPLES = examples(70)  # per RPC: 27 RPCs, 1,890 requests of 1-3 messages in all (half by default)
# Refusals a client may get for a hostile request. INTERNAL and UNKNOWN are bugs;
# DEADLINE_EXCEEDED would mean the service did not answer in time.
ACCEPTABLE = {grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.NOT_FOUND,
              grpc.StatusCode.RESOURCE_EXHAUSTED, grpc.StatusCode.OUT_OF_RANGE,
              grpc.StatusCode.FAILED_PRECONDITION, grpc.StatusCode.CANCELLED}
CALL_TIMEOUT_S = 30
MAX_GROWTH_MB = 800

SERVICES: dict[str, tuple[ServiceDescriptor, dict[str, Any]]] = {
    "detector": (detector_pb2.DESCRIPTOR.services_by_name["Detector"], {}),
    "asr": (speech_pb2.DESCRIPTOR.services_by_name["SpeechRecognizer"], {}),
    "llm": (language_pb2.DESCRIPTOR.services_by_name["LanguageModel"],
            {"generation": {"max_tokens": 2, "max_tokens_limit": 4}}),
    "models": (oip.DESCRIPTOR.services_by_name["GRPCInferenceService"], {}),
    "tts": (synthesis_pb2.DESCRIPTOR.services_by_name["SpeechSynthesizer"], {}),
    "policy": (policy_pb2.DESCRIPTOR.services_by_name["Policy"], {}),
    # A policy that sees: images by camera name are decoded before the state is checked.
    "policy:cameras": (policy_pb2.DESCRIPTOR.services_by_name["Policy"], {}),
}
CASES = [(service, method.name) for service, (descriptor, _) in SERVICES.items()
         for method in descriptor.methods]

# The last: a WAV header of 384 kHz in 32 channels whose data runs to the end of the file.
HEADERS = [b"\xff\xd8\xff\xc0\x00\x11\x08\xff\xff\xff\xff", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR",
           b"RIFF\xff\xff\xff\xffWAVEfmt ", b"GIF89a", b"", wav_header(384_000, 32, 0x7FFFFFFF)]
# The last two: numbers that read out many times longer, letters a voice spells one by one.
TEXTS = st.one_of(st.text(max_size=40), st.sampled_from(
    ["jpeg", "png", "rgb8", "bgr8", "mono8", "wav", "pcm_s16le", "person", "yolox-nano",
     "images", "output", "FP32", "BYTES", "UINT8", "{text}", "x" * 5000, "1" + ",000" * 400,
     "مرحبا بك"]))
BYTES = st.one_of(st.binary(max_size=512),
                  st.builds(lambda h, b: h + b, st.sampled_from(HEADERS), st.binary(max_size=256)))
INTS = st.one_of(st.integers(-3, 70_000), st.sampled_from([-(2**31), 2**31 - 1, 1, 0]))


# Fields drawn in every message, from values of their own: random ones would almost never
# be valid, and the checks behind them would go untried. Fact names: mostly the one the
# prompt template renders (often twice in a request), sometimes empty or hostile.
FIELD_VALUES: dict[str, st.SearchStrategy[Any]] = {
    "oricf.v1.Fact.name": st.one_of(st.sampled_from(["people_count", "people_count", "dogs",
                                                     ""]), TEXTS),
    "oricf.v1.Observation.ImagesEntry.key": st.one_of(st.just(CAMERA), TEXTS),
}


def scalar(field: FieldDescriptor) -> st.SearchStrategy[Any]:
    if field.full_name in FIELD_VALUES:
        return FIELD_VALUES[field.full_name]
    kind = field.type
    if kind == FieldDescriptor.TYPE_STRING:
        return TEXTS
    if kind == FieldDescriptor.TYPE_BYTES:
        return BYTES
    if kind == FieldDescriptor.TYPE_BOOL:
        return st.booleans()
    if kind in (FieldDescriptor.TYPE_FLOAT, FieldDescriptor.TYPE_DOUBLE):
        return st.sampled_from([0.0, -1.0, 0.5, 2.0, 1e30, math.inf, math.nan])
    if kind in (FieldDescriptor.TYPE_UINT32, FieldDescriptor.TYPE_FIXED32):
        return st.integers(0, 2**32 - 1)
    if kind in (FieldDescriptor.TYPE_UINT64, FieldDescriptor.TYPE_FIXED64):
        return st.integers(0, 2**64 - 1)
    if kind == FieldDescriptor.TYPE_ENUM:
        return st.sampled_from([v.number for v in field.enum_type.values])
    if kind in (FieldDescriptor.TYPE_INT64, FieldDescriptor.TYPE_SINT64):
        return st.one_of(INTS, st.sampled_from([-(2**63), 2**63 - 1]))
    return INTS


# Repeated fields drawn whole: a policy's state of the served Hopper's 15 values, sometimes
# with NaN, infinity or huge values in it, or of a wrong length.
HOSTILE_FLOATS = st.sampled_from([0.0, -1.0, 0.5, 1e30, -3.4e38, math.inf, math.nan])
LIST_VALUES: dict[str, st.SearchStrategy[Any]] = {
    "oricf.v1.Observation.state": st.one_of(
        st.lists(st.floats(-10, 10, width=32), min_size=15, max_size=15),
        st.lists(HOSTILE_FLOATS, min_size=15, max_size=15),
        st.lists(HOSTILE_FLOATS, max_size=40)),
}


def message(descriptor: Descriptor, depth: int = 0) -> st.SearchStrategy[dict[str, Any]]:
    """A random message of this type, as a dict of field values (each field optional but
    those of FIELD_VALUES)."""
    fields: dict[str, st.SearchStrategy[Any]] = {}
    for field in descriptor.fields:
        if field.full_name in LIST_VALUES:
            fields[field.name] = LIST_VALUES[field.full_name]
            continue
        if field.message_type is not None and field.message_type.GetOptions().map_entry:
            key, value = field.message_type.fields
            value_strategy = (message(value.message_type, depth + 1)
                              if value.message_type else scalar(value))
            fields[field.name] = st.dictionaries(scalar(key), value_strategy, max_size=3)
            continue
        if field.message_type is not None:
            if depth >= 3:
                continue
            one = message(field.message_type, depth + 1)
        else:
            one = scalar(field)
        repeated = field.is_repeated
        fields[field.name] = st.lists(one, max_size=4) if repeated else one
    required = {f.name: fields.pop(f.name) for f in descriptor.fields
                if f.full_name in FIELD_VALUES}
    return st.fixed_dictionaries(required, optional=fields)


def serialized(descriptor: Descriptor) -> st.SearchStrategy[bytes]:
    from google.protobuf import json_format
    from google.protobuf.message_factory import GetMessageClass

    cls = GetMessageClass(descriptor)

    def build(values: dict[str, Any]) -> bytes:
        msg = cls()
        try:
            _fill(msg, values)
        except (ValueError, TypeError, OverflowError):
            return json_format.MessageToJson(msg).encode()  # not a valid message: fine too
        return bytes(msg.SerializeToString())

    return message(descriptor).map(build)


def _fill(msg: Any, values: dict[str, Any]) -> None:
    for name, value in values.items():
        field = msg.DESCRIPTOR.fields_by_name[name]
        target = getattr(msg, name)
        if field.message_type is not None and field.message_type.GetOptions().map_entry:
            for key, item in value.items():
                if isinstance(item, dict):
                    _fill(target[key], item)
                else:
                    target[key] = item
        elif field.is_repeated:
            for item in value:
                if isinstance(item, dict):
                    _fill(target.add(), item)
                else:
                    target.append(item)
        elif isinstance(value, dict):
            _fill(target, value)
        else:
            setattr(msg, name, value)


def vm_hwm_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return 0.0


# The session's fixture of each service fuzzed with its shipped settings (tests/conftest.py);
# the language model, with short answers, is started for this module.
SESSION_FIXTURES = {"detector": "detector", "asr": "asr", "models": "models", "tts": "tts",
                    "policy": "policy", "policy:cameras": "camera_policy"}


class Fuzzed:
    """Each service fuzzed, started once for the module or taken from the session, and the
    process's peak memory when it was first asked for."""

    def __init__(self) -> None:
        self.stack = ExitStack()
        self._running: dict[str, tuple[RunningService, float]] = {}

    def service(self, name: str, request: pytest.FixtureRequest) -> RunningService:
        if name not in self._running:
            if name in SESSION_FIXTURES:
                running = request.getfixturevalue(SESSION_FIXTURES[name])
            else:
                running = self.stack.enter_context(running_service(name, SERVICES[name][1]))
            self._running[name] = running, vm_hwm_mb()
        return self._running[name][0]

    def check(self, name: str) -> None:
        """Memory grew within bounds since the service was first asked for (over all the
        cases it has had), and it is SERVING."""
        running, before = self._running[name]
        assert vm_hwm_mb() - before < MAX_GROWTH_MB, "memory grew without bound"
        health = health_pb2_grpc.HealthStub(running.channel).Check(
            health_pb2.HealthCheckRequest(), timeout=10)
        assert health.status == health_pb2.HealthCheckResponse.SERVING


@pytest.fixture(scope="module")
def fuzzed() -> Iterator[Fuzzed]:
    services = Fuzzed()
    with services.stack:
        yield services


def _call(channel: grpc.Channel, path: str, client_stream: bool, server_stream: bool,
          payloads: list[bytes]) -> None:
    if client_stream and server_stream:
        list(channel.stream_stream(path)(iter(payloads), timeout=CALL_TIMEOUT_S))
    elif client_stream:
        channel.stream_unary(path)(iter(payloads), timeout=CALL_TIMEOUT_S)
    elif server_stream:
        list(channel.unary_stream(path)(payloads[0], timeout=CALL_TIMEOUT_S))
    else:
        channel.unary_unary(path)(payloads[0], timeout=CALL_TIMEOUT_S)


@pytest.mark.parametrize(("name", "rpc"), CASES, ids=[f"{s}-{r}" for s, r in CASES])
def test_hostile_requests_never_crash_hang_or_leak(fuzzed: Fuzzed, name: str, rpc: str,
                                                   request: pytest.FixtureRequest) -> None:
    running = fuzzed.service(name, request)
    descriptor = SERVICES[name][0]
    method = descriptor.methods_by_name[rpc]
    path = f"/{descriptor.full_name}/{rpc}"
    payload = st.one_of(st.binary(max_size=256), serialized(method.input_type))

    sent: list[int] = []

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(payload, min_size=1, max_size=3))
    def fuzz(payloads: list[bytes]) -> None:
        sent.append(len(payloads))
        try:
            _call(running.channel, path, method.client_streaming, method.server_streaming,
                  payloads)
        except grpc.RpcError as error:
            assert error.code() in ACCEPTABLE, (rpc, error.code(), error.details())

    fuzz()
    assert len(sent) >= EXAMPLES, f"only {len(sent)} requests were tried"
    fuzzed.check(name)
