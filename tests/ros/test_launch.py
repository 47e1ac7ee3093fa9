"""ros/oricf_gateway/launch/people_qa.launch.py, as far as it can be checked without `launch`
and `launch_ros` (not on the package index): it compiles, imports nothing from ORICF, passes
exactly the node's parameters, and its defaults make a valid pipeline."""

from __future__ import annotations

import ast
import py_compile
from pathlib import Path
from typing import Any

import yaml

from oricf.config import config_dir
from oricf.gateway.config import load_pipeline
from oricf.gateway.ros.params import DESCRIPTIONS, Settings
from tests.ros.conftest import PACKAGE

LAUNCH = PACKAGE / "launch" / "people_qa.launch.py"


def module(path: Path = LAUNCH) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


def assigned(name: str, path: Path = LAUNCH) -> ast.expr:
    """The value the launch file's top level assigns to `name`."""
    for node in module(path).body:
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] \
                == [name]:
            return node.value
    raise AssertionError(f"{path}: no {name} = ...")


def imported(path: Path = LAUNCH) -> set[str]:
    """The top-level packages the launch file imports."""
    tree = module(path)
    names = {(n.module or "").split(".")[0] for n in ast.walk(tree)
             if isinstance(n, ast.ImportFrom)}
    return names | {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import)
                    for a in n.names}


def test_it_compiles(tmp_path: Path) -> None:
    py_compile.compile(str(LAUNCH), cfile=str(tmp_path / "launch.pyc"), doraise=True)


def test_it_imports_only_launch_and_launch_ros() -> None:
    """`ros2 launch` runs with the ROS install's Python, which may not see `oricf`."""
    assert imported() == {"launch", "launch_ros"}


def test_its_parameters_are_the_nodes_and_its_arguments_those_and_ross_own() -> None:
    arguments: dict[str, tuple[str, str]] = ast.literal_eval(assigned("ARGUMENTS"))
    parameters = assigned("PARAMETER_TYPES")
    assert isinstance(parameters, ast.Dict)
    names = [ast.literal_eval(key) for key in parameters.keys if key is not None]
    assert names == list(DESCRIPTIONS)
    assert list(arguments) == [*DESCRIPTIONS, "namespace", "log_level"]
    assert [ast.unparse(v) for v in parameters.values] == ["str", "str", "list[str]",
                                                           "list[str]"]


def test_its_defaults_make_the_reference_pipeline_onboard() -> None:
    defaults: dict[str, Any] = {name: default for name, (default, _) in
                                ast.literal_eval(assigned("ARGUMENTS")).items()}
    # launch_ros reads a list-typed value as YAML, as here
    settings = Settings(defaults["config"], defaults["placement"],
                        tuple(yaml.safe_load(defaults["overlays"])),
                        tuple(yaml.safe_load(defaults["sets"])))
    path, overlays = settings.files()
    pipelines = config_dir() / "pipelines"
    assert (path, overlays) == (pipelines / "people_qa.yaml",
                                [pipelines / "placement" / "onboard.yaml"])
    config = load_pipeline(path, overlays)
    assert config.node_name == "oricf_gateway"
    assert {e.address.split(":")[0] for e in config.endpoints.values()} == {"127.0.0.1"}
    assert defaults["log_level"] == "info" and defaults["namespace"] == ""
