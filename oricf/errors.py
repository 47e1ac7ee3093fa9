"""Domain errors shared by every part of ORICF.

Model code raises these without knowing about gRPC; services/runtime/errors.py maps
them to status codes in one place.
"""

from __future__ import annotations


class OricfError(Exception):
    """Base of every error ORICF raises on purpose."""


class InvalidInput(OricfError):
    """The caller sent something the model cannot use (bad image, empty audio...)."""


class NotFound(OricfError):
    """The caller named something the service does not have (a model, a version)."""


class NotReady(OricfError):
    """The model is not loaded yet, or the service is shutting down."""


class Overloaded(OricfError):
    """Too much work queued; the caller should retry later (after retry_after_ms if given)."""

    def __init__(self, message: str, retry_after_ms: int | None = None) -> None:
        super().__init__(message)
        self.retry_after_ms = retry_after_ms


class DeadlineExceeded(OricfError):
    """The caller's deadline passed before the work could finish."""


class Cancelled(OricfError):
    """The caller went away; the work was stopped."""


class ConfigError(OricfError):
    """A configuration file is missing, unreadable or invalid."""


class ModelMissing(OricfError):
    """A model is not in the local model store (or fails its checksum)."""
