"""The processes of `oricf bench offload`, each started in its CPU set: the robot's camera
and gateway, the detector and language model on the robot or the edge, and the client that
types questions into the gateway's text channel."""

from __future__ import annotations

import contextlib
import copy
import json
import logging
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml

from oricf.bench.common import stop
from oricf.bench.cpusets import CpuSet
from oricf.bench.netns import EdgeHost
from oricf.bench.relay import DelayRelay
from oricf.config import config_dir, read_yaml
from oricf.hosts import Address
from oricf.launch.health import free_port, wait_serving

log = logging.getLogger(__name__)

SERVICES = ("detector", "llm")
EDGE_PORTS = {"detector": 50051, "llm": 50053}  # inside the edge's network namespace
QUESTION = "How many people do you see?"


def oricf(*args: str) -> list[str]:
    return [sys.executable, "-m", "oricf", "--log-level", "WARNING", *args]


class Robot:
    """The camera (running from start to end) and, per placement and phase, the services
    and the gateway. `counts` collects the people route's JSON lines."""

    def __init__(self, sets: dict[str, CpuSet], edge: EdgeHost | None,
                 link: dict[str, float] | None, work: Path, logs: Path, fps: float) -> None:
        self.sets = sets
        self.edge = edge
        self.link = link or {}
        self.work = work
        self.logs = logs
        self.fps = fps
        self.counts = work / "counts.jsonl"
        self.channel = f"127.0.0.1:{free_port()}"
        self._counts_from = 0
        self._stack = ExitStack()

    def __enter__(self) -> Robot:
        self.logs.mkdir(parents=True, exist_ok=True)
        port = free_port()
        camera = self.start(self.sets["robot"], [
            sys.executable, "-m", "oricf.bench.mjpeg_camera", str(port), "--fps",
            str(self.fps)], "camera", stdout=subprocess.PIPE)
        self._stack.callback(stop, camera)
        if camera.stdout is None or camera.stdout.readline().strip() != b"ready":
            self._stack.close()
            raise RuntimeError(f"the camera did not start; see {self.logs / 'camera.log'}")
        self.pipelines = write_pipelines(self.work, f"http://127.0.0.1:{port}/", self.channel,
                                         self.counts)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stack.close()

    def start(self, cpuset: CpuSet, argv: list[str], name: str, **kwargs: Any
              ) -> subprocess.Popen[Any]:
        """argv in cpuset, its output appended to logs/NAME.log."""
        with (self.logs / f"{name}.log").open("ab") as log_file:
            kwargs.setdefault("stdout", log_file)
            return cpuset.popen(argv, stderr=log_file, **kwargs)

    @contextmanager
    def services(self, placement: str) -> Iterator[dict[str, str]]:
        """The detector and the language model where `placement` puts them, SERVING; yields
        the address the robot calls each at."""
        remote = self.edge if placement == "edge" else None
        cpuset = self.sets["robot" if placement == "onboard" else "edge"]
        with ExitStack() as stack:
            started = {}
            for name in SERVICES:
                address = (f"{remote.address}:{EDGE_PORTS[name]}" if remote
                           else f"127.0.0.1:{free_port()}")
                argv = oricf("serve", name, "--listen", address)
                process = self.start(cpuset, remote.exec_argv(argv) if remote else argv,
                                     f"{placement}-{name}")
                stack.callback(stop, process)
                started[name] = address, process
            endpoints = {}
            for name, (address, process) in started.items():
                wait_serving(address, timeout=300, process=process)
                endpoints[name] = self._over_link(address, stack) if remote else address
            yield endpoints

    def _over_link(self, address: str, stack: ExitStack) -> str:
        """The address through a delaying relay if the link has a delay."""
        if not self.link.get("delay_s"):
            return address
        upstream = Address.parse(address)
        relay = DelayRelay((upstream.host, upstream.port), self.link["delay_s"],
                           self.link.get("jitter_s", 0))
        stack.callback(relay.close)
        return relay.address

    @contextmanager
    def gateway(self, pipeline: str, placement: str, endpoints: dict[str, str]
                ) -> Iterator[subprocess.Popen[Any]]:
        """`oricf gateway` on the robot: the pipeline ("base" or "cnn") with the shipped
        placement overlay, the endpoints' addresses set and their fallbacks removed."""
        overlay = config_dir() / "pipelines" / "placement" / f"{placement}.yaml"
        argv = oricf("gateway", "--config", str(self.pipelines[pipeline]), "--overlay",
                     str(overlay))
        for name, address in endpoints.items():
            argv += ["--set", f"endpoints.{name}.address={json.dumps(address)}",
                     "--set", f"endpoints.{name}.fallback=~"]
        self._counts_from = self.counts.stat().st_size if self.counts.exists() else 0
        process = self.start(self.sets["robot"], argv, f"{placement}-gateway-{pipeline}")
        try:
            wait_listening(self.channel, process)
            yield process
        finally:
            stop(process)

    def wait_counts(self, timeout: float = 120) -> None:
        """Until the people route has counted a frame since the gateway started."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.counts.exists() and self.counts.stat().st_size > self._counts_from:
                return
            time.sleep(0.2)
        raise RuntimeError(f"no count in {timeout:g} s; see the gateway's log in {self.logs}")


def write_pipelines(folder: Path, camera: str, channel: str, counts: Path) -> dict[str, Path]:
    """The shipped text_questions.yaml reading the camera, its counts also written to
    `counts` ("cnn"), and without its camera route ("base")."""
    data = read_yaml(config_dir() / "pipelines" / "text_questions.yaml")
    data["channels"]["questions"]["listen"] = channel
    people = data["routes"]["people"]
    people["input"] = {"url": camera}  # a live stream: the camera sets the rate
    people["outputs"].append({"jsonl": str(counts), "from": "count"})
    base = copy.deepcopy(data)
    del base["routes"]["people"]
    del base["routes"]["ask"]["call"]["context"]  # no count without the camera route
    paths = {}
    for name, pipeline in (("base", base), ("cnn", data)):
        paths[name] = folder / f"pipeline-{name}.yaml"
        paths[name].write_text(yaml.safe_dump(pipeline, sort_keys=False))
    return paths


def wait_listening(address: str, process: subprocess.Popen[Any], timeout: float = 60) -> None:
    channel = Address.parse(address)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"the gateway exited with {process.returncode}")
        try:
            socket.create_connection((channel.host, channel.port), timeout=1).close()
            return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"the gateway's text channel {address} did not open in {timeout:g} s")


def frames_between(counts: Path, begin: float, end: float) -> int:
    """Lines of the people route written between two Unix times."""
    if not counts.exists():
        return 0
    frames = 0
    with counts.open() as lines:
        for line in lines:
            with contextlib.suppress(ValueError):  # the line being written
                frames += begin <= json.loads(line)["time"] < end
    return frames


class Questions:
    """A client of the gateway's text channel typing QUESTION: once on entering (waited for
    by wait_first_answer: the model's first call also fills its prompt cache), then every
    `every` seconds whatever the answers do. The channel answers a client's questions in
    the order asked, so the n-th line answers the n-th question."""

    def __init__(self, address: str, every: float) -> None:
        channel = Address.parse(address)
        self.every = every
        self.asked: list[float] = []     # Unix times
        self.answered: list[float] = []
        self.first_answer = ""
        self._sock = socket.create_connection((channel.host, channel.port), timeout=10)
        self._sock.settimeout(None)
        self._first = threading.Event()
        self._stop = threading.Event()

    def __enter__(self) -> Questions:
        threading.Thread(target=self._read, daemon=True, name="answers").start()
        self._ask()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._sock.close()

    def wait_first_answer(self, timeout: float = 120) -> None:
        if not self._first.wait(timeout):
            raise RuntimeError(f"the first question was not answered in {timeout:g} s")
        log.info("%s -> %s", QUESTION, self.first_answer)
        threading.Thread(target=self._schedule, daemon=True, name="questions").start()

    def between(self, begin: float, end: float) -> tuple[int, list[float]]:
        """Questions asked in [begin, end) and the seconds each one answered by `end` took."""
        pairs = list(zip(self.asked, self.answered, strict=False))
        return (sum(begin <= t < end for t in self.asked),
                [a - q for q, a in pairs if begin <= q < end and a < end])

    def _ask(self) -> None:
        self.asked.append(time.time())
        self._sock.sendall(f"{QUESTION}\n".encode())

    def _schedule(self) -> None:
        due = time.monotonic()
        while not self._stop.wait(max(0.0, due - time.monotonic())):
            try:
                self._ask()
            except OSError:
                return  # closed on exit
            due += self.every

    def _read(self) -> None:
        try:
            with self._sock.makefile("r", encoding="utf-8") as lines:
                for line in lines:
                    self.answered.append(time.time())
                    if not self._first.is_set():
                        self.first_answer = line.strip()
                        self._first.set()
        except OSError:
            pass  # closed on exit
