"""The ORICF gateway as a managed (lifecycle) node, as a ROS 2 launch file.

    ros2 launch oricf_gateway lifecycle.launch.py [autostart:=false] [node_name:=NAME]
        [the arguments of people_qa.launch.py: config, placement, overlays, sets, namespace,
        log_level]

The node starts with `--lifecycle managed`, unconfigured. With autostart (the default) this
file takes it through configure and, once configuring has ended in inactive, activate:
launch's lifecycle events, which call the node's lifecycle services. With autostart:=false it
waits for a lifecycle manager (nav2's lifecycle_manager, a robot's own) or `ros2 lifecycle
set`. A deactivate later on is left alone: only the end of configuring activates.

launch_ros reaches a lifecycle node's services by its name, so the name is given here:
node_name (default oricf_gateway, people_qa's `node_name`) renames the node as `-r
__node:=` would. Everything else is people_qa.launch.py's, read from the file beside this
one; like it, this file imports nothing from ORICF (docs/ros.md).
"""

import importlib.util
from pathlib import Path
from typing import Any

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from lifecycle_msgs.msg import Transition


def people_qa_launch() -> Any:
    """people_qa.launch.py, installed beside this file, as a module."""
    spec = importlib.util.spec_from_file_location(
        "oricf_gateway_people_qa_launch", Path(__file__).with_name("people_qa.launch.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PEOPLE_QA = people_qa_launch()
# name: (default, description), people_qa.launch.py's and these.
ARGUMENTS = {
    **PEOPLE_QA.ARGUMENTS,
    "node_name": ("oricf_gateway", "the node's name, by which launch and lifecycle managers "
                                   "reach its lifecycle services"),
    "autostart": ("true", "true: configure and activate the node; false: leave it "
                          "unconfigured for a lifecycle manager"),
}
# `oricf gateway`'s flag: the node waits for its configure and activate transitions.
MANAGED = ["--lifecycle", "managed"]


def transition(node: LifecycleNode, transition_id: int, **kwargs: Any) -> EmitEvent:
    """The event that asks the node's change_state service for this transition."""
    return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node),
                                       transition_id=transition_id), **kwargs)


def generate_launch_description() -> LaunchDescription:
    gateway = LifecycleNode(name=LaunchConfiguration("node_name"), arguments=MANAGED,
                            **PEOPLE_QA.gateway_node_options())
    autostart = LaunchConfiguration("autostart")
    activate_once_configured = RegisterEventHandler(
        OnStateTransition(target_lifecycle_node=gateway, start_state="configuring",
                          goal_state="inactive",
                          entities=[transition(gateway, Transition.TRANSITION_ACTIVATE)]),
        condition=IfCondition(autostart))
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=description)
          for name, (default, description) in ARGUMENTS.items()),
        gateway,
        activate_once_configured,
        transition(gateway, Transition.TRANSITION_CONFIGURE, condition=IfCondition(autostart)),
    ])
