"""Tests run against the real models, real gRPC servers on localhost and real DDS.

Nothing is skipped for a missing model or tool: run scripts/setup.sh --dev first.

A fixture named after a service (detector, asr, llm, tts, models, policy) is that service with
its shipped settings, shared by the session. A fixture that starts a service another way is
named for what differs (llm_small_context, tts_http, camera_policy), and tests/test_fixtures.py
keeps every fixture name to one meaning.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import pytest

from tests.support.certs import certs
from tests.support.services import RunningService, SharedServices, running_service

if TYPE_CHECKING:
    from tests.support.openai_http import HttpService

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
policy = shared("policy")


@pytest.fixture(scope="session")
def camera_policy(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningService]:
    """`oricf serve policy` with tests/support/camera_policy.py's declaration: a state and one
    camera's image in, the image's channel means and the state out."""
    from tests.support.camera_policy import declaration

    folder = tmp_path_factory.mktemp("camera-policy")
    with running_service("policy", {"model": str(declaration(folder))}) as service:
        yield service


@pytest.fixture(scope="session")
def tts_http() -> Iterator[HttpService]:
    """`oricf serve tts` with its shipped settings in a process of its own, HTTP opened: for
    tests of its OpenAI-compatible API and of what a request costs the process."""
    from tests.support.openai_http import http_service  # the OpenAI client: only when asked

    with http_service("tts") as service:
        yield service
