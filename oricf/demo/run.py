"""The demo's sequence: launch, connect, start the camera, ask each question, report."""

from __future__ import annotations

import logging
import statistics
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from oricf.launch.deployment import Deployment
from oricf.launch.launcher import Launcher, LaunchFailed
from oricf.launch.process import PrefixedLines
from oricf.launch.progress import ProgressLine

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S = 60.0
SPEECH_GAP_S = 3.0  # an answer's speech has ended when no piece came for this long


@dataclass(frozen=True)
class DemoOptions:
    source: str  # a video file, rtsp://, http(s):// or /dev/videoN
    questions: list[str]
    max_frames: int | None
    voice: str
    stage_timeout_s: float
    log_path: Path
    verbose: bool
    view: str | None = None  # the live view's address: the demo goes on until Ctrl-C
    speak: bool = False  # the gateway speaks the answers on /answer/audio (oricf.demo.speech)
    play: bool = False  # ... and the demo plays them on the default audio device
    speak_to: Path | None = None  # ... and writes them into this WAV file


@dataclass
class Result:
    question: str
    transcript: str | None = None
    count: int | None = None
    answer: str | None = None
    asr_ms: float | None = None
    detector_ms: float | None = None
    llm_ms: float | None = None
    total_ms: float | None = None
    first_audio_ms: float | None = None  # the question published -> its first audio sample
    spoken_s: float | None = None

    @property
    def complete(self) -> bool:
        return None not in (self.transcript, self.count, self.answer)


@contextmanager
def launched(deployment: Deployment, options: DemoOptions,
             progress: ProgressLine) -> Iterator[Launcher]:
    with options.log_path.open("w", encoding="utf-8") as handle:
        terminal = [sys.stdout] if options.verbose else []
        launcher = Launcher(deployment, PrefixedLines(handle, *terminal), progress)
        try:
            launcher.start(threading.Event())
            yield launcher
        finally:
            launcher.stop()


def run_demo(deployment: Deployment, options: DemoOptions, progress: ProgressLine) -> int:
    from oricf.audio import synthesize

    # Speech is synthesized before anything is timed (espeak-ng takes a moment).
    speech = [synthesize(q, voice=options.voice) for q in options.questions]
    with launched(deployment, options, progress) as launcher:
        results = _with_ros(launcher, options, speech, progress)
    print(format_summary(results), flush=True)
    return 0 if all(r.complete for r in results) else 1


def _with_ros(launcher: Launcher, options: DemoOptions, speech: list[Any],
              progress: ProgressLine) -> list[Result]:
    import rclpy

    from oricf.demo.node import COUNT, CameraFeed, DemoNode, ros_context

    context = ros_context()
    node = DemoNode(context)
    replay = CameraFeed(node.camera.publish, options.source, options.max_frames)
    player = None
    if options.speak:
        from oricf.demo.speech import AnswerPlayer

        player = AnswerPlayer(options.play, options.speak_to)
        node.on_spoken = player.play
        if player.note:
            print(f"speech: {player.note}", flush=True)
    try:
        wait_connected(node, launcher, progress)
        replay.start()
        rate = f"at {replay.fps:.0f} fps" if replay.fps else "as it sends"
        progress(f"camera {options.source} {rate}; "
                 "waiting for the first person count", False)
        if node.next(COUNT, options.stage_timeout_s) is None:
            raise LaunchFailed("no /human_counter message: the people route does not answer")
        progress("the gateway counts people; asking the questions", True)
        results = []
        for index, (question, samples) in enumerate(zip(options.questions, speech,
                                                        strict=True), 1):
            results.append(ask(node, replay, question, samples, options.stage_timeout_s,
                               player))
            print(format_result(index, results[-1]), flush=True)
        if options.view:
            keep_viewing(options.view)
        return results
    finally:
        replay.stop()
        node.close()
        if player is not None:
            player.close()
        rclpy.try_shutdown(context=context)


def keep_viewing(url: str) -> None:
    """The camera and the live view go on until Ctrl-C (or SIGTERM), which ends the demo
    normally."""
    print(f"\nthe live view stays open at {url}; Ctrl-C to stop", flush=True)
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        pass


def wait_connected(node: Any, launcher: Launcher, progress: ProgressLine) -> None:
    start = time.monotonic()
    while not node.connected():
        gateway = launcher.gateway
        if gateway is not None and gateway.poll() is not None:
            tail = "\n".join(gateway.tail)
            raise LaunchFailed(f"the gateway ended while starting:\n{tail}")
        elapsed = time.monotonic() - start
        if elapsed > CONNECT_TIMEOUT_S:
            raise LaunchFailed(f"the gateway's topics were not seen in {elapsed:.0f} s")
        progress(f"waiting for the gateway's topics ({elapsed:.0f} s)", False)
        time.sleep(0.1)
    progress(f"gateway connected ({time.monotonic() - start:.1f} s)", True)


def ask(node: Any, replay: Any, question: str, samples: Any, timeout: float,
        player: Any = None) -> Result:
    from oricf.demo.node import ANSWER, SPOKEN, TRANSCRIPT

    result = Result(question)
    node.drain(TRANSCRIPT)
    node.drain(ANSWER)
    node.drain(SPOKEN)
    sent = node.say(samples)
    heard = node.next(TRANSCRIPT, timeout)
    if heard is None:
        return result
    result.transcript, result.asr_ms = str(heard.value), (heard.at - sent) * 1000
    answer = node.next(ANSWER, timeout)
    if answer is not None:
        result.answer = str(answer.value)
        result.llm_ms = (answer.at - heard.at) * 1000
        result.total_ms = (answer.at - sent) * 1000
    # The count the language model was given: the latest one when the transcript arrived
    # (the gateway reads its people_count product at that moment).
    counts = [c for c in node.counts if c.at <= heard.at]
    if counts:
        result.count = int(counts[-1].value)
        result.detector_ms = detector_latency_ms(counts, replay, since=sent)
    if player is not None and answer is not None:
        hear(node, player, sent, result, timeout)
    return result


def hear(node: Any, player: Any, sent: float, result: Result, timeout: float) -> None:
    """The answer's speech: how long after the question its first sample came out (at the
    speaker when one plays it, else on arrival), and how long it is."""
    from oricf.demo.node import SPOKEN
    from oricf.demo.speech import TOPIC_RATE

    piece = node.next(SPOKEN, timeout)
    if piece is None:
        return
    first_at, samples = piece.at, 0
    while piece is not None:
        samples += len(piece.value)
        piece = node.next(SPOKEN, SPEECH_GAP_S)
    sounded = player.first_sample_after(sent, 1.0)
    result.first_audio_ms = ((sounded or first_at) - sent) * 1000
    result.spoken_s = samples / TOPIC_RATE
    player.wait_played(60)


def detector_latency_ms(counts: list[Any], replay: Any, since: float) -> float | None:
    """Median of (count received - latest frame sent before it) over the counts received
    while the question ran (else the last ten). Exact while a frame is counted before the
    next one is sent, which holds when the detector keeps up with the frame rate."""
    window = [c for c in counts if c.at >= since] or counts[-10:]
    delays = []
    for count in window:
        sent = replay.last_sent_before(count.at)
        if sent is not None:
            delays.append((count.at - sent) * 1000)
    return statistics.median(delays) if delays else None


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f} ms"


def format_result(index: int, r: Result) -> str:
    missing = "(nothing within the timeout)"
    return "\n".join([
        f"\nQ{index}: {r.question}",
        f"  transcript : {missing if r.transcript is None else r.transcript}",
        f"  people     : {'-' if r.count is None else r.count}",
        f"  answer     : {missing if r.answer is None else r.answer}",
        f"  latency    : ASR {_ms(r.asr_ms)} | detector {_ms(r.detector_ms)} | "
        f"LLM {_ms(r.llm_ms)} | total {_ms(r.total_ms)}",
        *([f"  spoken     : first audio {_ms(r.first_audio_ms)} after the question, "
           f"{r.spoken_s:.1f} s of speech"] if r.spoken_s is not None else []),
    ])


def format_summary(results: list[Result]) -> str:
    done = sum(r.complete for r in results)
    totals = [r.total_ms for r in results if r.total_ms is not None]
    median = f"; median total {statistics.median(totals):.0f} ms" if totals else ""
    firsts = [r.first_audio_ms for r in results if r.first_audio_ms is not None]
    if firsts:
        median += f"; median first audio {statistics.median(firsts):.0f} ms"
    return f"\n{done}/{len(results)} questions answered{median}"
