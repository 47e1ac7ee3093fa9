"""Every registered method is one class with the lifecycle of a Triton python_backend model
(built once per route with its settings, `execute` per record, `close`), and a call that
fails shows that class's methods in its traceback, never a closure's `<locals>`: each
method's real call to an address where nothing listens (a real gRPC channel, refused)."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path
from typing import Any

import grpc
import numpy as np
import pytest

from oricf.config import REPO_ROOT
from oricf.gateway.components import METHODS, MethodCall
from oricf.gateway.endpoints import Endpoint, EndpointConfig
from oricf.gateway.products import ProductStore
from oricf.gateway.values import AudioClip, Frame, Record

NOBODY = "127.0.0.1:1"  # nothing listens: every call is refused (UNAVAILABLE)
METHODS_DIR = REPO_ROOT / "gateway" / "methods"
FRAME = Frame.from_pixels(np.zeros((32, 32, 3), np.uint8))

# Per method: its call's settings beside method and service, and a record it takes.
CALLS: dict[str, tuple[dict[str, Any], Record]] = {
    "Detect": ({}, {"image": FRAME}),
    "Transcribe": ({}, {"audio": AudioClip(bytes(3200), 16000, 1)}),
    "Generate": ({"sentences": True}, {"text": "How many people are there?"}),
    "Infer": ({"model": str(REPO_ROOT / "configs" / "models" / "yolox-nano.yaml")},
              {"image": FRAME}),
    "Synthesize": ({}, {"value": "Two people."}),
    "Act": ({}, {"state": np.zeros(3), "step": 1}),
}


def test_every_method_is_a_class_with_the_lifecycle() -> None:
    assert set(CALLS) <= set(METHODS)
    for name, method in METHODS.items():
        cls = method.calls
        assert inspect.isclass(cls) and issubclass(cls, MethodCall), name
        assert not inspect.isabstract(cls), f"{name}: {cls.__name__} has no execute"
        for step in ("execute", "close", "__call__"):
            assert "<locals>" not in getattr(cls, step).__qualname__
        assert cls.execute.__qualname__ == f"{cls.__name__}.execute"
        assert Path(inspect.getfile(cls)).parent == METHODS_DIR, name


@pytest.mark.parametrize("name", list(CALLS))
def test_a_failing_call_is_traced_through_its_class(name: str) -> None:
    method = METHODS[name]
    settings, record = CALLS[name]
    call = method.config.model_validate({"method": name, "service": "x", **settings})
    assert dataclasses.is_dataclass(method.result(call))
    endpoint = Endpoint("x", EndpointConfig(address=NOBODY, deadline_ms=2000), method)
    bound = method.open(call, endpoint, ProductStore())
    try:
        with pytest.raises(grpc.RpcError) as refused:
            bound(record)
    finally:
        bound.close()
        endpoint.close()
    assert refused.value.code() == grpc.StatusCode.UNAVAILABLE
    names = [frame.f_code.co_qualname for frame, _ in _frames(refused.value.__traceback__)]
    cls = method.calls.__name__
    assert f"{cls}.execute" in names, names
    assert not [n for n in names if "<locals>" in n], names


def _frames(tb: Any) -> list[tuple[Any, int]]:
    """The traceback's frames in the gateway's method modules, outermost first."""
    found = []
    while tb is not None:
        if Path(tb.tb_frame.f_code.co_filename).parent == METHODS_DIR:
            found.append((tb.tb_frame, tb.tb_lineno))
        tb = tb.tb_next
    return found
