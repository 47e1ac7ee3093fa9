"""No import cycle anywhere in the oricf namespace: services/, gateway/, bench/ and the stubs
included (scripts/namespace_view.py links them where Python imports them, so grimp sees the
whole namespace). The layers themselves are import-linter's contracts in pyproject.toml,
which scripts/test.sh checks with lint-imports on the same view.

Imports under `if TYPE_CHECKING:` count: they do not run, but a cycle through one is still
two modules that each need the other, and moving the shared type out of the pair breaks it.

docs/architecture.md draws each layers contract and walks through the code by its modules,
classes and functions: the page's diagrams are the contracts, and what it names exists.
"""

from __future__ import annotations

import ast
import functools
import json
import os
import re
import subprocess
import sys
from collections.abc import Collection, Iterator
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import pytest

from oricf.config import REPO_ROOT
from tests.support.scripts import load_script

# Run in a fresh interpreter: grimp finds `oricf` with importlib, and this process has
# imported it already from oricf/ alone.
DUMP_GRAPH = """
import json, sys
import grimp
graph = grimp.build_graph("oricf", cache_dir=None, exclude_type_checking_imports=False)
json.dump({m: sorted(graph.find_modules_directly_imported_by(m)) for m in graph.modules},
          sys.stdout)
"""

Graph = dict[str, list[str]]


@pytest.fixture(scope="module")
def graph(tmp_path_factory: pytest.TempPathFactory) -> Graph:
    root = tmp_path_factory.mktemp("namespace")
    load_script("namespace_view").build_view(root)
    done = subprocess.run([sys.executable, "-c", DUMP_GRAPH], cwd=root, capture_output=True,
                          text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(root)})
    assert done.returncode == 0, done.stderr
    imports: Graph = json.loads(done.stdout)
    return imports


def strongly_connected(graph: Graph) -> Iterator[list[str]]:
    """Tarjan's strongly connected components, without recursion."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(graph.get(start, ())))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            module, imported = work[-1]
            for other in imported:
                if other not in index:
                    index[other] = low[other] = len(index)
                    stack.append(other)
                    on_stack.add(other)
                    work.append((other, iter(graph.get(other, ()))))
                    break
                if other in on_stack:
                    low[module] = min(low[module], index[other])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[module])
                if low[module] == index[module]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == module:
                            break
                    yield sorted(component)


def a_cycle(graph: Graph, members: list[str]) -> list[str]:
    """One shortest path from the first member back to itself, inside the component."""
    inside = set(members)
    start = members[0]
    paths = {start: [start]}
    frontier = [start]
    while frontier:
        following = []
        for module in frontier:
            for other in graph.get(module, ()):
                if other == start:
                    return [*paths[module], start]
                if other in inside and other not in paths:
                    paths[other] = [*paths[module], other]
                    following.append(other)
        frontier = following
    raise AssertionError(f"no cycle through {start}")


def test_the_graph_holds_the_whole_namespace(graph: Graph) -> None:
    for module in ("oricf.cli", "oricf.audio.vad", "oricf.services.runtime.server",
                   "oricf.gateway.pipeline", "oricf.bench.llm", "oricf.v1.detector_pb2"):
        assert module in graph


def test_no_import_cycle(graph: Graph) -> None:
    cycles = [" -> ".join(a_cycle(graph, members))
              for members in strongly_connected(graph)
              if len(members) > 1 or members[0] in graph.get(members[0], ())]
    assert not cycles, "import cycles:\n  " + "\n  ".join(cycles)


def package_of(module: str, packages: Collection[str]) -> str | None:
    """The package of `packages` that holds `module`, if any."""
    return next((p for p in packages if module == p or module.startswith(p + ".")), None)


def test_no_model_service_imports_another(graph: Graph) -> None:
    """What two services share lives in services/runtime or the library (oricf.models)."""
    from oricf.services import SERVICES

    packages = {f"oricf.services.{name}" for name in SERVICES}
    crossings = []
    for module, imported in graph.items():
        mine = package_of(module, packages)
        crossings += [f"{module} -> {other}" for other in imported
                      if mine and package_of(other, packages) not in (None, mine)]
    assert not crossings, "a service imports another:\n  " + "\n  ".join(sorted(crossings))


def test_the_independence_contract_names_every_service() -> None:
    """pyproject.toml's contract for lint-imports lists the packages of SERVICES, no fewer."""
    from oricf.services import SERVICES

    pyproject = REPO_ROOT / "pyproject.toml"
    contracts = tomllib.loads(pyproject.read_text())["tool"]["importlinter"]["contracts"]
    independent = [set(c["modules"]) for c in contracts if c["type"] == "independence"]
    services = [modules for modules in independent
                if any(m.startswith("oricf.services.") for m in modules)]
    assert services == [{f"oricf.services.{name}" for name in SERVICES}]


SURFACES = ("oricf.gateway.agents", "oricf.gateway.api", "oricf.gateway.live_view")


def test_no_gateway_surface_imports_another(graph: Graph) -> None:
    """MCP, the control API and the live view read the core (oricf.gateway.operations) and
    act through it (oricf.gateway.actuation), never through each other."""
    crossings = []
    for module, imported in graph.items():
        mine = package_of(module, SURFACES)
        crossings += [f"{module} -> {other}" for other in imported
                      if mine and package_of(other, SURFACES) not in (None, mine)]
    assert not crossings, "a surface imports another:\n  " + "\n  ".join(sorted(crossings))


def test_actuation_and_operations_import_no_surface_and_no_ros(graph: Graph) -> None:
    """Everything that can move the robot, and the operations every surface carries, sit
    under the surfaces and under ROS (its agent sender uses the policy, never the reverse)."""
    core = ("oricf.gateway.actuation", "oricf.gateway.operations")
    above = (*SURFACES, "oricf.gateway.ros")
    crossings = [f"{module} -> {other}" for module, imported in graph.items()
                 if package_of(module, core) for other in imported
                 if package_of(other, above)]
    assert not crossings, "imported from above:\n  " + "\n  ".join(sorted(crossings))


# docs/architecture.md draws the layer contracts; a diagram's first layer names its contract.
ARCHITECTURE = REPO_ROOT / "docs" / "architecture.md"


def diagrams(text: str) -> dict[str, list[str]]:
    """The layer diagrams of the page, by their first layer: each a list of layers, a line
    `label  a : b | c` each (a line that starts blank continues the one before)."""
    found = {}
    for block in re.findall(r"```\n(.*?)```", text, re.S):
        layers: list[str] = []
        for line in block.splitlines():
            if line[:1].isspace() and layers:
                layers[-1] += " " + line.strip()
            elif line.strip():
                layers.append(re.split(r"\s{2,}", line.strip(), maxsplit=1)[-1])
        if layers:
            found[" ".join(layers[0].split())] = [" ".join(layer.split()) for layer in layers]
    return found


def test_the_architecture_page_draws_the_layer_contracts() -> None:
    """Every layers contract of pyproject.toml is one diagram of docs/architecture.md, layer
    for layer, siblings and separators as the contract has them."""
    contracts = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text()
                              )["tool"]["importlinter"]["contracts"]
    drawn = diagrams(ARCHITECTURE.read_text())
    for contract in (c for c in contracts if c["type"] == "layers"):
        layers = [" ".join(layer.split()) for layer in contract["layers"]]
        assert drawn.get(layers[0]) == layers, contract["name"]


def defined(module: Path, names: list[str]) -> bool:
    """Whether `names` (a top-level name, then a name in its class body) are defined in the
    module's source."""
    body = ast.parse(module.read_text()).body
    for name in names[:2]:
        found = [node for node in body if name in defined_names(node)]
        if not found:
            return False
        body = getattr(found[0], "body", [])
    return True


def defined_names(node: ast.stmt) -> set[str]:
    if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
        return {node.name}
    if isinstance(node, ast.Assign):
        return {t.id for t in node.targets if isinstance(t, ast.Name)}
    if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
        return {node.target.id}
    if isinstance(node, ast.ImportFrom | ast.Import):
        return {alias.asname or alias.name.split(".")[0] for alias in node.names}
    if isinstance(node, ast.For | ast.If | ast.With | ast.Try):
        return {name for child in node.body for name in defined_names(child)}
    return set()


def module_file(parts: list[str], roots: list[Path]) -> tuple[Path, list[str]] | None:
    """The module that the longest prefix of `parts` names under the first of `roots` that
    holds one, and the names after it."""
    for root in roots:
        path, rest = root, list(parts)
        while rest and (path / rest[0]).is_dir():
            path = path / rest.pop(0)
        if rest and (path / f"{rest[0]}.py").is_file():
            return path / f"{rest.pop(0)}.py", rest
        if path != root and (path / "__init__.py").is_file():
            return path / "__init__.py", rest
    return None


def named_in_architecture() -> Iterator[str]:
    """The code the page names in backticks: files and folders (`ros/camera.py`,
    `services/runtime/`), a module's name as `topics/codec.input_loader`, and dotted names
    (`route.Route.process`, `oricf.audio.vad`); not placeholders (`services/NAME/`)."""
    for token in re.findall(r"`([\w./]+)`", ARCHITECTURE.read_text()):
        if "NAME" not in token and (token.endswith((".py", "/"))
                                    or re.fullmatch(r"[\w/]+/\w+(\.\w+)+", token)
                                    or re.fullmatch(r"\w+(\.\w+)+", token)):
            yield token


def resolved(token: str) -> bool | None:
    """Whether the code a token names is there; None for a dotted name that names no module
    of the gateway or the namespace (prose, a file name such as `people_qa.yaml`)."""
    roots = [REPO_ROOT, REPO_ROOT / "gateway", REPO_ROOT / "services"]
    if token.endswith((".py", "/")) or any((root / token).is_file() for root in roots):
        return any((root / token).exists() for root in roots)
    path, _, dotted = token.rpartition("/")
    parts = dotted.split(".")
    if path:
        parts, search = [*path.split("/"), *parts], roots
    elif parts[0] == "oricf":  # the namespace: oricf.gateway.x is gateway/x
        parts = parts[1:]
        if parts[0] in ("v1", "oip"):
            return None  # generated stubs
        if parts[0] not in ("gateway", "services", "bench"):
            parts = ["oricf", *parts]
        search = [REPO_ROOT]
    else:
        search = [REPO_ROOT / "gateway"]
    found = module_file(parts, search)
    if found is None:
        if path or token.startswith("oricf."):
            return False
        return defined_anywhere(parts) if parts[0].isidentifier() else None
    module, names = found
    return not names or defined(module, names)


@functools.cache
def sources() -> dict[str, list[ast.Module]]:
    """Every module of the library, the gateway and the services, by its file's stem."""
    found: dict[str, list[ast.Module]] = {}
    for folder in ("oricf", "gateway", "services"):
        for path in (REPO_ROOT / folder).rglob("*.py"):
            found.setdefault(path.stem, []).append(ast.parse(path.read_text()))
    return found


def defined_anywhere(parts: list[str]) -> bool:
    """`Class.name`: a class of that name defines `name` (in its body, or as `self.name`);
    `module.name`: a module of that name (in any package) defines it."""
    first, name = parts[0], parts[1]
    if first[0].islower():
        return any(name in defined_names(node) for module in sources().get(first, [])
                   for node in module.body)
    classes = [node for modules in sources().values() for module in modules
               for node in ast.walk(module)
               if isinstance(node, ast.ClassDef) and node.name == first]
    return any(name in defined_names(node) or name in assigned_to_self(node)
               for cls in classes for node in cls.body)


def assigned_to_self(node: ast.stmt) -> set[str]:
    return {target.attr for child in ast.walk(node)
            for target in getattr(child, "targets", [getattr(child, "target", None)])
            if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name)
            and target.value.id == "self"}


def test_every_module_and_name_the_architecture_page_gives_exists() -> None:
    """A module moved or a class renamed is a page that lies: each path the page names is a
    file or folder (of the repository, the gateway or the services), each dotted name under
    `oricf` or a gateway module a module, a name defined in it, or a name in that class."""
    missing = [token for token in named_in_architecture() if resolved(token) is False]
    assert not missing, "docs/architecture.md names what is not there: " + ", ".join(missing)
