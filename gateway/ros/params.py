"""The gateway's ROS parameters: which pipeline the node runs, said as to any ROS node.

The parameters are `config`, `placement`, `overlays` and `sets` (docs/ros.md, Parameters):
the flags of `oricf gateway` give their defaults, and a parameter given to the node
overrides its flag, as ROS overrides do.

Why a short-lived node reads them: ROS hands parameters to a node, resolved by rcl for the
node's name after remapping (`-p`, `/**` and `/NAME` sections of a params file), and rclpy
offers no way to read them without one. The pipeline must be loaded before the gateway node
exists: it names the node (`node_name`), and its routes are the node's topics. So a node of
a private context (no /rosout, no parameter services) reads the parameters and is destroyed;
the gateway node then declares the values it runs with as read-only parameters, for `ros2
param get`. Give its parameters under `/**` or under the name given by `-r __node:=NAME` or a
launch file's `name=`: a params-file section keyed by a pipeline's own `node_name` is
not seen, because that name is only known once the pipeline is loaded.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from oricf.config import config_dir
from oricf.errors import ConfigError

if TYPE_CHECKING:
    from rclpy.node import Node

log = logging.getLogger(__name__)

# The node that reads the parameters has the name the gateway's launch file and the shipped
# pipelines give; -r __node:=NAME renames it like any other node of the process.
SETTINGS_NODE = "oricf_gateway"
STRINGS = ("config", "placement")
STRING_LISTS = ("overlays", "sets")
DESCRIPTIONS = {
    "config": "pipeline YAML path, or the name of a shipped pipeline (people_qa, ...)",
    "placement": "placement overlay: a shipped name (onboard, edge, ...) or a YAML path; "
                 "empty for none",
    "overlays": "more YAML files merged on top of the pipeline, in order",
    "sets": "KEY=VALUE assignments applied last, like --set",
}
# Parameters rclpy declares on every node, or takes from overrides for QoS: not ours to judge.
ROS_OWN = ("use_sim_time", "start_type_description_service")


@dataclass(frozen=True)
class Settings:
    """What the gateway runs: the pipeline, its placement, overlays and assignments."""

    config: str
    placement: str = ""
    overlays: tuple[str, ...] = ()
    sets: tuple[str, ...] = ()

    def files(self) -> tuple[Path, list[Path]]:
        """The pipeline file and the files merged on top of it, in order."""
        if not self.config.strip():
            raise ConfigError("config: empty; give a pipeline YAML path or the name of a "
                              "shipped pipeline")
        pipelines = config_dir() / "pipelines"
        path = shipped_or_path(self.config, pipelines, "config")
        overlays = [Path(p).expanduser() for p in self.overlays]
        if self.placement.strip():
            overlays.insert(0, shipped_or_path(self.placement, pipelines / "placement",
                                               "placement"))
        return path, overlays


def shipped_or_path(value: str, folder: Path, what: str) -> Path:
    """A bare name (no folder, no .yaml) is a shipped file of folder; anything else a path."""
    value = value.strip()
    if "/" in value or value.endswith((".yaml", ".yml")):
        return Path(value).expanduser()
    shipped = folder / f"{value}.yaml"
    if not shipped.is_file():
        names = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
        raise ConfigError(f"{what} {value!r}: no such file in {folder} (shipped: {names}); "
                          f"give a YAML path for a file of your own")
    return shipped


def read_parameters(ros_args: list[str], defaults: Settings) -> Settings:
    """The settings the node's ROS parameters give, defaults where they give none.

    ros_args is rclpy's argument list (a program name, then --ros-args ...). Needs rclpy."""
    import rclpy
    from rclpy.context import Context
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.node import Node

    from oricf.gateway.ros.dds import use_dds_profile

    # Fast DDS reads its profiles file once per process, when the first participant is made:
    # this node's, so the gateway's profile must be chosen before it.
    use_dds_profile()
    context = Context()
    try:
        rclpy.init(args=ros_args, context=context)
    except (rclpy_implementation.RCLInvalidROSArgsError,
            rclpy_implementation.UnknownROSArgsError, RuntimeError) as exc:
        raise ConfigError(f"--ros-args: {exc}") from None
    try:
        node = Node(SETTINGS_NODE, context=context, enable_rosout=False,
                    start_parameter_services=False)
        try:
            return settings_from(given_parameters(node), defaults)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def given_parameters(node: Node) -> dict[str, Any]:
    """Every parameter the node was given (name -> rclpy Parameter), whatever its type.

    rclpy has no public accessor for a node's overrides: its own
    automatically_declare_parameters_from_overrides reads this attribute, and cannot declare
    an empty list (rcl reads `[]` as a value of no type)."""
    from rcl_interfaces.msg import ParameterDescriptor

    for name in DESCRIPTIONS:  # dynamically typed: a wrong type is ours to name, below
        node.declare_parameter(name, None, ParameterDescriptor(dynamic_typing=True))
    return dict(node._parameter_overrides)


def settings_from(given: dict[str, Any], defaults: Settings) -> Settings:
    """Settings from a node's parameters (name -> rclpy Parameter), checked for type."""
    from rclpy.parameter import Parameter

    ignored = sorted(name for name in given if name not in DESCRIPTIONS and
                     name not in ROS_OWN and not name.startswith("qos_overrides."))
    if ignored:
        log.warning("ignoring parameters the gateway does not have: %s (it has %s)",
                    ", ".join(ignored), ", ".join(DESCRIPTIONS))
    values: dict[str, Any] = {}
    for name in STRINGS:
        if name in given:
            parameter = given[name]
            if parameter.type_ != Parameter.Type.STRING:
                raise ConfigError(f"parameter {name}: {_wrong_type(parameter)}; expected a "
                                  f"string ({DESCRIPTIONS[name]})")
            values[name] = parameter.value
    for name in STRING_LISTS:
        if name in given:
            parameter = given[name]
            if parameter.type_ == Parameter.Type.NOT_SET:  # rcl reads `[]` as no value
                values[name] = ()
            elif parameter.type_ == Parameter.Type.STRING_ARRAY:
                values[name] = tuple(parameter.value)
            else:
                raise ConfigError(f"parameter {name}: {_wrong_type(parameter)}; expected a "
                                  f"list of strings, e.g. -p {name}:=\"['...', '...']\" "
                                  f"({DESCRIPTIONS[name]})")
    return Settings(config=values.get("config", defaults.config),
                    placement=values.get("placement", defaults.placement),
                    overlays=values.get("overlays", defaults.overlays),
                    sets=values.get("sets", defaults.sets))


def _wrong_type(parameter: Any) -> str:
    return f"{parameter.value!r} is {parameter.type_.name.lower().replace('_', ' ')}"


def declare_settings(node: Node, settings: Settings) -> None:
    """The settings the node runs with, as read-only parameters (`ros2 param get`)."""
    from rcl_interfaces.msg import ParameterDescriptor

    for name in STRINGS:
        node.declare_parameter(name, getattr(settings, name), ParameterDescriptor(
            description=DESCRIPTIONS[name], read_only=True), ignore_override=True)
    for name in STRING_LISTS:
        # rclpy types an empty list as bytes, and a list declared by its type alone stays
        # unset, which fails `ros2 param get` and `dump` for every name asked with it: so
        # the lists are dynamically typed, and an empty one is an empty byte array.
        node.declare_parameter(name, list(getattr(settings, name)), ParameterDescriptor(
            description=DESCRIPTIONS[name], read_only=True, dynamic_typing=True),
            ignore_override=True)
