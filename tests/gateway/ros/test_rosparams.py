"""The gateway's ROS parameters, read by rcl from real --ros-args (-p, params files, remaps)
as `ros2 run` and `ros2 launch` pass them, on this session's private DDS domain."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
import yaml
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.config import load_pipeline
from oricf.gateway.ros.params import Settings, declare_settings, read_parameters
from oricf.gateway.shells.main import main
from tests.gateway.pipelines import PEOPLE_QA

FLAGS = Settings(config=str(PEOPLE_QA))
PIPELINES = config_dir() / "pipelines"


def ros(*args: str) -> list[str]:
    """rclpy's argument list for these ROS arguments, as split_ros_args makes it."""
    return ["oricf_gateway", "--ros-args", *args]


def loaded(settings: Settings) -> dict[str, str]:
    """Endpoint addresses and deadlines of the pipeline the settings give."""
    path, overlays = settings.files()
    config = load_pipeline(path, overlays, sets=settings.sets)
    return {f"{name}": f"{e.address} {e.deadline_ms}" for name, e in config.endpoints.items()}


def test_without_parameters_the_flags_stand(ros_env: dict[str, str]) -> None:
    flags = Settings(config=str(PEOPLE_QA), overlays=("a.yaml",), sets=("node_name=x",))
    assert read_parameters(ros("-r", "__node:=other"), flags) == flags


def test_parameters_override_the_flags_and_merge_in_order(
        ros_env: dict[str, str], tmp_path: Path) -> None:
    site = tmp_path / "site.yaml"
    site.write_text("endpoints: {asr: {address: 10.0.0.9:50052, deadline_ms: 1234}}\n")
    settings = read_parameters(ros(
        "-p", "config:=people_qa", "-p", "placement:=edge", "-p", f"overlays:=[{site}]",
        "-p", "sets:=[endpoints.llm.deadline_ms=777]"), FLAGS)
    assert settings == Settings("people_qa", "edge", (str(site),),
                                ("endpoints.llm.deadline_ms=777",))
    assert settings.files() == (PIPELINES / "people_qa.yaml",
                                [PIPELINES / "placement" / "edge.yaml", site])
    assert loaded(settings) == {"detector": "edge.local:50051 800",   # placement
                                "asr": "10.0.0.9:50052 1234",          # overlay, after it
                                "llm": "edge.local:50053 777"}         # set, last


def test_a_params_file_for_the_remapped_name_and_for_all_nodes(
        ros_env: dict[str, str], tmp_path: Path) -> None:
    """What a launch file passes: a params file, the node's name and namespace as remaps."""
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({
        "/**": {"ros__parameters": {"placement": "edge", "overlays": []}},
        "/robot1/front_gateway": {"ros__parameters": {"config": "fall_alert"}},
        "/robot1/someone_else": {"ros__parameters": {"config": "text_questions"}}}))
    flags = Settings(config=str(PEOPLE_QA), overlays=("flag.yaml",))
    settings = read_parameters(ros("-r", "__node:=front_gateway", "-r", "__ns:=/robot1",
                                   "--params-file", str(params)), flags)
    # `overlays: []` is an empty list that rcl reads as a value of no type: it still
    # replaces the flag's overlays.
    assert settings == Settings("fall_alert", "edge", (), ())
    assert settings.files()[0] == PIPELINES / "fall_alert.yaml"


@pytest.mark.parametrize(("argument", "message"), [
    ("config:=3", "parameter config: 3 is integer; expected a string"),
    ("placement:=[edge]", "parameter placement: ['edge'] is string array; expected a string"),
    ("overlays:=site.yaml", "parameter overlays: 'site.yaml' is string; expected a list of "
                            "strings"),
    ("sets:=true", "parameter sets: True is bool; expected a list of strings"),
])
def test_a_parameter_of_the_wrong_type_is_refused_by_name(
        ros_env: dict[str, str], argument: str, message: str) -> None:
    with pytest.raises(ConfigError) as error:
        read_parameters(ros("-p", argument), FLAGS)
    assert message in str(error.value)


def test_unknown_names_and_malformed_arguments_are_refused(ros_env: dict[str, str]) -> None:
    with pytest.raises(ConfigError, match=r"placement 'edgy': no such file in .*placement "
                                          r"\(shipped: edge, ollama, onboard, onboard_first, "
                                          r"tls\)"):
        read_parameters(ros("-p", "placement:=edgy"), FLAGS).files()
    with pytest.raises(ConfigError, match="config: empty"):
        read_parameters(ros("-p", "config:=''"), FLAGS).files()
    with pytest.raises(ConfigError, match=r"--ros-args: .*Couldn't parse parameter override"):
        read_parameters(ros("-p", "config"), FLAGS)


def test_a_parameter_the_gateway_does_not_have_is_named(
        ros_env: dict[str, str], caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="oricf"):
        settings = read_parameters(ros("-p", "placment:=edge", "-p", "use_sim_time:=false",
                                       "-p", "qos_overrides./camera.subscription.depth:=2"),
                                   FLAGS)
    assert settings == FLAGS
    assert [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING] == [
        "ignoring parameters the gateway does not have: placment (it has config, placement, "
        "overlays, sets)"]


def test_check_reads_the_parameters_and_a_bad_one_exits_2(
        ros_env: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--check", "--ros-args", "-p", "config:=fall_alert"]) == 0
    assert capsys.readouterr().out.startswith(f"{PIPELINES / 'fall_alert.yaml'}: OK (1 routes")
    with pytest.raises(ConfigError, match="parameter overlays"):  # the entry points: exit 2
        main(["--check", "--ros-args", "-p", "overlays:=site.yaml"])


def test_the_running_node_shows_its_settings_read_only(ros_context: Context) -> None:
    node = Node("settings_shown", context=ros_context)
    try:
        declare_settings(node, Settings("people_qa", "edge", ("a.yaml", "b.yaml")))
        assert node.get_parameter("config").value == "people_qa"
        assert node.get_parameter("placement").value == "edge"
        assert node.get_parameter("overlays").value == ["a.yaml", "b.yaml"]
        assert node.get_parameter("sets").value == []  # set, so `ros2 param dump` works
        assert node.describe_parameter("sets").read_only
        result = node.set_parameters([Parameter("config", value="fall_alert")])[0]
        assert not result.successful
        assert node.get_parameter("config").value == "people_qa"
    finally:
        node.destroy_node()
