"""The gateway's log on /rosout: records of the `oricf` Python loggers, handed to the node's
ROS logger.

rcutils then does with each line what it does for any ROS node: prints it on the console,
writes it to the ROS log file (~/.ros/log) and publishes an rcl_interfaces/msg/Log on
/rosout, named after the node's logger (`oricf_gateway`, or `ns.oricf_gateway` in a
namespace), with the file, function and line of the Python call. While attached:

- the `oricf` logger stops propagating to the root handlers, so each line is printed once,
  by rcutils (`[INFO] [time] [oricf_gateway]: ...`, RCUTILS_CONSOLE_OUTPUT_FORMAT applies);
- its level follows the node logger's ROS level: `--ros-args --log-level debug` (or
  `--log-level oricf_gateway:=debug`) shows the gateway's DEBUG lines, whatever
  ORICF_LOG_LEVEL says. Other Python loggers keep the root's level and handlers.

There is no way round back into Python: rcutils is C and logs nothing through `logging`.
Lines logged before the node exists (loading the pipeline), once its context is shut down
(SIGINT, SIGTERM: rcl can no longer publish them) or after it is destroyed go to the root
handlers, the console, as without ROS. The gateway's entry points attach it
(oricf.gateway.shells.ros.GatewayRosNode); a GatewayNode built in a test leaves the test's
log capture alone.
"""

from __future__ import annotations

import logging
from typing import Any

from rclpy.context import Context
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.impl.logging_severity import LoggingSeverity
from rclpy.node import Node

ROOT = "oricf"
# Python logging level -> rcutils severity, highest first (the numbers happen to agree).
SEVERITIES = ((logging.CRITICAL, LoggingSeverity.FATAL), (logging.ERROR, LoggingSeverity.ERROR),
              (logging.WARNING, LoggingSeverity.WARN), (logging.INFO, LoggingSeverity.INFO))


def ros_severity(levelno: int) -> LoggingSeverity:
    return next((severity for level, severity in SEVERITIES if levelno >= level),
                LoggingSeverity.DEBUG)


def python_level(severity: LoggingSeverity) -> int:
    return next((level for level, s in SEVERITIES if s == severity), logging.DEBUG)


class RosoutHandler(logging.Handler):
    """Each record as a line of one ROS logger, with the record's own file, function and
    line (rclpy's Logger.log would report this handler's instead, and refuses a severity
    that changes between calls from one line of code)."""

    def __init__(self, ros_logger: str, context: Context) -> None:
        super().__init__()
        self.ros_logger = ros_logger
        self.context = context

    def emit(self, record: logging.LogRecord) -> None:
        if not self.context.ok():
            logging.getLogger().handle(record)
            return
        try:
            severity = ros_severity(record.levelno)
            if rclpy_implementation.rclpy_logging_logger_is_enabled_for(self.ros_logger,
                                                                        severity):
                rclpy_implementation.rclpy_logging_rcutils_log(
                    severity, self.ros_logger, self.format(record), record.funcName,
                    record.pathname, record.lineno)
        except Exception:
            self.handleError(record)


class RosoutLogging(Node):
    """A Node (mixed in before Node) whose `oricf` Python log goes to its ROS logger from
    the moment the ROS node exists until destroy_node()."""

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.attach_rosout()

    def attach_rosout(self) -> None:
        """For a class whose __init__ does not reach this one's (rclpy's LifecycleNode calls
        Node.__init__ by name): to call once the node exists."""
        logger = logging.getLogger(ROOT)
        self._saved_logging = logger.level, logger.propagate
        self._rosout = RosoutHandler(self.get_logger().name, self.context)
        logger.setLevel(python_level(self.get_logger().get_effective_level()))
        logger.propagate = False
        logger.addHandler(self._rosout)

    def destroy_node(self) -> None:
        logger = logging.getLogger(ROOT)
        logger.removeHandler(self._rosout)
        level, logger.propagate = self._saved_logging
        logger.setLevel(level)
        super().destroy_node()

