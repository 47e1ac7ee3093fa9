"""`oricf gateway`: the ROS 2 node that routes topics to the model services.

    oricf gateway --config configs/pipelines/people_qa.yaml \\
        [--overlay configs/pipelines/placement/edge.yaml ...] \\
        [--set routes.people.input.url=rtsp://camera.local/stream ...] \\
        [--record run.mcap] [--replay run.mcap [--rate 0]] [--foxglove 127.0.0.1:8765] \\
        [--lifecycle managed] [--ros-args -r __node:=my_gateway ...]

Also runnable as a plain ROS node: `python -m oricf.gateway.shells.main --config FILE`, and as the
ROS 2 package ros/oricf_gateway: `ros2 run oricf_gateway gateway --ros-args -p config:=...`,
`ros2 launch oricf_gateway people_qa.launch.py` (docs/ros.md). The flags are the defaults of
the node's parameters config, placement, overlays and sets (oricf.gateway.ros.params); given
after --ros-args, a parameter wins. --config and the placement parameter also take the name
of a shipped file (people_qa, edge). The node's log goes to /rosout (oricf.gateway.ros.rosout).
It is a managed (lifecycle) node that configures and activates itself; with --lifecycle
managed it waits for `ros2 lifecycle set`, a launch file's events or a lifecycle manager.

Where rclpy comes from (PyPI wheels, or a robot's own ROS 2): docs/ros.md. The audio
convention of std_msgs/Int16MultiArray inputs: docs/gateway.md.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.ros.params import Settings, read_parameters
from oricf.gateway.ros.process import poll_in_calling_thread
from oricf.logs import setup_logging

if TYPE_CHECKING:
    from oricf.gateway.config import PipelineConfig

log = logging.getLogger(__name__)

# --lifecycle: who takes the node's configure and activate transitions.
LIFECYCLES = ("auto", "managed")


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
    parser.add_argument("--foxglove", metavar="HOST:PORT",
                        help="serve the live view (Foxglove WebSocket protocol) at "
                             "ws://HOST:PORT, for Foxglove or Lichtblick to open (the "
                             "pipeline's `foxglove.listen`; docs/live-view.md)")
    parser.add_argument("--record", type=Path, metavar="OUT.mcap",
                        help="record every topic input and output into this new MCAP file "
                             "(rosbag2's layout; see docs/record-replay.md)")
    parser.add_argument("--replay", type=Path, metavar="IN.mcap",
                        help="take topic inputs from this MCAP recording instead of ROS, "
                             "without ROS; topic outputs go to --record, else to standard "
                             "output as JSON lines")
    parser.add_argument("--lifecycle", choices=LIFECYCLES, default="auto",
                        help="auto (default): the node configures and activates itself; "
                             "managed: it waits unconfigured for `ros2 lifecycle set`, "
                             "launch's lifecycle events or a lifecycle manager (docs/ros.md)")
    parser.add_argument("--rate", type=replay_rate, default=None,
                        help="--replay: 1 plays at the recorded pace (default), 2 twice as "
                             "fast (0.01 to 1000); 0 as fast as the routes take every "
                             "message, none dropped")
    return parser


def replay_rate(text: str) -> float:
    from oricf.gateway.recording.pace import check_rate

    try:
        rate = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    try:
        return check_rate(rate)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def replay(config: PipelineConfig, args: argparse.Namespace) -> int:
    """--replay: the pipeline without ROS, its topic inputs from the recording."""
    from oricf.gateway.recording.recorder import Recorder, RecordingError
    from oricf.gateway.recording.replay import Replay
    from oricf.gateway.shells import without_ros as standalone

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
    # First: grpc reads its settings when it loads, and this module's imports do not load it.
    poll_in_calling_thread()
    from oricf.gateway.config import load_pipeline
    from oricf.gateway.recording.recorder import RecordingError

    ours, ros_args = split_ros_args(list(sys.argv[1:] if argv is None else argv))
    args = build_parser().parse_args(ours)
    settings = Settings(config=str(args.config), overlays=tuple(map(str, args.overlay)),
                        sets=tuple(args.sets))
    if ros_args:  # the node's ROS parameters, where given, override the flags
        settings = read_parameters(ros_args, settings)
    sets = list(settings.sets)
    if args.metrics_listen:  # JSON: a YAML string whatever the address looks like
        sets.append(f"metrics.listen={json.dumps(args.metrics_listen)}")
    if args.foxglove:
        sets.append(f"foxglove.listen={json.dumps(args.foxglove)}")
    path, overlays = settings.files()
    config = load_pipeline(path, overlays, sets=sets)
    from oricf.tls import check_token_sources  # grpc: after its polling is set

    check_token_sources(config, config.origin)  # --check as the start: every token read
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
    managed = args.lifecycle == "managed"
    if managed and (args.replay is not None or not config.uses_ros):
        raise ConfigError("--lifecycle managed: only for a ROS node, and this pipeline runs "
                          "without ROS (it reads and writes no topic, or --replay)")
    if args.replay is not None:
        return replay(config, args)
    from oricf.gateway.recording.recorder import RecordingError

    if args.rate is not None:
        raise RecordingError("--rate: only with --replay")
    if not config.uses_ros:
        if args.record is not None:
            raise RecordingError(f"--record {args.record}: the pipeline reads and writes no "
                                 f"topic, so there is nothing to record")
        from oricf.gateway.shells import without_ros as standalone

        return standalone.run(config)
    from oricf.gateway.shells.ros import run

    return run(config, ros_args, args.record, settings, autostart=not managed)


def ros_main() -> int:
    """`ros2 run oricf_gateway gateway` (ros/oricf_gateway) and `python -m
    oricf.gateway.shells.main`: main() with the logging set-up and exit codes of a program."""
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
