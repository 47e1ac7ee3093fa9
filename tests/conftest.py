"""Tests run against the real models, real gRPC servers on localhost and real DDS.

Nothing is skipped for a missing model or tool: run scripts/setup.sh --dev first.
"""

from collections.abc import Iterator
from typing import Any

import pytest

from tests.support.certs import certs
from tests.support.services import RunningService, SharedServices

__all__ = ["certs"]  # the session's TLS certificates, a fixture


@pytest.fixture(scope="session")
def shared_services() -> Iterator[SharedServices]:
    services = SharedServices()
    yield services
    services.close()


def shared(name: str) -> Any:
    """A session fixture named after a service: that service with its shipped settings,
    shared by the session."""

    @pytest.fixture(scope="session", name=name)
    def service(shared_services: SharedServices) -> RunningService:
        return shared_services[name]

    return service


# Each a RunningService (.address, .channel, .host).
detector = shared("detector")
asr = shared("asr")
llm = shared("llm")
tts = shared("tts")
models = shared("models")
