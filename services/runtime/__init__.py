"""The shared service runtime: lifecycle, health, reflection, limits and error mapping."""

from oricf.services.runtime.config import ServerSettings, ServiceConfig
from oricf.services.runtime.model import Model, ModelInfo, ModelSlot
from oricf.services.runtime.parts import ServiceParts
from oricf.services.runtime.server import ServiceHost, serve

__all__ = ["Model", "ModelInfo", "ModelSlot", "ServerSettings", "ServiceConfig", "ServiceHost",
           "ServiceParts", "serve"]
