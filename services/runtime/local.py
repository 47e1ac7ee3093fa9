"""A model service inside the calling process, on a free local port: for tests and benchmarks
that measure or exercise the real service without starting another process."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from oricf.config import deep_merge, read_yaml, shipped_service_config, validate
from oricf.services import load_spec
from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.server import ServiceHost
from oricf.store import ModelStore

LOCAL_LISTEN = "127.0.0.1:0"


def service_config(name: str, overrides: dict[str, Any] | None = None,
                   path: Path | None = None) -> Any:
    """A service's YAML (the shipped one by default) with overrides merged on top, listening
    on a free local port; validated, errors naming the file."""
    path = path or shipped_service_config(name)
    data = deep_merge(read_yaml(path), {"server": {"listen": LOCAL_LISTEN}})
    data = deep_merge(data, overrides or {})
    return validate(data, load_spec(name).config_schema, str(path), base_dir=path.parent)


@contextmanager
def local_service(name: str, config: ServiceConfig, *, load: bool = True,
                  store: ModelStore | None = None) -> Iterator[ServiceHost]:
    """The service started (its model loaded unless load=False); stopped on exit."""
    spec = load_spec(name)
    host = ServiceHost(spec, config, spec.create_model(config, store or ModelStore()))
    host.start()
    try:
        if load:
            host.load_model()
        yield host
    finally:
        host.stop(grace=1.0)
