"""Every `oricf bench` command after the README's set-up (`scripts/setup.sh`: the core
dependencies and its default extras, nothing more).

The tests run in the full (dev) environment and take the rest away: every installed
distribution that the README's set-up does not bring (computed from pyproject.toml's
requirements and setup.sh's extras, through each distribution's own metadata) is made
unimportable in a child interpreter by a meta-path finder in a sitecustomize on its
PYTHONPATH. There each benchmark's --help runs, every module of oricf.bench imports, and
`oricf bench models` runs to its end, skipping the back end it cannot load; a benchmark that
needs a package beyond the set-up says so in one line. And statically: every third-party
import in bench/ is declared for that set-up, or sits in a function that first calls
`need()` with the extra that declares it.
"""

from __future__ import annotations

import ast
import importlib.metadata
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterable, Iterator
from functools import cache
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from oricf.bench.rtsp_camera import SERVER
from oricf.cli import BENCHMARKS

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "bench"
# What `python -m venv` puts into every environment before setup.sh installs anything.
VENV_OWN = {"pip", "setuptools"}
TRACEBACK = "Traceback (most recent call last)"
BLOCKER = '''import sys

BLOCKED = frozenset({blocked!r})


class NotInstalled:
    """Imports of a package outside the README's set-up fail as if it were absent."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, NotInstalled)
'''


@cache
def pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


@cache
def readme_extras() -> list[str]:
    """The extras that `scripts/setup.sh` (without --dev) installs: its EXTRAS, and the ROS
    extra that scripts/ros-source.sh chooses on this machine (ros, ros-kilted, or none)."""
    match = re.search(r'^EXTRAS="([^"]+)"', (ROOT / "scripts/setup.sh").read_text(), re.M)
    assert match, "scripts/setup.sh sets EXTRAS"
    decided = subprocess.run([str(ROOT / "scripts/ros-source.sh")], capture_output=True,
                             text=True, timeout=60, check=False)
    assert decided.returncode == 0, decided.stderr
    source, _, extra = decided.stdout.split("\n")[0].split()[:3]
    return [*match.group(1).split(","), *([extra] if source == "wheels" else [])]


def requirements(extras: Iterable[str]) -> list[str]:
    """pyproject's core requirements and those of the extras named."""
    extra_lists = pyproject()["project"]["optional-dependencies"]
    return [*pyproject()["project"]["dependencies"], *(r for e in extras for r in extra_lists[e])]


def declared(extras: Iterable[str]) -> set[str]:
    """The distributions these requirements name; a metapackage among them (no module of
    its own, as ros-jazzy-rclpy for ros-rclpy) stands for those it requires."""
    names = {canonicalize_name(Requirement(r).name) for r in requirements(extras)}
    providing = set().union(*providers().values())
    for name in [n for n in names if n not in providing]:
        try:
            names |= {canonicalize_name(Requirement(r).name)
                      for r in importlib.metadata.requires(name) or []
                      if not Requirement(r).marker}
        except importlib.metadata.PackageNotFoundError:
            continue
    return names


def closure(wanted: Iterable[str]) -> set[str]:
    """The installed distributions these requirements bring, transitively."""
    seen: set[tuple[str, str]] = set()
    todo = [(Requirement(r), "") for r in wanted]
    while todo:
        requirement, extra = todo.pop()
        if requirement.marker and not requirement.marker.evaluate({"extra": extra}):
            continue
        name = canonicalize_name(requirement.name)
        for asked in ("", *sorted(requirement.extras)):
            if (name, asked) in seen:
                continue
            seen.add((name, asked))
            try:
                todo += [(Requirement(r), asked) for r in importlib.metadata.requires(name) or []]
            except importlib.metadata.PackageNotFoundError:
                continue
    return {name for name, _ in seen}


@cache
def providers() -> dict[str, set[str]]:
    """Top-level module -> the installed distributions that provide it."""
    return {module: {canonicalize_name(d) for d in dists}
            for module, dists in importlib.metadata.packages_distributions().items()}


@cache
def outside_readme_set_up() -> frozenset[str]:
    """Top-level modules that only distributions outside the README's set-up provide."""
    installed = {canonicalize_name(d.metadata["Name"]) for d in importlib.metadata.distributions()}
    kept = closure(requirements(readme_extras())) | VENV_OWN | {"oricf"}
    absent = installed - kept
    return frozenset(m for m, dists in providers().items() if dists and dists <= absent)


def readme_env(folder: Path, also_blocked: Iterable[str] = ()) -> dict[str, str]:
    """An environment whose interpreter cannot import what the README's set-up lacks."""
    blocked = sorted(outside_readme_set_up() | set(also_blocked))
    (folder / "sitecustomize.py").write_text(BLOCKER.format(blocked=blocked))
    path = os.pathsep.join(p for p in (str(folder), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path}


def oricf(env: dict[str, str], *args: str, timeout: float = 120
          ) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "oricf", *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_the_dev_only_packages_are_blocked(tmp_path: Path) -> None:
    """The harness itself: a package that only the dev extra brings does not import."""
    assert "pytest" in outside_readme_set_up() and "grpc" not in outside_readme_set_up()
    done = subprocess.run([sys.executable, "-c", "import grpc, yaml; import pytest"],
                          env=readme_env(tmp_path), capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "No module named 'pytest'" in done.stderr, done.stderr


# Every benchmark's --help through the `oricf` command's main() in one child interpreter
# (one set of imports instead of one per benchmark): {name: [exit code, output]}.
HELPS = """import contextlib, io, json, sys, traceback
from oricf.cli import main
results = {}
for name in sys.argv[1:]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            code = main(["bench", name, "--help"])
        except SystemExit as exc:
            code = exc.code
        except BaseException:
            traceback.print_exc()
            code = "raised"
    results[name] = [code, out.getvalue()]
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def helps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[int, str]]:
    env = readme_env(tmp_path_factory.mktemp("readme-set-up"))
    done = subprocess.run([sys.executable, "-c", HELPS, *BENCHMARKS], env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return {name: (code, output) for name, (code, output) in json.loads(done.stdout).items()}


@pytest.mark.parametrize("name", BENCHMARKS)
def test_each_benchmark_explains_itself_after_the_readme_set_up(
        helps: dict[str, tuple[int, str]], name: str) -> None:
    code, output = helps[name]
    assert code == 0 and TRACEBACK not in output, output
    assert f"usage: oricf bench {name}" in output, output


def test_every_bench_module_imports_after_the_readme_set_up(tmp_path: Path) -> None:
    modules = [f"oricf.bench.{p.stem}" for p in sorted(BENCH.glob("*.py"))
               if p.name not in ("__init__.py", SERVER.name)]
    program = f"import importlib\nfor m in {modules!r}:\n    importlib.import_module(m)\n"
    done = subprocess.run([sys.executable, "-c", program], env=readme_env(tmp_path),
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr


def test_bench_models_skips_openvino_when_it_is_not_installed(tmp_path: Path) -> None:
    done = oricf(readme_env(tmp_path, {"openvino"}), "bench", "models", "--frames", "3",
                 timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "openvino: not installed (pip install 'oricf[openvino]'); skipped" in done.stdout
    assert "onnxruntime 2 threads" in done.stdout and "outputs agree" in done.stdout
    assert TRACEBACK not in done.stderr, done.stderr


def test_a_benchmark_that_needs_an_extra_names_it_in_one_line(tmp_path: Path) -> None:
    """Before measuring for minutes, `bench offload` finds that it cannot draw Figure 1."""
    done = oricf(readme_env(tmp_path, {"matplotlib"}), "bench", "offload", "--quick",
                 "--out", str(tmp_path / "out"))
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "needs matplotlib, which is not installed (pip install 'oricf[figures]')" in lines[0]
    assert not (tmp_path / "out").exists()


def test_a_missing_import_of_a_benchmark_is_one_line_not_a_traceback(tmp_path: Path) -> None:
    """Where a dependency is absent after all (an installation without it), the benchmark's
    import failing is named in one line."""
    done = oricf(readme_env(tmp_path, {"psutil"}), "bench", "edge", "--help")
    assert done.returncode == 2, done.stdout + done.stderr
    assert TRACEBACK not in done.stderr, done.stderr
    assert "oricf bench edge needs psutil, which is not installed (pip install psutil)" in \
        done.stderr


# --- every third-party import of bench/ is declared ---------------------------------------


def imports(tree: ast.Module) -> Iterator[tuple[str, int, ast.AST | None]]:
    """(top-level module, line, innermost enclosing function or None) of every absolute
    import of a module outside the standard library and ORICF."""
    def walk(node: ast.AST, function: ast.AST | None) -> Iterator[tuple[str, int, ast.AST | None]]:
        for child in ast.iter_child_nodes(node):
            inner = child if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef) \
                else function
            names: list[str] = []
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom) and child.level == 0 and child.module:
                names = [child.module]
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in ("oricf", "__future__"):
                    yield top, child.lineno, function
            yield from walk(child, inner)
    yield from walk(tree, None)


def needs(function: ast.AST, line: int) -> set[tuple[str, str]]:
    """(module, extra) of each `need(MODULE, EXTRA, ...)` call in function before line."""
    found = set()
    for node in ast.walk(function):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "need" \
                and node.lineno < line and len(node.args) >= 2 \
                and all(isinstance(a, ast.Constant) for a in node.args[:2]):
            found.add((node.args[0].value, node.args[1].value))
    return found


def undeclared(path: Path) -> list[str]:
    readme = declared(readme_extras())
    extras = pyproject()["project"]["optional-dependencies"]
    problems = []
    for module, line, function in imports(ast.parse(path.read_text())):
        where = f"{path.name}:{line}: {module}"
        dists = providers().get(module)
        if not dists:
            problems.append(f"{where}: no installed distribution provides it")
        elif dists & readme:
            continue
        elif function is None:
            problems.append(f"{where}: outside the README's set-up, imported at module level")
        elif not any(m == module and e in extras and dists & declared([e])
                     for m, e in needs(function, line)):
            problems.append(f"{where}: outside the README's set-up; the function must call "
                            f"need({module!r}, EXTRA, ...) first, EXTRA an extra declaring it")
    return problems


def test_every_third_party_import_in_bench_is_declared_for_the_readme_set_up() -> None:
    # SERVER runs under the system Python (GStreamer's bindings), not in oricf's environment.
    files = [p for p in sorted(BENCH.glob("*.py")) if p.name != SERVER.name]
    problems = [problem for path in files for problem in undeclared(path)]
    assert not problems, "\n".join(problems)


def test_the_import_check_catches_an_undeclared_import(tmp_path: Path) -> None:
    module = tmp_path / "example.py"
    module.write_text("import yaml\nimport pytest\n\n\ndef figure():\n    import matplotlib\n\n\n"
                      "def guarded():\n    need('matplotlib', 'figures', 'a figure')\n"
                      "    import matplotlib\n")
    assert [p.split(": ", 1)[0] for p in undeclared(module)] == ["example.py:2",
                                                                  "example.py:6"]
