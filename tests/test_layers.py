"""No import cycle anywhere in the oricf namespace: services/, gateway/, bench/ and the stubs
included (scripts/namespace_view.py links them where Python imports them, so grimp sees the
whole namespace). The layers themselves are import-linter's contracts in pyproject.toml,
which scripts/test.sh checks with lint-imports on the same view.

Imports under `if TYPE_CHECKING:` count: they do not run, but a cycle through one is still
two modules that each need the other, and moving the shared type out of the pair breaks it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Collection, Iterator

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
