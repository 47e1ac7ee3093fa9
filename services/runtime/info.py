"""GetModelInfo, the same for every service."""

from __future__ import annotations

from typing import Any

from oricf.services.runtime.model import ModelSlot
from oricf.v1 import common_pb2


def model_info_response(service: str, slot: ModelSlot[Any]) -> common_pb2.GetModelInfoResponse:
    info = slot.peek().info()
    return common_pb2.GetModelInfoResponse(
        service=service,
        model=info.model,
        runtime=info.runtime,
        providers=info.providers,
        license=info.license,
        sha256=info.sha256,
        labels=info.labels,
        parameters=info.parameters,
        load_seconds=slot.load_seconds,
    )
