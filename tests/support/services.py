"""Starts a real model service in-process on 127.0.0.1:0 and gives a real channel to it."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any

import grpc

from oricf.services.local import local_service, service_config
from oricf.services.runtime import ServiceHost
from oricf.store import ModelStore

__all__ = ["RunningService", "SharedServices", "running_service", "service_config"]

CHANNEL_OPTIONS = [
    ("grpc.max_send_message_length", 64 * 1024 * 1024),
    ("grpc.max_receive_message_length", 64 * 1024 * 1024),
]


@dataclass
class RunningService:
    host: ServiceHost
    channel: grpc.Channel

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.host.port}"


@contextmanager
def running_service(name: str, overrides: dict[str, Any] | None = None, *, load: bool = True,
                    store: ModelStore | None = None) -> Iterator[RunningService]:
    """A started service (model loaded unless load=False) and an open channel to it."""
    with local_service(name, service_config(name, overrides), load=load, store=store) as host:
        channel = grpc.insecure_channel(f"127.0.0.1:{host.port}", options=CHANNEL_OPTIONS)
        try:
            yield RunningService(host, channel)
        finally:
            channel.close()


class SharedServices:
    """Each service with its shipped settings, started the first time a test asks for it and
    kept until the session ends: a model loads once, not once per test module. Tests that
    change a service's settings, stop it, or load it to its limits start their own with
    running_service()."""

    def __init__(self) -> None:
        self._stack = ExitStack()
        self._started: dict[str, RunningService] = {}

    def __getitem__(self, name: str) -> RunningService:
        if name not in self._started:
            self._started[name] = self._stack.enter_context(running_service(name))
        return self._started[name]

    def close(self) -> None:
        self._stack.close()
        self._started.clear()
