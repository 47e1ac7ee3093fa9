"""`oricf gateway`: the ROS 2 node that routes topics to the model services.

    oricf gateway --config configs/pipelines/people_qa.yaml \\
        [--overlay configs/pipelines/placement/edge.yaml ...] \\
        [--set routes.people.input.url=rtsp://camera.local/stream ...] \\
        [--record run.mcap] [--replay run.mcap [--rate 0]] \\
        [--ros-args -r __node:=my_gateway ...]

Also runnable as a plain ROS node: `python -m oricf.gateway.main --config FILE`, and as the
ROS 2 package ros/oricf_gateway: `ros2 run oricf_gateway gateway --ros-args -p config:=...`,
`ros2 launch oricf_gateway people_qa.launch.py` (docs/ros.md). The flags are the defaults of
the node's parameters config, placement, overlays and sets (oricf.gateway.rosparams); given
after --ros-args, a parameter wins. --config and the placement parameter also take the name
of a shipped file (people_qa, edge). The node's log goes to /rosout (oricf.gateway.roslog).

Where rclpy comes from:
- x86-64 workstation or CI: the PyPI Jazzy wheels, `pip install "oricf[ros]"` (the `ros` extra:
  ros-jazzy-rclpy[fastrtps], ros-jazzy-std-msgs, ros-jazzy-sensor-msgs). Nothing to source.
- A robot with its own ROS 2 (e.g. an aarch64 Jetson; there are no aarch64 wheels): install
  Jazzy from apt (ros-jazzy-ros-base, which has rclpy, std_msgs and sensor_msgs), then

      source /opt/ros/jazzy/setup.bash
      python3 -m venv --system-site-packages ~/oricf-venv   # sees the apt rclpy
      ~/oricf-venv/bin/pip install oricf                     # WITHOUT the [ros] extra
      ~/oricf-venv/bin/oricf gateway --config people_qa.yaml

  The venv's Python must be the one ROS was built for (Python 3.12 for Jazzy on Ubuntu 24.04).
  Keep ROS_DOMAIN_ID (and ROS_AUTOMATIC_DISCOVERY_RANGE) the same as the robot's other nodes.

Audio convention: std_msgs/Int16MultiArray, one complete utterance per message, the int16
values are the PCM samples (interleaved if several channels); sample rate and channels are
set per route in the YAML (`input.sample_rate`, `input.channels`; 16000 Hz mono by default).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.config import PipelineConfig, load_pipeline
from oricf.gateway.dds import use_dds_profile
from oricf.gateway.grpc_client import poll_in_calling_thread
from oricf.gateway.memory import keep_freed_memory
from oricf.gateway.record import Recorder, RecordingError
from oricf.gateway.rosparams import Settings, declare_settings, read_parameters
from oricf.logs import setup_logging

log = logging.getLogger(__name__)

STOP_CHECK_S = 0.5  # how late a stop may be noticed when rclpy does not wake the executor


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="oricf gateway", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path,
                        default=config_dir() / "pipelines" / "people_qa.yaml",
                        help="pipeline YAML, or a shipped pipeline's name (default "
                             "configs/pipelines/people_qa.yaml)")
    parser.add_argument("--overlay", type=Path, action="append", default=[],
                        help="YAML merged on top, e.g. a placement file (repeatable)")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="override any pipeline key, e.g. routes.people.input.url=rtsp://"
                             "cam/stream (VALUE is YAML; repeatable; validated like the file)")
    parser.add_argument("--check", action="store_true",
                        help="validate the configuration and exit")
    parser.add_argument("--metrics-listen", metavar="HOST:PORT",
                        help="serve Prometheus metrics at http://HOST:PORT/metrics (the "
                             "pipeline's `metrics.listen`; docs/metrics.md)")
    parser.add_argument("--record", type=Path, metavar="OUT.mcap",
                        help="record every topic input and output into this new MCAP file "
                             "(rosbag2's layout; see docs/record-replay.md)")
    parser.add_argument("--replay", type=Path, metavar="IN.mcap",
                        help="take topic inputs from this MCAP recording instead of ROS, "
                             "without ROS; topic outputs go to --record, else to standard "
                             "output as JSON lines")
    parser.add_argument("--rate", type=replay_rate, default=None,
                        help="--replay: 1 plays at the recorded pace (default), 2 twice as "
                             "fast; 0 as fast as the routes take every message, none dropped")
    return parser


def replay_rate(text: str) -> float:
    try:
        rate = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 <= rate < float("inf"):
        raise argparse.ArgumentTypeError("must be 0 (as fast as possible) or more")
    return rate


def run(config: PipelineConfig, ros_args: list[str], record: Path | None = None,
        settings: Settings | None = None) -> int:
    """Spins the node until SIGINT/SIGTERM (rclpy handles both and shuts the context down)."""
    poll_in_calling_thread()  # before the node's imports load grpc
    try:
        import rclpy
        from rclpy.executors import (
            Executor,
            ExternalShutdownException,
            MultiThreadedExecutor,
            SingleThreadedExecutor,
        )
        from rclpy.impl.implementation_singleton import rclpy_implementation

        from oricf.gateway.roslog import GatewayRosNode

        RCLError = rclpy_implementation.RCLError
    except ImportError as exc:
        log.error("ROS 2 Python packages not found (%s): source /opt/ros/jazzy/setup.bash, "
                  "or pip install 'oricf[ros]' on x86-64", exc)
        return 2
    use_dds_profile()
    if not keep_freed_memory():
        log.info("mallopt not available: large frame buffers come from fresh pages")
    recorder = Recorder(record) if record is not None else None  # before ROS: fail at once
    rclpy.init(args=ros_args)
    node = GatewayRosNode(config, recorder=recorder)  # its log on /rosout
    if settings is not None:
        declare_settings(node, settings)
    # Camera frames never pass through the executor (oricf.gateway.camera); the text and audio
    # callbacks only hand messages to their routes' worker threads and never block, so one
    # executor thread keeps up. executor_threads > 1 selects rclpy's MultiThreadedExecutor.
    executor: Executor = (SingleThreadedExecutor() if config.executor_threads == 1
                          else MultiThreadedExecutor(num_threads=config.executor_threads))
    executor.add_node(node)
    try:
        # Not executor.spin(): on SIGTERM or SIGINT rclpy's signal thread shuts the context
        # down, but now and then (about 1 stop in 10 here, rclpy 7.1) the executor's wait is
        # not woken, and spin() slept on until the next timer (stats_interval_s; forever
        # without one). A bounded wait notices the shut-down context.
        while rclpy.ok():
            executor.spin_once(timeout_sec=STOP_CHECK_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        # SIGTERM shut the context down while the executor was building its next wait set;
        # rclpy reports that race as an RCLError. Anything else is a real failure.
        if rclpy.ok():
            raise
    finally:
        log.info("gateway stopping")
        node.shutdown()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        if recorder is not None:
            recorder.close()
    return 0


def replay(config: PipelineConfig, args: argparse.Namespace) -> int:
    """--replay: the pipeline without ROS, its topic inputs from the recording."""
    from oricf.gateway import standalone
    from oricf.gateway.sources.replay import Replay

    player = Replay(args.replay, config, 1.0 if args.rate is None else args.rate)
    try:
        if args.record is not None:
            player.recorder = Recorder(args.record, wait_when_full=True)
    except RecordingError:
        player.close()
        raise
    return standalone.run(config, replay=player)


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """(our arguments, the --ros-args ... part for rclpy)."""
    if "--ros-args" not in argv:
        return argv, []
    at = argv.index("--ros-args")
    return argv[:at], ["oricf_gateway", *argv[at:]]


def main(argv: list[str] | None = None) -> int:
    ours, ros_args = split_ros_args(list(sys.argv[1:] if argv is None else argv))
    args = build_parser().parse_args(ours)
    settings = Settings(config=str(args.config), overlays=tuple(map(str, args.overlay)),
                        sets=tuple(args.sets))
    if ros_args:  # the node's ROS parameters, where given, override the flags
        settings = read_parameters(ros_args, settings)
    sets = list(settings.sets)
    if args.metrics_listen:  # JSON: a YAML string whatever the address looks like
        sets.append(f"metrics.listen={json.dumps(args.metrics_listen)}")
    path, overlays = settings.files()
    config = load_pipeline(path, overlays, sets=sets)
    if args.check:
        print(f"{path}: OK ({len(config.routes)} routes, "
              f"endpoints {', '.join(config.endpoints)})")
        return 0
    try:
        return start(config, args, ros_args, settings)
    except RecordingError as exc:  # a recording that cannot be read or written
        log.error("%s", exc)
        return 2


def start(config: PipelineConfig, args: argparse.Namespace, ros_args: list[str],
          settings: Settings | None = None) -> int:
    """With ROS if the pipeline has topics, unless they are replayed from a recording."""
    if args.replay is not None:
        return replay(config, args)
    if args.rate is not None:
        raise RecordingError("--rate: only with --replay")
    if not config.uses_ros:
        if args.record is not None:
            raise RecordingError(f"--record {args.record}: the pipeline reads and writes no "
                                 f"topic, so there is nothing to record")
        from oricf.gateway import standalone

        return standalone.run(config)
    return run(config, ros_args, args.record, settings)


def ros_main() -> int:
    """`ros2 run oricf_gateway gateway` (ros/oricf_gateway) and `python -m
    oricf.gateway.main`: main() with the logging set-up and exit codes of a program."""
    setup_logging()
    try:
        return main()
    except ConfigError as error:
        log.error("%s", error)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(ros_main())
