"""`oricf demo`: the reference pipeline end to end on one machine, with real data.

Starts the services and the gateway of a deployment (configs/deployments/local.yaml, or
robot.yaml with --placement edge: detector and language model on an edge server such as
compose/edge.yaml, with TLS, and onboard fallbacks),
publishes a camera on camera/image_raw (a pedestrian video, vtest.avi, at its frame rate;
or --source: a video file, an RTSP or HTTP stream, a /dev/videoN device), speaks each
question (espeak-ng) on /audio/utterance, and prints for each question the transcript, the
person count, the answer, and the latency of each stage:

  ASR       audio published -> /speech/transcript received
  detector  frame published -> /human_counter received (median while the question ran)
  LLM       transcript received -> /answer received
  total     audio published -> /answer received

The gateway speaks each answer (the speech synthesis service, sentence by sentence as the
answer is generated, on /answer/audio): the demo plays it on the default audio device when
there is one (--speak-to FILE.wav also writes it; --no-speak: no speech) and prints the
time from the question to the first audio sample:

  spoken    audio published -> first sample at the speaker (without one: first audio
            received)

The services' and gateway's own output goes to a log file (--verbose: to the terminal).

With --view the gateway also serves the live view (docs/live-view.md): the camera with the
detector's boxes, the counts, transcripts and answers, for Foxglove or Lichtblick to open at
the address printed; after the questions the camera and the view go on until Ctrl-C.

Ctrl-C or SIGTERM stops the demo at any stage, and everything it started with it. Exit
codes: 0 every question answered (Ctrl-C after them with --view included), 1 a question
unanswered or a process that failed, 2 bad options, 130 stopped before the questions were
done. The processes it starts stop by themselves if the demo is killed outright.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
from pathlib import Path

import yaml

from oricf.config import config_dir
from oricf.demo.run import DemoOptions, run_demo
from oricf.launch.deployment import Deployment, load_deployment
from oricf.launch.launcher import LaunchFailed, Stopped
from oricf.launch.progress import ProgressLine
from oricf.launch.wiring import edge_host_endpoints
from oricf.signals import interrupt_on_signals

log = logging.getLogger(__name__)

# Phrasings that espeak-ng speaks and Whisper tiny.en hears back word for word.
DEFAULT_QUESTIONS = ["How many people do you see?", "Can you see any people?",
                     "How many people are there?"]
PLACEMENTS = {"onboard": "local.yaml", "edge": "robot.yaml"}
DEFAULT_VIEW = "127.0.0.1:8765"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="oricf demo", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--source", "--video", dest="source",
                        help="the camera: a video file (played at its frame rate, looped), "
                        "rtsp://..., http(s)://... or /dev/videoN (default: vtest.avi from the "
                        "model store)")
    parser.add_argument("--question", action="append", dest="questions",
                        help="a question to speak (repeatable; default: three questions)")
    parser.add_argument("--placement", choices=sorted(PLACEMENTS), default="onboard",
                        help="onboard: start every service here; edge: detector and language "
                        "model on an edge server (configs/deployments/robot.yaml)")
    parser.add_argument("--deployment", type=Path,
                        help="deployment YAML to use instead of the placement's")
    parser.add_argument("--edge-host", help="host of the edge server: replaces the host of "
                        "every endpoint address not on this machine (edge.local in "
                        "configs/pipelines/placement/edge.yaml)")
    parser.add_argument("--frames", type=int, help="stop the video after this many frames "
                        "(default: play, looping, until every question is answered)")
    parser.add_argument("--view", nargs="?", const=DEFAULT_VIEW, metavar="HOST:PORT",
                        help=f"serve the live view (Foxglove WebSocket protocol) at "
                        f"ws://HOST:PORT (default {DEFAULT_VIEW}) and keep the demo running "
                        f"after the questions until Ctrl-C")
    parser.add_argument("--voice", default="en-us", help="espeak-ng voice")
    parser.add_argument("--speak-to", type=Path, metavar="FILE.wav",
                        help="write the spoken answers into this WAV file (as well as "
                        "playing them on the default audio device, if there is one)")
    parser.add_argument("--no-speak", action="store_true",
                        help="the answers are text only: no speech synthesis, no playback")
    parser.add_argument("--timeout", type=float, default=120.0,
                        help="seconds to wait for each stage of a question")
    parser.add_argument("--log", type=Path, help="file for the processes' output")
    parser.add_argument("--verbose", action="store_true",
                        help="show the processes' output instead of writing it to the log file")
    return parser


def pick_deployment(args: argparse.Namespace, scratch: Path) -> tuple[Path, Deployment]:
    """The deployment to run; --edge-host adds an overlay (written in scratch) to its
    gateway."""
    path = args.deployment or config_dir() / "deployments" / PLACEMENTS[args.placement]
    deployment = load_deployment(path)
    gateway = deployment.gateway
    if gateway is None:
        raise LaunchFailed(f"{path}: the demo needs a deployment with a gateway")
    overlays = []
    if args.edge_host:
        overlays.append({"endpoints": edge_host_endpoints(deployment, args.edge_host)})
    if args.view:
        overlays.append({"foxglove": {"listen": args.view}})
    for index, overlay in enumerate(overlays):
        file = scratch / f"demo-overlay-{index}.yaml"
        file.write_text(yaml.safe_dump(overlay))
        gateway = gateway.model_copy(update={"overlays": [*gateway.overlays, file]})
    deployment = deployment.model_copy(update={"gateway": gateway})
    if not args.no_speak:
        from oricf.demo.speech import speaking_deployment

        deployment = speaking_deployment(deployment, scratch / "demo-voice.yaml")
    return path, deployment


def view_url(listen: str) -> str:
    """The address a viewer opens for the demo's `foxglove.listen` (plain ws://: the demo's
    view stays on loopback, where neither TLS nor a token is needed)."""
    return f"ws://{listen}"


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.frames is not None and args.frames < 1:
        print("--frames must be at least 1", file=sys.stderr)
        return 2
    if args.no_speak and args.speak_to:
        print("--speak-to and --no-speak exclude each other", file=sys.stderr)
        return 2
    if args.source is None:
        from oricf.store import ModelStore

        args.source = str(ModelStore().path("vtest-video", "vtest.avi"))
    log_path = args.log or Path(tempfile.mkstemp(prefix="oricf-demo-", suffix=".log")[1])
    # Ctrl-C and SIGTERM end the demo at any stage: everything it started is stopped.
    with interrupt_on_signals(), tempfile.TemporaryDirectory(prefix="oricf-demo-") as scratch:
        return _run(args, log_path, Path(scratch))


def _run(args: argparse.Namespace, log_path: Path, scratch: Path) -> int:
    try:
        path, deployment = pick_deployment(args, scratch)
        options = DemoOptions(
            source=args.source, questions=args.questions or DEFAULT_QUESTIONS,
            max_frames=args.frames, voice=args.voice, stage_timeout_s=args.timeout,
            log_path=log_path, verbose=args.verbose,
            view=view_url(args.view) if args.view else None,
            speak=not args.no_speak, play=not args.no_speak, speak_to=args.speak_to)
        print(f"ORICF demo: deployment {path}, camera {args.source}, "
              f"log {log_path}", flush=True)
        if options.view:
            print(f"live view: {options.view} (open it in Foxglove or Lichtblick: Open "
                  f"connection -> Foxglove WebSocket; docs/live-view.md)", flush=True)
        return run_demo(deployment, options, ProgressLine(sys.stdout))
    except (LaunchFailed, TimeoutError) as exc:
        print(f"demo failed: {exc}\n(process output: {log_path})", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, Stopped):
        print("demo interrupted", file=sys.stderr)
        return 130
