"""configs/services/models.yaml: the server and the declared models it serves."""

from __future__ import annotations

from pydantic import Field

from oricf.config import FilePath, Schema
from oricf.imaging import MAX_PIXELS
from oricf.services.runtime import ServiceConfig
from oricf.services.runtime.batching import BatchingSettings
from oricf.services.runtime.shared_memory import SharedMemorySettings


class EncodedImageSettings(Schema):
    max_pixels: int = Field(MAX_PIXELS, ge=1, description="refuse larger encoded images")


class ModelsConfig(ServiceConfig):
    models: list[FilePath] = Field(min_length=1,
                                   description="declared model files (configs/models/*.yaml)")
    images: EncodedImageSettings = EncodedImageSettings()
    batching: dict[str, BatchingSettings] = Field(
        default_factory=dict,
        description="model name -> dynamic batching for it (its batch dimension must be free)")
    shared_memory: SharedMemorySettings = Field(
        default_factory=SharedMemorySettings,
        description="system shared memory for clients on this host (Triton's extension)")
