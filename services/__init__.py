"""The model services. Each one is a ServiceSpec, looked up by name without importing the others."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from oricf.services.runtime.spec import ServiceSpec

# name -> "module:attribute" of its ServiceSpec; heavy model libraries load only when served.
REGISTRY = {
    "detector": "oricf.services.detector.service:SPEC",
    "asr": "oricf.services.asr.service:SPEC",
    "llm": "oricf.services.llm.service:SPEC",
    "tts": "oricf.services.tts.service:SPEC",
    "models": "oricf.services.models.service:SPEC",
}


def load_spec(name: str) -> ServiceSpec:
    try:
        target = REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown service '{name}' (known: {', '.join(REGISTRY)})") from None
    module, attribute = target.split(":")
    spec: ServiceSpec = getattr(importlib.import_module(module), attribute)
    return spec
