"""`oricf bench soak`: the voice demo for a long run, watched for leaks and errors.

Runs `oricf demo`'s pipeline (its launcher and ROS node: the services, the gateway speaking
every answer, vtest.avi looped on camera/image_raw) with the live view on and a viewer
subscribed to every channel for the whole run, and speaks a question every --every seconds
(the demo's phrasings in turn). Each answer is judged against the people count published
just before it: right when the answer states that number.

Every --sample-every seconds (a minute by default) it reads the resident memory (RSS, and
its anonymous and file-backed parts) and the CPU time of every process (each service, the
gateway, the viewer and this bench) and counts the ERROR and Traceback lines in the
processes' log. At the end, per process: RSS at the first sample and the last, growth per
hour (a least-squares line over the samples after --warmup, and over the run's last third),
whether memory still grows in the last third and which (anonymous or file-backed), CPU;
questions answered and asked, wrong answers, error lines. --report FILE writes all of it as
JSON, and the samples as CSV beside it (FILE with .csv).

Exits 1 when a question went unanswered, an error line appeared or a process ended.
"""

from __future__ import annotations

import argparse
import logging
import os
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from oricf.bench.gateway_view import start_viewer, stop_viewer
from oricf.bench.soak_report import (
    Answer,
    LogErrors,
    Outcome,
    Sample,
    print_samples,
    print_summary,
    read_process,
    summarize,
    write_report,
)
from oricf.demo.main import DEFAULT_QUESTIONS, pick_deployment, view_url
from oricf.demo.run import DemoOptions, Result, ask, launched, wait_connected
from oricf.hosts import Address
from oricf.launch.health import free_port
from oricf.launch.launcher import Launcher, LaunchFailed
from oricf.launch.progress import ProgressLine
from oricf.signals import interrupt_on_signals

log = logging.getLogger(__name__)

KEPT_COUNTS = 100  # of the demo node's count history: the recent ones are all a question reads
VIEW_TIMEOUT_S = 60.0


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="oricf bench soak", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=60, help="length of the run")
    parser.add_argument("--every", type=float, default=10, metavar="S",
                        help="seconds between questions (default 10)")
    parser.add_argument("--sample-every", type=float, default=60, metavar="S",
                        help="seconds between samples of RSS and CPU (default 60)")
    parser.add_argument("--warmup", type=float, default=60, metavar="S",
                        help="seconds of samples left out of the growth fit (default 60)")
    parser.add_argument("--report", type=Path, help="write the report as JSON here (and the "
                        "samples as CSV beside it)")
    parser.add_argument("--deployment", type=Path, help="deployment YAML instead of the "
                        "demo's (configs/deployments/local.yaml)")
    parser.add_argument("--source", help="the camera (default: vtest.avi, looped)")
    parser.add_argument("--voice", default="en-us", help="espeak-ng voice of the questions")
    parser.add_argument("--timeout", type=float, default=120.0,
                        help="seconds to wait for each stage of a question")
    parser.add_argument("--log", type=Path, help="file for the processes' output")
    args = parser.parse_args(argv)
    for name in ("minutes", "every", "sample_every"):
        if getattr(args, name) <= 0:
            parser.error(f"--{name.replace('_', '-')} must be more than 0")
    return args


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    if args.source is None:
        from oricf.store import ModelStore

        args.source = str(ModelStore().path("vtest-video", "vtest.avi"))
    log_path = args.log or Path(tempfile.mkstemp(prefix="oricf-soak-", suffix=".log")[1])
    listen = f"127.0.0.1:{free_port()}"
    errors = LogErrors(log_path)
    logging.getLogger().addHandler(errors.handler())
    try:
        # Ctrl-C and SIGTERM end the soak at any stage: everything it started is stopped.
        with interrupt_on_signals(), tempfile.TemporaryDirectory(prefix="oricf-soak-") as scratch:
            choice = argparse.Namespace(deployment=args.deployment, placement="onboard",
                                        edge_host=None, view=listen, no_speak=False)
            path, deployment = pick_deployment(choice, Path(scratch))
            options = DemoOptions(
                source=args.source, questions=DEFAULT_QUESTIONS, max_frames=None,
                voice=args.voice, stage_timeout_s=args.timeout, log_path=log_path,
                verbose=False, view=view_url(listen), speak=True)
            print(f"soak: {args.minutes:g} min, a question every {args.every:g} s, deployment "
                  f"{path}, live view {options.view}, log {log_path}", flush=True)
            outcome = soak(deployment, options, args, errors)
    except LaunchFailed as exc:
        print(f"soak failed: {exc}\n(process output: {log_path})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("soak interrupted", file=sys.stderr)
        return 130
    errors.scan()  # what the processes wrote while stopping counts too
    return report(outcome, errors, args)


def soak(deployment: Any, options: DemoOptions, args: argparse.Namespace,
         errors: LogErrors) -> Outcome:
    from oricf.audio import synthesize

    speech = [synthesize(q, voice=options.voice) for q in options.questions]
    progress = ProgressLine(sys.stdout)
    with launched(deployment, options, progress) as launcher:
        return with_ros(launcher, options, speech, args, errors, progress)


def with_ros(launcher: Launcher, options: DemoOptions, speech: list[Any],
             args: argparse.Namespace, errors: LogErrors, progress: ProgressLine) -> Outcome:
    import rclpy

    from oricf.demo.node import COUNT, CameraFeed, DemoNode, ros_context
    from oricf.demo.speech import AnswerPlayer

    context = ros_context()
    node = DemoNode(context)
    replay = CameraFeed(node.camera.publish, options.source, None)
    player = AnswerPlayer(play=False, wav=None)  # the speech is received and timed, not played
    node.on_spoken = player.play
    try:
        wait_connected(node, launcher, progress)
        replay.start()
        if node.next(COUNT, options.stage_timeout_s) is None:
            raise LaunchFailed("no /human_counter message: the people route does not answer")
        assert options.view is not None
        wait_listening(options.view)
        viewer = start_viewer(options.view)
        progress("the gateway counts people and a viewer watches; soaking", True)
        pids = {p.name: p.pid for p in launcher.processes if p.pid is not None}
        pids.update(viewer=viewer.pid, bench=os.getpid())
        outcome = Outcome()
        try:
            questions(node, replay, player, speech, args, Sampling(pids, errors, args, outcome))
        finally:
            outcome.viewer_images_per_s = stop_viewer(viewer)
        return outcome
    finally:
        replay.stop()
        node.close()
        player.close()
        rclpy.try_shutdown(context=context)


def wait_listening(url: str) -> None:
    """Until the live view accepts connections (it opens as the gateway starts)."""
    view = Address.parse(url.removeprefix("ws://"))
    deadline = time.monotonic() + VIEW_TIMEOUT_S
    while True:
        try:
            socket.create_connection((view.host, view.port), timeout=1).close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise LaunchFailed(f"the live view did not open at {url}") from None
            time.sleep(0.2)


class Sampling:
    """Samples every process and scans the log every --sample-every s, in a thread of its
    own so a question in progress does not delay it; a last round when stopped."""

    def __init__(self, pids: dict[str, int], errors: LogErrors, args: argparse.Namespace,
                 outcome: Outcome) -> None:
        self.pids, self.errors, self.outcome = pids, errors, outcome
        self.interval = args.sample_every
        self.started = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="soak-sampler", daemon=True)

    def __enter__(self) -> Sampling:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.take()

    def _run(self) -> None:
        rounds = 0
        while not self._stop.wait(self.started + rounds * self.interval - time.monotonic()):
            self.take()
            rounds += 1

    def take(self) -> None:
        t_s = time.monotonic() - self.started
        round_: list[Sample] = [read_process(n, pid, t_s) for n, pid in self.pids.items()]
        self.outcome.samples.extend(round_)
        self.errors.scan()
        print_samples(round_)


def questions(node: Any, replay: Any, player: Any, speech: list[Any],
              args: argparse.Namespace, sampling: Sampling) -> None:
    """A question every --every s until --minutes have passed (one in progress finishes)."""
    from oricf.demo.node import COUNT

    phrasings = list(zip(DEFAULT_QUESTIONS, speech, strict=True))
    with sampling:
        end = sampling.started + args.minutes * 60
        due = sampling.started
        while (now := time.monotonic()) < end:
            if now < due:
                time.sleep(min(due, end) - now)
                continue
            question, samples = phrasings[len(sampling.outcome.answers) % len(phrasings)]
            result = ask(node, replay, question, samples, args.timeout, player)
            answer = judged(result, now - sampling.started)
            sampling.outcome.answers.append(answer)
            print_answer(len(sampling.outcome.answers), answer)
            due = max(due + args.every, time.monotonic())
            # The node keeps every count and the camera every send time: only the recent
            # ones are read, and a long run must not grow the bench itself.
            node.drain(COUNT)
            del node.counts[:-KEPT_COUNTS]
            del replay.sent_at[:-KEPT_COUNTS]


def judged(result: Result, at_s: float) -> Answer:
    return Answer(at_s, result.question, result.transcript, result.count, result.answer,
                  result.total_ms, result.first_audio_ms)


def print_answer(index: int, answer: Answer) -> None:
    if not answer.answered:
        print(f"Q{index} [{answer.at_s / 60:5.1f} min] {answer.question}: UNANSWERED "
              f"(transcript {answer.transcript!r}, answer {answer.answer!r})", flush=True)
        return
    verdict = "right" if answer.right else "WRONG"
    print(f"Q{index} [{answer.at_s / 60:5.1f} min] {answer.question} -> {answer.answer} "
          f"(count {answer.count}: {verdict}; total {answer.total_ms or 0:.0f} ms)", flush=True)


def report(outcome: Outcome, errors: LogErrors, args: argparse.Namespace) -> int:
    summaries = summarize(outcome.samples, args.warmup, errors.counts)
    print_summary(summaries, outcome.answers, args.warmup)
    print(f"the viewer received {outcome.viewer_images_per_s:.1f} camera images a second")
    if errors.lines:
        print("first error lines:\n  " + "\n  ".join(errors.lines))
    if args.report:
        settings = {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}
        table = write_report(args.report, outcome.report(summaries, errors, settings),
                             outcome.samples)
        print(f"wrote {args.report} and {table}")
    unanswered = sum(not a.answered for a in outcome.answers)
    ended = [s.process for s in summaries if s.ended]
    if ended:
        print(f"ended during the soak: {', '.join(ended)}")
    return 1 if unanswered or errors.counts or ended or not outcome.answers else 0
