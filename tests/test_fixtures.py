"""Each fixture name means one thing across the suite.

A fixture that a conftest.py shares with its folder is not defined again anywhere below it (a
test module's `llm` with other settings would hide the session's `llm` from that module alone), a
session fixture's name is defined once, and every shipped service has its session fixture in
tests/conftest.py. The definitions are read from the source with ast, so the rule holds in every
file, the ones the default run deselects included.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from oricf.services import SERVICES

TESTS = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Definition:
    name: str
    scope: str
    path: Path  # from the folder above the suite's: tests/gateway/conftest.py
    line: int

    def __str__(self) -> str:
        return f"{self.path}:{self.line} ({self.scope})"


def fixture_decorator(decorator: ast.expr) -> ast.Call | None:
    """The call in @pytest.fixture(...) or @fixture(...); an empty one for a bare decorator."""
    target = decorator.func if isinstance(decorator, ast.Call) else decorator
    named = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
    if named != "fixture":
        return None
    return decorator if isinstance(decorator, ast.Call) else ast.Call(target, [], [])


def keyword(call: ast.Call, name: str) -> ast.expr | None:
    return next((k.value for k in call.keywords if k.arg == name), None)


def literal(node: ast.expr | None) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def fixtures_in(function: ast.FunctionDef | ast.AsyncFunctionDef
                ) -> Iterator[tuple[ast.expr | None, str]]:
    """(the name given to the fixture, or None for the function's own; its scope) per
    fixture decorator on the function."""
    for decorator in function.decorator_list:
        call = fixture_decorator(decorator)
        if call is not None:
            yield keyword(call, "name"), literal(keyword(call, "scope")) or "function"


def definitions(path: Path, root: Path) -> Iterator[Definition]:
    """The fixtures a file defines: decorated functions, and `x = factory("x")` where the
    module's factory makes a fixture named by its argument (tests/conftest.py's shared)."""
    tree = ast.parse(path.read_text(), str(path))
    path = path.relative_to(root.parent)
    factories: dict[str, str] = {}
    for node in ast.walk(tree):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for name, scope in fixtures_in(node):
            if name is None or literal(name) is not None:
                yield Definition(literal(name) or node.name, scope, path, node.lineno)
        for inner in ast.walk(node):
            if inner is not node and isinstance(inner, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for name, scope in fixtures_in(inner):
                    if isinstance(name, ast.Name):
                        factories[node.name] = scope
    for node in tree.body:
        call = node.value if isinstance(node, ast.Assign) else None
        if isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and \
                call.func.id in factories and call.args:
            made = literal(call.args[0])
            if made is not None:
                yield Definition(made, factories[call.func.id], path, node.lineno)


def suite(root: Path) -> list[Definition]:
    return [d for path in sorted(root.rglob("*.py")) for d in definitions(path, root)]


def conflicts(found: Iterable[Definition]) -> list[str]:
    """Each definition that gives a name a second meaning: below a conftest.py that shares
    that name with its folder, or anywhere for a session fixture's name."""
    found = list(found)
    wrong = []
    for shared in found:
        folder = shared.path.parent
        for other in found:
            if other == shared or other.name != shared.name:
                continue
            if shared.scope == "session" or (shared.path.name == "conftest.py"
                                            and other.path.is_relative_to(folder)):
                wrong.append(f"{other.name}: {other} gives {shared}'s name a second meaning")
    return sorted(set(wrong))


def test_no_fixture_name_has_two_meanings() -> None:
    assert conflicts(suite(TESTS)) == []


def test_every_shipped_service_has_its_session_fixture() -> None:
    conftest = definitions(TESTS / "conftest.py", TESTS)
    shared = {d.name for d in conftest if d.scope == "session"}
    assert set(SERVICES) <= shared, sorted(set(SERVICES) - shared)


def test_a_module_fixture_named_after_a_session_fixture_is_caught(tmp_path: Path) -> None:
    (tmp_path / "conftest.py").write_text(
        "import pytest\n\ndef shared(name):\n"
        "    @pytest.fixture(scope='session', name=name)\n"
        "    def service(): ...\n    return service\n\nllm = shared('llm')\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "conftest.py").write_text(
        "import pytest\n\n@pytest.fixture\ndef driver(): ...\n")
    (tmp_path / "sub" / "test_a.py").write_text(
        "import pytest\n\n@pytest.fixture(scope='module')\ndef llm(): ...\n\n"
        "@pytest.fixture(name='driver')\ndef other_driver(): ...\n")
    (tmp_path / "test_b.py").write_text(  # not below sub/: a name of its own here
        "import pytest\n\n@pytest.fixture\ndef driver(): ...\n")
    found = conflicts(suite(tmp_path))
    assert [line.split(":")[0] for line in found] == ["driver", "llm"], found
    assert all("sub/test_a.py" in line for line in found), found
