"""ros/oricf_gateway: a valid format-3 manifest, what `colcon build` installs, and the
installed `gateway` executable found and run as `ros2 run oricf_gateway gateway` does."""

from __future__ import annotations

import importlib.metadata
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import yaml
from catkin_pkg.package import parse_package
from rcl_interfaces.msg import Log, ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.context import Context
from rclpy.node import Node

from oricf.config import config_dir
from tests.gateway.ros.gateway_node import spinning, wait_for
from tests.gateway.ros.rosout import next_line, rosout_reader
from tests.ros.conftest import PACKAGE, Workspace

PIPELINES = config_dir() / "pipelines"


def test_the_manifest_is_a_valid_format_3_ament_python_package() -> None:
    manifest = parse_package(str(PACKAGE))  # the parser colcon, rosdep and bloom use
    manifest.validate()
    assert (manifest.package_format, manifest.name) == (3, PACKAGE.name)
    assert manifest.get_build_type() == "ament_python"
    assert manifest.version == importlib.metadata.version("oricf")
    assert {d.name for d in manifest.exec_depends} >= {
        "rclpy", "rcl_interfaces", "lifecycle_msgs", "std_msgs", "sensor_msgs", "launch",
        "launch_ros"}
    assert manifest.maintainers and manifest.licenses == ["Apache-2.0"]
    # format 3's element order: name, version, description, maintainer, license
    tags = [e.tag for e in ElementTree.parse(PACKAGE / "package.xml").getroot()]
    assert tags[:5] == ["name", "version", "description", "maintainer", "license"]


def test_colcon_installs_the_marker_manifest_launch_file_and_executable(
        workspace: Workspace) -> None:
    prefix = workspace.prefix
    assert (workspace.install / "setup.sh").is_file()
    assert (prefix / "share/ament_index/resource_index/packages/oricf_gateway").is_file()
    for name in ("package.xml", "launch/people_qa.launch.py", "launch/lifecycle.launch.py"):
        assert (prefix / "share/oricf_gateway" / name).read_bytes() == \
            (PACKAGE / name).read_bytes()
    executable = prefix / "lib/oricf_gateway/gateway"
    assert os.access(executable, os.X_OK)
    # run by the Python that ran colcon: the one that has oricf
    assert executable.read_text().splitlines()[0] == f"#!{sys.executable}"
    # installed explicitly, not by colcon-ros's fallback (which warns it will go away)
    assert "doesn't explicitly install" not in workspace.build_log
    # nothing written into the source folder
    assert sorted(p.name for p in PACKAGE.iterdir()) == [
        "launch", "package.xml", "resource", "setup.cfg", "setup.py"]


def gateway_executable(workspace: Workspace) -> Path:
    """What `ros2 run oricf_gateway gateway` finds: <prefix from the ament index>/lib/<pkg>."""
    find = ("from ament_index_python.packages import get_package_prefix; "
            "print(get_package_prefix('oricf_gateway'))")
    prefix = subprocess.run([sys.executable, "-c", find], env=workspace.env(), check=True,
                            capture_output=True, text=True).stdout.strip()
    assert Path(prefix) == workspace.prefix
    return Path(prefix) / "lib" / "oricf_gateway" / "gateway"


def test_the_installed_executable_reads_its_parameters(workspace: Workspace,
                                                       ros_env: dict[str, str]) -> None:
    gateway = gateway_executable(workspace)
    env = {**workspace.env(), **ros_env}
    check = subprocess.run([gateway, "--check", "--ros-args", "-p", "config:=fall_alert",
                            "-p", "placement:=edge"], env=env, capture_output=True, text=True,
                           timeout=60)
    assert check.returncode == 0, check.stderr
    assert check.stdout.startswith(f"{PIPELINES / 'fall_alert.yaml'}: OK (1 routes")
    bad = subprocess.run([gateway, "--ros-args", "-p", "overlays:=site.yaml"], env=env,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2
    assert "parameter overlays: 'site.yaml' is string; expected a list of strings" in bad.stderr


def get_parameters(context: Context, node_name: str, names: list[str]) -> list[object]:
    """The values of a node's parameters, asked over its parameter service."""
    probe = Node("parameter_probe", context=context)
    try:
        with spinning(context, probe):
            client = probe.create_client(GetParameters, f"{node_name}/get_parameters")
            assert client.wait_for_service(timeout_sec=10)
            future = client.call_async(GetParameters.Request(names=names))
            wait_for(future.done)
            values = future.result().values
    finally:
        probe.destroy_node()
    return [v.string_value if v.type == ParameterType.PARAMETER_STRING
            else list(v.string_array_value or v.byte_array_value) for v in values]


def test_the_installed_gateway_runs_as_a_ros_node_and_logs_to_rosout(
        workspace: Workspace, ros_env: dict[str, str], ros_context: Context,
        tmp_path: Path) -> None:
    site = tmp_path / "site.yaml"
    site.write_text(yaml.safe_dump({"endpoints": {"asr": {"deadline_ms": 1234}}}))
    gateway = subprocess.Popen(
        [gateway_executable(workspace), "--ros-args", "-p", "placement:=edge",
         "-p", f"overlays:=[{site}]", "-r", "__ns:=/robot7"],
        env={**workspace.env(), **ros_env}, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        with rosout_reader(ros_context) as lines:
            started = next_line(lines, "robot7.oricf_gateway",
                                "gateway node oricf_gateway: 4 routes", timeout=60)
            assert (started.level, started.function) == (Log.INFO, "_activate")
            assert started.file.endswith("gateway/shells/ros_node.py")
            assert get_parameters(ros_context, "/robot7/oricf_gateway",
                                  ["config", "placement", "overlays", "sets"]) == [
                str(PIPELINES / "people_qa.yaml"), "edge", [str(site)], []]
        time.sleep(0.5)  # past rclpy's signal handler set-up, long done by now anyway
        gateway.send_signal(signal.SIGTERM)
        code = gateway.wait(timeout=20)
        assert gateway.stdout is not None
        console = gateway.stdout.read()
    finally:
        if gateway.poll() is None:
            os.killpg(gateway.pid, signal.SIGKILL)
            gateway.wait(timeout=10)
    assert code == 0, console
    assert "[robot7.oricf_gateway]: endpoint detector: edge.local:50051" in console
    assert "endpoint asr: 127.0.0.1:50052, deadline 1234 ms" in console
    assert "gateway stopping" in console
    assert "Failed to publish" not in console and "Traceback" not in console
