"""The shared service runtime: lifecycle, health, reflection, limits and error mapping. A
service is a `Service` class (service.py), whose gRPC side the runtime derives (handlers.py),
as the detector and the policy are; asr, llm, tts and models still give their parts as written
(`ServiceParts`, parts.py)."""

from oricf.services.runtime.config import ServerSettings, ServiceConfig
from oricf.services.runtime.model import Model, ModelInfo, ModelSlot
from oricf.services.runtime.parts import ServiceParts
from oricf.services.runtime.server import ServiceHost, serve
from oricf.services.runtime.service import Call, Service

__all__ = ["Call", "Model", "ModelInfo", "ModelSlot", "ServerSettings", "Service",
           "ServiceConfig", "ServiceHost", "ServiceParts", "serve"]
