"""The component registries: every module of a kind's package that declares a component is
found, in rank order; two modules that declare one key are refused, naming both."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import create_model

from oricf.config import Schema, validate
from oricf.errors import ConfigError
from oricf.gateway.components import (
    METHODS,
    STEPS,
    ComponentError,
    Method,
    Registry,
    StepKind,
)
from oricf.gateway.config import PostStep, call_schema, parse_pipeline
from tests.gateway.test_config import edited

STEP_MODULE = """
from oricf.gateway.components import Step, StepKind

def build(settings):
    return Step(frozenset(), None, lambda record: None)

COMPONENT = StepKind({key!r}, dict, build, rank={rank})
"""

METHOD_MODULE = """
from dataclasses import dataclass
from typing import Literal

from oricf.gateway.components import CallBase, Method, MethodCall

class Call(CallBase):
    method: Literal[{key!r}]
    loud: bool = False

@dataclass(frozen=True)
class Said:
    said: str

class Echo(MethodCall[Call]):
    result = Said

    def execute(self, record):
        return Said(str(record["text"]))

METHOD = Method({key!r}, Call, "test.Echo", lambda channel: None,
                lambda channel, timeout, metadata=(): True, Echo, rank={rank})
"""


def package(tmp_path: Path, name: str, modules: dict[str, str]) -> str:
    folder = tmp_path / name
    folder.mkdir()
    (folder / "__init__.py").write_text("")
    for module, text in modules.items():
        (folder / f"{module}.py").write_text(text)
    return name


@pytest.fixture
def on_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in [m for m in sys.modules if m.startswith(("steps_", "methods_"))]:
        del sys.modules[name]


def test_the_post_steps_are_found_in_rank_order() -> None:
    assert list(STEPS)[:3] == ["map_labels", "filter", "count"]
    assert {"track", "zone", "line"} <= set(STEPS)
    assert list(PostStep.model_fields) == list(STEPS)


def test_modules_without_a_declaration_are_skipped(on_path: Path) -> None:
    name = package(on_path, "steps_found", {
        "b": STEP_MODULE.format(key="b", rank=1), "a": STEP_MODULE.format(key="a", rank=2),
        "helper": "VALUE = 1\n"})
    found: Registry[StepKind] = Registry(name, "COMPONENT", StepKind)
    assert list(found) == ["b", "a"]


def test_a_key_declared_twice_names_both_modules(on_path: Path) -> None:
    name = package(on_path, "steps_twice", {
        "first": STEP_MODULE.format(key="same", rank=1),
        "second": STEP_MODULE.format(key="same", rank=1)})
    with pytest.raises(ComponentError,
                       match=r"'same' is declared by both steps_twice\.first and "
                             r"steps_twice\.second"):
        list(Registry(name, "COMPONENT", StepKind))


def test_a_declaration_of_another_kind_is_refused(on_path: Path) -> None:
    name = package(on_path, "steps_wrong", {"odd": "COMPONENT = 42\n"})
    with pytest.raises(ComponentError, match=r"steps_wrong\.odd\.COMPONENT is no StepKind"):
        list(Registry(name, "COMPONENT", StepKind))


def test_a_method_module_found_by_the_registry_is_a_call_routes_can_make(on_path: Path
                                                                         ) -> None:
    name = package(on_path, "methods_found", {
        "echo": METHOD_MODULE.format(key="Echo", rank=1),
        "shout": METHOD_MODULE.format(key="Shout", rank=0), "shared": "VALUE = 1\n"})
    found: Registry[Method] = Registry(name, "METHOD", Method)
    assert list(found) == ["Shout", "Echo"]
    route = create_model("Route", __base__=Schema, call=(call_schema(found.values()), ...))
    call = validate({"call": {"method": "Echo", "service": "x", "loud": True}}, route,
                    "p.yaml").call  # type: ignore[attr-defined]
    assert type(call) is found["Echo"].config and call.loud
    with pytest.raises(ConfigError) as refused:
        validate({"call": {"method": "Shout", "service": "x", "quiet": True}}, route, "p.yaml")
    assert str(refused.value) == "p.yaml: call.Shout.quiet: unknown key"
    with pytest.raises(ConfigError) as unknown:
        validate({"call": {"method": "Sing", "service": "x"}}, route, "p.yaml")
    assert str(unknown.value) == "p.yaml: call.method: 'Sing' is not one of Shout, Echo"


def test_the_registered_methods_are_the_calls_of_a_route() -> None:
    """Each method module found is in the pipeline schema's `call:` (a key of its own is
    refused under its name), in rank order; an unknown method's error lists them all."""
    assert {"Detect", "Transcribe", "Generate", "Infer", "Synthesize"} <= set(METHODS)
    ranks = [method.rank for method in METHODS.values()]
    assert ranks == sorted(ranks)
    for key in METHODS:
        with pytest.raises(ConfigError,
                           match=rf"routes\.people\.call\.{key}\.no_such_key: unknown key"):
            parse_pipeline(edited({"routes": {"people": {"call": {
                "method": key, "no_such_key": 1}}}}), "p.yaml")
    with pytest.raises(ConfigError) as unknown:
        parse_pipeline(edited({"routes": {"people": {"call": {"method": "Sing"}}}}), "p.yaml")
    assert str(unknown.value) == (f"p.yaml: routes.people.call.method: 'Sing' is not one of "
                                  f"{', '.join(METHODS)}")
