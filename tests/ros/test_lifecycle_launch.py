"""ros/oricf_gateway/launch/lifecycle.launch.py, as far as it can be checked without `launch`
and `launch_ros` (not on the package index): it compiles, imports nothing from ORICF, starts
the node with a flag `oricf gateway` takes for waiting unconfigured, takes people_qa's
arguments plus its own, and asks for configure, then activate only once configuring has
ended in inactive."""

from __future__ import annotations

import ast
import py_compile
from pathlib import Path

from oricf.config import config_dir
from oricf.gateway.config import load_pipeline
from oricf.gateway.shells.main import build_parser
from tests.ros.conftest import PACKAGE
from tests.ros.test_launch import assigned, imported, module

LAUNCH = PACKAGE / "launch" / "lifecycle.launch.py"


def test_it_compiles(tmp_path: Path) -> None:
    py_compile.compile(str(LAUNCH), cfile=str(tmp_path / "launch.pyc"), doraise=True)


def test_it_imports_only_launch_launch_ros_lifecycle_msgs_and_the_standard_library() -> None:
    assert imported(LAUNCH) == {"launch", "launch_ros", "lifecycle_msgs", "importlib",
                                "pathlib", "typing"}


def test_its_node_waits_unconfigured() -> None:
    flag = ast.literal_eval(assigned("MANAGED", LAUNCH))
    assert build_parser().parse_args(flag).lifecycle == "managed"


def test_its_arguments_are_people_qas_the_node_name_and_autostart() -> None:
    arguments = assigned("ARGUMENTS", LAUNCH)
    assert isinstance(arguments, ast.Dict)
    assert ast.unparse(arguments.values[0]) == "PEOPLE_QA.ARGUMENTS"  # the ** entry
    own = {ast.literal_eval(key): ast.literal_eval(value)
           for key, value in zip(arguments.keys[1:], arguments.values[1:], strict=True)
           if key is not None}
    assert list(own) == ["node_name", "autostart"]
    people_qa = load_pipeline(config_dir() / "pipelines" / "people_qa.yaml")
    assert own["node_name"][0] == people_qa.node_name  # the name launch reaches it by
    assert own["autostart"][0] == "true"


def test_it_configures_and_activates_only_at_the_end_of_configuring() -> None:
    tree = module(LAUNCH)
    transitions = [ast.unparse(n) for n in ast.walk(tree) if isinstance(n, ast.Attribute)
                   and n.attr.startswith("TRANSITION_")]
    assert sorted(transitions) == ["Transition.TRANSITION_ACTIVATE",
                                   "Transition.TRANSITION_CONFIGURE"]
    [handler] = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
                 and ast.unparse(n.func) == "OnStateTransition"]
    states = {k.arg: ast.literal_eval(k.value) for k in handler.keywords
              if k.arg in ("start_state", "goal_state")}
    assert states == {"start_state": "configuring", "goal_state": "inactive"}
    assert "TRANSITION_ACTIVATE" in ast.unparse(handler)
