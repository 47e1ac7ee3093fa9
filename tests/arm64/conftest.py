"""The arm64 root, set up once a session, and the model services started in it, each once a
session, the first time a test asks for it (tests/arm64/root.py)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import grpc
import pytest

from tests.arm64.root import service_in_root, set_up


@pytest.fixture(scope="session")
def arm64_root() -> str:
    """scripts/arm64-setup.sh's output: the root made, the project and the README's set-up
    in it (each step skipped when done)."""
    return set_up()


@dataclass
class ServiceInRoot:
    address: str           # 127.0.0.1:PORT, shared by the root and this machine
    channel: grpc.Channel  # a channel from this machine


def serve(name: str) -> Iterator[ServiceInRoot]:
    with service_in_root(name) as address, grpc.insecure_channel(address) as channel:
        yield ServiceInRoot(address, channel)


@pytest.fixture(scope="session")
def arm64_detector(arm64_root: str) -> Iterator[ServiceInRoot]:
    yield from serve("detector")


@pytest.fixture(scope="session")
def arm64_asr(arm64_root: str) -> Iterator[ServiceInRoot]:
    yield from serve("asr")


@pytest.fixture(scope="session")
def arm64_llm(arm64_root: str) -> Iterator[ServiceInRoot]:
    yield from serve("llm")


@pytest.fixture(scope="session")
def arm64_tts(arm64_root: str) -> Iterator[ServiceInRoot]:
    yield from serve("tts")
