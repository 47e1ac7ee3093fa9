"""Tests run against the real models, real gRPC servers on localhost and real DDS.

Nothing is skipped for a missing model or tool: run scripts/setup.sh --dev first.
"""

from collections.abc import Iterator

import pytest

from tests.support.certs import certs
from tests.support.services import RunningService, SharedServices

__all__ = ["certs"]  # the session's TLS certificates, a fixture


@pytest.fixture(scope="session")
def shared_services() -> Iterator[SharedServices]:
    services = SharedServices()
    yield services
    services.close()


@pytest.fixture(scope="session")
def detector(shared_services: SharedServices) -> RunningService:
    """The detector with its shipped settings, shared by the session."""
    return shared_services["detector"]


@pytest.fixture(scope="session")
def asr(shared_services: SharedServices) -> RunningService:
    """The speech recognizer with its shipped settings, shared by the session."""
    return shared_services["asr"]


@pytest.fixture(scope="session")
def llm(shared_services: SharedServices) -> RunningService:
    """The language model with its shipped settings, shared by the session."""
    return shared_services["llm"]


@pytest.fixture(scope="session")
def tts(shared_services: SharedServices) -> RunningService:
    """The speech synthesizer with its shipped settings, shared by the session."""
    return shared_services["tts"]


@pytest.fixture(scope="session")
def models(shared_services: SharedServices) -> RunningService:
    """The declared-models service with its shipped settings, shared by the session."""
    return shared_services["models"]
