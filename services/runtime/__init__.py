"""The shared service runtime: lifecycle, health, reflection, limits and error mapping."""

from oricf.services.runtime.config import ServerSettings, ServiceConfig
from oricf.services.runtime.model import Model, ModelInfo, ModelSlot
from oricf.services.runtime.server import ServiceHost, serve
from oricf.services.runtime.spec import ServiceSpec

__all__ = ["Model", "ModelInfo", "ModelSlot", "ServerSettings", "ServiceConfig", "ServiceHost",
           "ServiceSpec", "serve"]
