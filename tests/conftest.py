"""Tests run against the real models, real gRPC servers on localhost and real DDS.

Nothing is skipped for a missing model or tool: run scripts/setup.sh --dev first.

A fixture named after a service (detector, asr, llm, tts, models, policy) is that service with
its shipped settings, shared by the session. A fixture that starts a service another way is
named for what differs (llm_small_context, tts_http, camera_policy), and tests/test_fixtures.py
keeps every fixture name to one meaning. One that tests in two modules need is shared by the
session too, so that its model loads once.
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
def policy_models(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningService]:
    """`oricf serve models` with the shipped Hopper policy and tests/support/camera_policy.py's
    declared: the policies over the Open Inference Protocol."""
    from oricf.config import config_dir
    from tests.support.camera_policy import declaration

    hopper = config_dir() / "models" / "policies" / "hopper.yaml"
    camera = declaration(tmp_path_factory.mktemp("camera-policy-oip"))
    with running_service("models", {"models": [str(hopper), str(camera)]}) as service:
        yield service


@pytest.fixture(scope="session")
def llm_one_call(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    """`oricf serve llm` with HTTP opened, in a process of its own, taking one call at a time
    (a refused caller told to wait 400 ms or more): for tests that fill its only slot."""
    from tests.support.openai_http import http_service, overlay

    folder = tmp_path_factory.mktemp("llm-one-call")
    one = overlay(folder, {"server": {"max_concurrent_rpcs": 1, "retry_after_ms": 400}})
    with http_service("llm", "--overlay", one) as service:
        yield service


@pytest.fixture(scope="session")
def asr_small_uploads(tmp_path_factory: pytest.TempPathFactory) -> Iterator[HttpService]:
    """`oricf serve asr` with HTTP opened, in a process of its own, taking uploads of 1 MB at
    most (server.http.max_upload_mb)."""
    from tests.support.openai_http import http_service, overlay

    folder = tmp_path_factory.mktemp("asr-small-uploads")
    limits = overlay(folder, {"server": {"http": {"max_upload_mb": 1}}})
    with http_service("asr", "--overlay", limits) as service:
        yield service


@pytest.fixture(scope="session")
def tts_http() -> Iterator[HttpService]:
    """`oricf serve tts` with its shipped settings in a process of its own, HTTP opened: for
    tests of its OpenAI-compatible API and of what a request costs the process."""
    from tests.support.openai_http import http_service  # the OpenAI client: only when asked

    with http_service("tts") as service:
        yield service
