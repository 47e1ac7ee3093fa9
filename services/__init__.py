"""The model services: `SERVICES` is the one list of them, which the command line, the
launcher and the deployment files read. A service's code (its `Service` class or its
`ServiceParts`, and the heavy model libraries) is imported only when it is served
(`load_spec`)."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from oricf.services.spec import ServiceSpec

if TYPE_CHECKING:
    from oricf.services.runtime.parts import ServiceParts

SERVICES: dict[str, ServiceSpec] = {spec.name: spec for spec in (
    ServiceSpec("detector", "oricf.v1.Detector", 50051),
    ServiceSpec("asr", "oricf.v1.SpeechRecognizer", 50052, http=True),
    ServiceSpec("llm", "oricf.v1.LanguageModel", 50053, http=True),
    ServiceSpec("tts", "oricf.v1.SpeechSynthesizer", 50054, http=True),
    # Declared models over the Open Inference Protocol, on its customary gRPC port.
    ServiceSpec("models", "inference.GRPCInferenceService", 8001),
    # Learned control policies: observations in, chunks of actions out.
    ServiceSpec("policy", "oricf.v1.Policy", 50055),
)}

__all__ = ["SERVICES", "ServiceSpec", "load_spec"]


def load_spec(name: str) -> ServiceParts:
    """The parts of the service `name` (its config schema, model and servicer), imported:
    derived from the module's `SERVICE` class, or its `PARTS` as written."""
    try:
        spec = SERVICES[name]
    except KeyError:
        raise KeyError(f"unknown service '{name}' (known: {', '.join(SERVICES)})") from None
    module = importlib.import_module(spec.module)
    if hasattr(module, "SERVICE"):  # a Service class: the runtime derives its parts
        from oricf.services.runtime.handlers import service_parts

        return service_parts(module.SERVICE, spec)
    parts: ServiceParts = module.PARTS
    return parts
