"""What a loaded model is, for GetModelInfo and logs: the same record for every service."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class ModelInfo:
    """What a model is, for GetModelInfo and logs."""

    model: str
    runtime: str
    providers: list[str] = field(default_factory=list)
    license: str = ""
    sha256: str = ""
    labels: list[str] = field(default_factory=list)
    parameters: dict[str, str] = field(default_factory=dict)
