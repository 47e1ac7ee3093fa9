"""The ORICF gateway on the reference pipeline (people_qa), as a ROS 2 launch file.

    ros2 launch oricf_gateway people_qa.launch.py [placement:=edge] [config:=people_qa]
        [overlays:="['/etc/oricf/site.yaml']"] [sets:="['routes.people.input.topic=front/image']"]
        [namespace:=robot1] [log_level:=debug]

config, placement, overlays and sets become the node's parameters of the same names
(oricf.gateway.ros.params: shipped names resolved, files merged in that order, each value
checked); namespace and log_level are ROS's own. The node's name is the pipeline's
`node_name` (oricf_gateway for people_qa), in the namespace.

No ORICF import here: `ros2 launch` runs in the Python of the ROS install, which need not
see the `oricf` package that the node's executable runs with (docs/ros.md).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

# name: (default, description); each of the first four is a parameter of the node.
ARGUMENTS = {
    "config": ("people_qa", "the pipeline: a YAML path, or the name of a shipped pipeline "
                            "(configs/pipelines/NAME.yaml)"),
    "placement": ("onboard", "where the services run: onboard or edge (the shipped "
                             "configs/pipelines/placement/NAME.yaml), or a YAML path"),
    "overlays": ("[]", "more YAML files merged on top, in order: \"['a.yaml', 'b.yaml']\""),
    "sets": ("[]", "KEY=VALUE assignments applied last, a list like overlays"),
    "namespace": ("", "ROS namespace of the node and of its relative topic names"),
    "log_level": ("info", "debug, info, warn, error or fatal"),
}
PARAMETER_TYPES = {"config": str, "placement": str, "overlays": list[str], "sets": list[str]}


def gateway_node_options() -> dict[str, object]:
    """The node's executable, namespace, parameters and log level from the arguments (also
    lifecycle.launch.py's)."""
    return {
        "package": "oricf_gateway",
        "executable": "gateway",
        "namespace": LaunchConfiguration("namespace"),
        # Typed, so that `[]` stays an empty list and a path is never read as YAML.
        "parameters": [{name: ParameterValue(LaunchConfiguration(name), value_type=kind)
                        for name, kind in PARAMETER_TYPES.items()}],
        "ros_arguments": ["--log-level", LaunchConfiguration("log_level")],
        "output": "screen",
        "emulate_tty": True,
    }


def generate_launch_description() -> LaunchDescription:
    gateway = Node(**gateway_node_options())
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=description)
          for name, (default, description) in ARGUMENTS.items()),
        gateway,
    ])
