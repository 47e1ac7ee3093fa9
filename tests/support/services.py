"""Starts a real model service in-process on 127.0.0.1:0 and gives a real channel to it."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import grpc

from oricf.config import config_dir, deep_merge, read_yaml, validate
from oricf.services import load_spec
from oricf.services.runtime import ServiceHost
from oricf.store import ModelStore

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


def service_config(name: str, overrides: dict[str, Any] | None = None) -> Any:
    """The service's shipped config with overrides merged on top, listening on a free port."""
    path = config_dir() / "services" / f"{name}.yaml"
    data = deep_merge(read_yaml(path), {"server": {"listen": "127.0.0.1:0"}})
    data = deep_merge(data, overrides or {})
    return validate(data, load_spec(name).config_schema, str(path), base_dir=Path(path).parent)


@contextmanager
def running_service(name: str, overrides: dict[str, Any] | None = None, *, load: bool = True,
                    store: ModelStore | None = None) -> Iterator[RunningService]:
    """A started service (model loaded unless load=False) and an open channel to it."""
    spec = load_spec(name)
    config = service_config(name, overrides)
    host = ServiceHost(spec, config, spec.create_model(config, store or ModelStore()))
    host.start()
    channel = grpc.insecure_channel(f"127.0.0.1:{host.port}", options=CHANNEL_OPTIONS)
    try:
        if load:
            host.load_model()
        yield RunningService(host, channel)
    finally:
        channel.close()
        host.stop(grace=1.0)
