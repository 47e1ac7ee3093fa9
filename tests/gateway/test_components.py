"""The component registries: every module of a kind's package that declares a component is
found, in rank order; two modules that declare one key are refused, naming both."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from oricf.gateway.components import STEPS, ComponentError, Registry, StepKind
from oricf.gateway.config import PostStep

STEP_MODULE = """
from oricf.gateway.components import Step, StepKind

def build(settings):
    return Step(frozenset(), None, lambda record: None)

COMPONENT = StepKind({key!r}, dict, build, rank={rank})
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
    for name in [m for m in sys.modules if m.startswith("steps_")]:
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
