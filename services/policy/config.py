"""configs/services/policy.yaml: the server and which declared policy it serves."""

from __future__ import annotations

from pydantic import Field

from oricf.config import FilePath, config_dir
from oricf.services.runtime import ServiceConfig


class PolicyConfig(ServiceConfig):
    model: FilePath = Field(
        default_factory=lambda: config_dir() / "models" / "policies" / "hopper.yaml",
        description="a declared policy (task: {kind: policy}; configs/models/policies/*.yaml)")
