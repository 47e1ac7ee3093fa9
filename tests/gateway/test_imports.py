"""The routing core imports without ROS; only the node and its converters need rclpy."""

from __future__ import annotations

import subprocess
import sys

from oricf.gateway.shells.main import split_ros_args

CORE = ["config", "methods", "methods.detect", "methods.transcribe", "methods.generate",
        "methods.infer", "values", "post", "products", "endpoints", "worker", "route",
        "pipeline", "metrics", "throttle", "ros", "ros.dds", "ros.frame_loss", "ros.process",
        "ros.params", "topics.cdr", "topics.codec", "recording.recorder", "recording.replay",
        "shells.main", "sources", "sources.video", "sources.video_source", "sinks",
        "channels.server",
        "shells.without_ros", "actuation.actuation", "actuation.senders", "operations.view",
        "operations.client", "ros.commands", "host.gateway", "host.surfaces", "shells.embedded",
        "shells.ros"]


def test_core_modules_do_not_import_ros() -> None:
    imports = "; ".join(f"import oricf.gateway.{name}" for name in CORE)
    check = ("import sys; bad = sorted(m for m in sys.modules if m.split('.')[0] in "
             "('rclpy', 'sensor_msgs', 'std_msgs')); assert not bad, bad")
    result = subprocess.run([sys.executable, "-c", f"{imports}; {check}"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_ros_arguments_go_to_rclpy() -> None:
    ours, ros = split_ros_args(["--config", "p.yaml", "--ros-args", "-r", "__node:=gw"])
    assert ours == ["--config", "p.yaml"]
    assert ros == ["oricf_gateway", "--ros-args", "-r", "__node:=gw"]
    assert split_ros_args(["--check"]) == (["--check"], [])


def test_the_gateway_sets_grpc_polling_before_grpc_loads() -> None:
    """grpcio reads GRPC_EXPERIMENTS once, when it loads: `oricf gateway` (through the CLI
    or as a ROS node) must not load it before main() has turned the EventEngine client off
    (oricf.gateway.ros.process), or every reply wakes the EventEngine's threads."""
    assert_grpc_polls_in_calling_thread(
        "import oricf.cli, oricf.gateway.shells.main as gateway\n"
        "assert 'grpc' not in sys.modules, 'grpc loaded on import'\n"
        "assert gateway.main(['--check']) == 0\n")


def test_oricf_mcp_sets_grpc_polling_before_grpc_loads() -> None:
    """`oricf mcp --config` runs the pipeline in its own process like `oricf gateway`, but its
    module loads grpc on import: the CLI turns the EventEngine client off before that."""
    assert_grpc_polls_in_calling_thread(
        "import oricf.cli\n"
        "try:\n"
        "    oricf.cli.main(['mcp', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n")


def assert_grpc_polls_in_calling_thread(steps: str) -> None:
    """Runs `steps` in a fresh interpreter without GRPC_EXPERIMENTS; afterwards grpc must
    be loaded with the EventEngine client off (set before it loaded: once grpc is loaded,
    poll_in_calling_thread leaves the variable unset)."""
    script = ("import os, sys\n"
              "os.environ.pop('GRPC_EXPERIMENTS', None)\n"
              f"{steps}"
              "assert 'grpc' in sys.modules\n"
              "assert os.environ['GRPC_EXPERIMENTS'] == '-event_engine_client'\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
