"""The gateway node's executor and its spin loop, one way for `oricf gateway` (in the main
thread until SIGINT/SIGTERM) and for a pipeline hosted by `oricf mcp --config` (on a thread
of its own until its context is shut down)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from oricf.errors import ConfigError

log = logging.getLogger(__name__)

STOP_CHECK_S = 0.5  # how late a stop may be noticed when rclpy does not wake the executor


def make_executor(threads: int, context: Any = None, kind: str = "python") -> Any:
    """Camera frames never pass through the executor (oricf.gateway.ros.camera); the text
    and audio callbacks only hand messages to their routes' worker threads and never block,
    so one executor thread keeps up. threads > 1 selects rclpy's MultiThreadedExecutor.

    kind events: rclpy's EventsExecutor, whose wait for the next callback is C++ instead of
    the Python executors' rebuilding of a wait set per message: at a control loop's rate
    (a state in, an action out, 80 times a second) the process's CPU per message fell to
    under half (docs/control.md). Experimental in rclpy; not in Humble's."""
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

    if kind == "events":
        executor = require_executor(kind)(context=context)
    elif threads == 1:
        executor = SingleThreadedExecutor(context=context)
    else:
        executor = MultiThreadedExecutor(num_threads=threads, context=context)
    log.info("ROS executor: %s", type(executor).__name__)
    return executor


def require_executor(kind: str) -> Any:
    """The events executor's class (None for the Python executors), or a ConfigError where
    this rclpy lacks it."""
    if kind != "events":
        return None
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError as exc:
        raise ConfigError(f"executor: events needs rclpy's EventsExecutor (Jazzy's rclpy "
                          f"7.1.4 or later, Kilted): {exc}") from None
    return EventsExecutor


def spin_until_shutdown(executor: Any, ok: Callable[[], bool]) -> None:
    """Spins until `ok()` turns false (the context shut down by a signal or by a stop).

    Not executor.spin(): when rclpy's signal thread shuts the context down, now and then
    (rclpy 7.1) the executor's wait is not woken, and spin() slept on until the next timer
    (stats_interval_s; forever without one). A bounded wait notices the shut-down context."""
    from rclpy.executors import ExternalShutdownException
    from rclpy.impl.implementation_singleton import rclpy_implementation

    try:
        while ok():
            executor.spin_once(timeout_sec=STOP_CHECK_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except rclpy_implementation.RCLError:
        # The context was shut down while the executor was building its next wait set;
        # rclpy reports that race as an RCLError. Anything else is a real failure.
        if ok():
            raise
