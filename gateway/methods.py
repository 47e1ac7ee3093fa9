"""Every method a route can call, one table entry each: its gRPC service and stub, the RPC
it makes, how to ask whether a server is ready, the record fields it adds, and how it turns
a record into a request and the response into fields (oricf.gateway.calls). The call's own
keys are its schema in oricf.gateway.config (CallConfig, one class per method)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.gateway import calls
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.v1 import detector_pb2_grpc, language_pb2_grpc, speech_pb2_grpc

Metadata = tuple[tuple[str, str], ...]
Ready = Callable[[grpc.Channel, float, Metadata], bool]


def health_check(service: str) -> Ready:
    """Ready when grpc.health.v1 says the service is SERVING (ORICF's own services)."""
    def ready(channel: grpc.Channel, timeout: float, metadata: Metadata = ()) -> bool:
        reply = health_pb2_grpc.HealthStub(channel).Check(
            health_pb2.HealthCheckRequest(service=service), timeout=timeout,
            metadata=metadata)
        return bool(reply.status == health_pb2.HealthCheckResponse.SERVING)

    return ready


def server_ready(channel: grpc.Channel, timeout: float, metadata: Metadata = ()) -> bool:
    """Ready when the Open Inference Protocol's ServerReady says so: Triton, KServe and
    MLServer need not implement grpc.health.v1."""
    stub = oip_grpc.GRPCInferenceServiceStub(channel)
    return bool(stub.ServerReady(oip.ServerReadyRequest(), timeout=timeout,
                                 metadata=metadata).ready)


@dataclass(frozen=True)
class Method:
    service: str                               # the gRPC service the endpoint must serve
    stub: Callable[[grpc.Channel], Any]
    rpc: str                                   # the stub method each record calls
    ready: Ready                               # the probe used to come back from a fallback
    fields: Callable[[Any], tuple[str, ...]]   # the record fields a call config adds
    bind: calls.Binder                         # (call config, endpoint, products) -> invoke
    image_transport: bool = False              # sends camera frames (endpoint.image applies)


METHODS: dict[str, Method] = {
    "Detect": Method(
        "oricf.v1.Detector", detector_pb2_grpc.DetectorStub, "Detect",
        health_check("oricf.v1.Detector"), lambda call: ("detections", "counts", "annotated"),
        calls.detect, image_transport=True),
    "Transcribe": Method(
        "oricf.v1.SpeechRecognizer", speech_pb2_grpc.SpeechRecognizerStub, "Transcribe",
        health_check("oricf.v1.SpeechRecognizer"), lambda call: ("transcript", "duration_s"),
        calls.transcribe),
    "Generate": Method(
        "oricf.v1.LanguageModel", language_pb2_grpc.LanguageModelStub, "Generate",
        health_check("oricf.v1.LanguageModel"), lambda call: ("answer",), calls.generate),
    "Infer": Method(
        "inference.GRPCInferenceService", oip_grpc.GRPCInferenceServiceStub, "ModelInfer",
        server_ready, calls.infer_fields, calls.infer, image_transport=True),
}
