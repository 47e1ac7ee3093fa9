"""A model service inside the calling process, on a free local port: for tests and benchmarks
that measure or exercise the real service without starting another process."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from oricf.config import deep_merge, read_with_overlays, shipped_service_config, validate
from oricf.services import load_spec
from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.handlers import service_parts
from oricf.services.runtime.server import ServiceHost
from oricf.services.runtime.service import Service
from oricf.store import ModelStore

LOCAL_LISTEN = "127.0.0.1:0"


def service_config(name: str, overrides: dict[str, Any] | None = None,
                   path: Path | None = None, overlays: Iterable[Path] = ()) -> Any:
    """A service's YAML (the shipped one by default) with overlay files and then overrides
    merged on top, listening on a free local port; validated, errors naming the files."""
    path = path or shipped_service_config(name)
    data, sources = read_with_overlays(path, overlays)
    data = deep_merge(data, {"server": {"listen": LOCAL_LISTEN}})
    data = deep_merge(data, overrides or {})
    return validate(data, load_spec(name).config_schema, " + ".join(sources),
                    base_dir=path.parent)


@contextmanager
def local_service(name: str | type[Service[Any]], config: ServiceConfig, *, load: bool = True,
                  store: ModelStore | None = None) -> Iterator[ServiceHost]:
    """The service started (its model loaded unless load=False); stopped on exit. name: one
    of SERVICES, or a Service class that is in no list."""
    spec = load_spec(name) if isinstance(name, str) else service_parts(name)
    host = ServiceHost(spec, config, spec.create_model(config, store or ModelStore()))
    host.start()
    try:
        if load:
            host.load_model()
        yield host
    finally:
        host.stop(grace=1.0)
