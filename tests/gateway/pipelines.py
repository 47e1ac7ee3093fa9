"""The reference pipeline with test addresses merged in (what a placement overlay does)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from oricf.config import config_dir, deep_merge, read_yaml
from oricf.gateway.config import PipelineConfig, parse_pipeline

PEOPLE_QA = config_dir() / "pipelines" / "people_qa.yaml"


def shipped_pipeline(path: Path, overlay: dict[str, Any] | None = None, **addresses: str
                     ) -> PipelineConfig:
    """A shipped pipeline with endpoint addresses (detector="127.0.0.1:1234", ...) and an
    overlay merged on top."""
    data = read_yaml(path)
    data = deep_merge(data, {"endpoints": {name: {"address": address}
                                           for name, address in addresses.items()}})
    data = deep_merge(data, overlay or {})
    return parse_pipeline(data, f"{path} (test overlay)", path.parent)


def people_qa(overlay: dict[str, Any] | None = None, **addresses: str) -> PipelineConfig:
    """people_qa.yaml with endpoint addresses and an overlay."""
    return shipped_pipeline(PEOPLE_QA, overlay, **addresses)
