"""The component registries: the modules a kind's package lists are its components, in rank
order, and exactly the modules there that declare one; a listed module that is missing or
declares nothing, and two modules that declare one key, are refused, naming them. Loading
the pipeline schema imports the declarations only: no device, stream or codec."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pydantic import create_model

from oricf.config import Schema, validate
from oricf.errors import ConfigError
from oricf.gateway.components import (
    METHODS,
    SINKS,
    SOURCES,
    STEPS,
    ComponentError,
    Method,
    Registry,
    StepKind,
)
from oricf.gateway.config import PostStep, call_schema, parse_pipeline
from tests.gateway.test_config import MINIMAL, edited

STEP_MODULE = """
from oricf.gateway.components import Step, StepKind

class Nothing(Step):
    reads = frozenset()

    def run(self, record):
        pass

COMPONENT = StepKind({key!r}, dict, Nothing, rank={rank})
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


def package(tmp_path: Path, name: str, modules: dict[str, str],
            listed: tuple[str, ...] | None = None) -> str:
    """A package of these modules whose COMPONENTS lists `listed` (by default, all)."""
    folder = tmp_path / name
    folder.mkdir()
    names = tuple(modules) if listed is None else listed
    (folder / "__init__.py").write_text(f"COMPONENTS = {names!r}\n")
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


def test_only_the_listed_modules_are_imported(on_path: Path) -> None:
    """A module the package does not list (a helper, an implementation) is not imported."""
    name = package(on_path, "steps_found", {
        "b": STEP_MODULE.format(key="b", rank=1), "a": STEP_MODULE.format(key="a", rank=2),
        "helper": "raise ImportError('a helper is never imported by the registry')\n"},
        listed=("a", "b"))
    found: Registry[StepKind] = Registry(name, "COMPONENT", StepKind)
    assert list(found) == ["b", "a"]
    assert f"{name}.helper" not in sys.modules


def test_a_listed_module_that_is_missing_or_declares_nothing_is_refused(on_path: Path
                                                                        ) -> None:
    missing = package(on_path, "steps_missing", {"a": STEP_MODULE.format(key="a", rank=1)},
                      listed=("a", "gone"))
    with pytest.raises(ComponentError, match=r"steps_missing\.COMPONENTS names "
                                             r"steps_missing\.gone, which does not exist"):
        list(Registry(missing, "COMPONENT", StepKind))
    empty = package(on_path, "steps_empty", {"helper": "VALUE = 1\n"})
    with pytest.raises(ComponentError, match=r"steps_empty\.COMPONENTS names "
                                             r"steps_empty\.helper, which declares no "
                                             r"COMPONENT"):
        list(Registry(empty, "COMPONENT", StepKind))


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
        "shout": METHOD_MODULE.format(key="Shout", rank=0), "shared": "VALUE = 1\n"},
        listed=("echo", "shout"))
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


REGISTRIES: dict[str, Registry[Any]] = {
    "sources": SOURCES, "sinks": SINKS, "post": STEPS, "methods": METHODS}
ATTRS = {"sources": "COMPONENT", "sinks": "COMPONENT", "post": "COMPONENT", "methods": "METHOD"}


def declaring_modules(registry: Registry[Any], attr: str) -> set[str]:
    """The modules of the registry's package whose source assigns `attr` at module level,
    read without importing them."""
    folder = Path(sys.modules[registry.package].__file__ or "").parent
    found = set()
    for path in sorted(folder.glob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        targets = [t for node in tree.body if isinstance(node, ast.Assign | ast.AnnAssign)
                   for t in (node.targets if isinstance(node, ast.Assign) else [node.target])]
        if any(isinstance(t, ast.Name) and t.id == attr for t in targets):
            found.add(f"{registry.package}.{path.stem}")
    return found


@pytest.mark.parametrize("kind", list(REGISTRIES))
def test_each_package_lists_exactly_its_component_modules(kind: str) -> None:
    """A component module without its line in COMPONENTS, or a line without its module,
    fails here: the list is what the schema is built from."""
    registry = REGISTRIES[kind]
    listed = registry.modules()
    assert len(set(listed)) == len(listed), f"{registry.package}.COMPONENTS repeats a module"
    assert set(listed) == declaring_modules(registry, ATTRS[kind])
    assert len(registry) == len(listed)  # each listed module declares a key of its own


# Modules that read devices, streams and codecs: what runs a component, never its schema.
HEAVY = ["oricf.gateway.sources.audio_source", "oricf.gateway.sources.audio_device",
         "oricf.gateway.sources.wav", "oricf.gateway.sinks.speaker_sink",
         "oricf.gateway.sinks.speaker_device", "oricf.gateway.sources.video_source",
         "oricf.gateway.sources.http_stream", "oricf.gateway.sources.mjpeg",
         "oricf.gateway.control.source", "cv2", "sounddevice", "onnxruntime", "rclpy"]


def test_loading_the_schema_imports_no_device_stream_or_codec() -> None:
    """A fresh interpreter that loads the pipeline schema and validates a pipeline of one
    topic route has imported every component's declaration and none of what runs them."""
    script = ("import json, sys\n"
              "from oricf.gateway.config import parse_pipeline\n"
              f"config = parse_pipeline({MINIMAL!r}, 'p.yaml')\n"
              "assert list(config.routes) == ['people']\n"
              f"print(json.dumps(sorted(set({HEAVY!r}) & set(sys.modules))))\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            check=False)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == []
