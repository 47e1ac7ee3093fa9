"""Topic inputs from an MCAP recording instead of DDS, without ROS (rclpy is never imported):

    oricf gateway --config PIPELINE.yaml --replay run.mcap [--rate 1] [--record out.mcap]

The file is a rosbag2 recording (`ros2 bag record -s mcap`), or one the gateway wrote with
--record. Its messages are read in file order; each on a topic some route reads (the
route's topic as a ROS name: camera/image_raw is /camera/image_raw) goes to that route, the
rest are skipped. Each message becomes its route's record through the topic codec
(oricf.gateway.topics.codec) as the ROS node's do: camera frames from their serialized bytes,
the others once mcap-ros2-support has decoded them with the definition in the file (or the
gateway's own, oricf.gateway.topics.definitions, if the file has none).

A camera frame's time (values.FRAME_TIME, what the track step measures time by) is its
header's stamp, when the camera took it, or the log time, when it was recorded, for a
camera that leaves the stamp zero: the recorded time, whatever the rate, so tracks, their
ages and "seen in the last minute" come out as they did live.

`rate` 1 plays at the recorded pace, 2 twice as fast (0.01 to 1000); a camera route then
keeps only the newest frame, as it would live. A gap of more than a minute of recorded time
between messages is skipped with a warning (pace.py). `rate` 0 plays as fast as the
routes take the messages and every message is processed, none dropped as stale, so two
replays of one file give comparable counts. The routes end when the file has been played
and they are idle.

At start, a file that is not MCAP, cannot be opened, or gives a route's topic another type
is refused (RecordingError: exit code 2). A message that cannot be decoded is logged and
skipped. Damage further in (a recording cut short) ends the replay there with an error, and
the gateway exits with code 1 after finishing what was read.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap_ros2.decoder import DecoderFactory

from oricf.gateway.config import InputConfig, PipelineConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.recording.mcap_reader import McapFile
from oricf.gateway.recording.pace import Pace
from oricf.gateway.recording.recorder import Recorder, RecordingError, linked, ros_name
from oricf.gateway.route import Loader
from oricf.gateway.sources.base import OnEnd, Source
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.topics import definitions as msgdefs
from oricf.gateway.topics.codec import input_loader, timed
from oricf.gateway.topics.types import ros_type
from oricf.logs import quoted

log = logging.getLogger(__name__)

ROOM_WAIT_S = 0.5  # how often a replay waiting for a busy route checks for a stop


@dataclass(frozen=True)
class Feed:
    """How the messages of one channel reach the routes that read its topic."""

    topic: str
    type: str
    routes: dict[str, InputConfig]
    decode: Callable[[bytes], Any] | None  # None: camera frames, read by the route itself


class Replay:
    """A recording played into a pipeline's topic routes, on a thread of its own."""

    def __init__(self, path: Path, config: PipelineConfig, rate: float = 1.0,
                 recorder: Recorder | None = None) -> None:
        self.path = path
        self.rate = rate
        self._pace = Pace(path, rate)  # refuses a rate out of range before the file opens
        self.recorder = recorder
        self.played = 0
        self.skipped = 0  # messages of topics no route reads
        self.undecodable = 0
        self.damaged = False
        self._wanted: dict[str, dict[str, InputConfig]] = {}
        for name, route in config.routes.items():
            if route.input.topic is not None:
                self._wanted.setdefault(ros_name(route.input.topic), {})[name] = route.input
        if not self._wanted:
            raise RecordingError(f"{path}: no route of the pipeline reads a topic, so there "
                                 f"is nothing to replay into")
        self._file = McapFile(path)
        self._schemas: dict[int, Schema] = {}
        self._feeds: dict[int, Feed | None] = {}
        try:
            self._check_summary()
        except BaseException:
            self._file.close()
            raise
        self._seen: set[str] = set()
        self._throttle = ThrottledLog(log)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started = False

    def _check_summary(self) -> None:
        """With a summary, every channel is checked before anything plays."""
        summary = self._file.summary
        if summary is None:
            log.warning("%s has no summary (a recording cut short?): its topics are checked "
                        "as they come", self.path)
            return
        self._schemas.update(summary.schemas)
        problems = []
        for channel in summary.channels.values():
            try:  # the file's strings (topics, types, encodings) are quoted where logged
                self._feeds[channel.id] = self._feed(channel)
            except RecordingError as exc:
                problems.append(str(exc))
        if problems:
            raise RecordingError("\n".join(problems))
        present = {c.topic for c in summary.channels.values()}
        shown = ", ".join(sorted(quoted(topic, 80) for topic in present))  # the file's names
        missing = sorted(set(self._wanted) - present)
        if len(missing) == len(self._wanted):
            raise RecordingError(f"{self.path}: none of the routes' topics "
                                 f"({', '.join(sorted(self._wanted))}) is in the file (it "
                                 f"has: {shown or 'no topics'})")
        for topic in missing:
            log.warning("%s: no messages on %s (routes %s)", self.path, topic,
                        ", ".join(self._wanted[topic]))
        counts = summary.statistics.message_count if summary.statistics else "?"
        log.info("%s: %s messages; topics: %s", self.path, counts, shown)

    def _feed(self, channel: Channel) -> Feed | None:
        """How to play a channel, None if no route reads it; RecordingError if its type or
        encoding is not what the routes read."""
        routes = self._wanted.get(channel.topic)
        if not routes:
            return None
        schema = self._schemas.get(channel.schema_id)
        found = msgdefs.type_name(schema.name) if schema is not None else ""
        for name, config in routes.items():
            if found != config.type:  # the file's type name, quoted: it may be anything
                told = quoted(found, 80) if found else "a type not named"
                raise RecordingError(f"{self.path}: topic {channel.topic} is {told} in the "
                                     f"file; route {name} reads {config.type}")
        type_ = found
        if channel.message_encoding != MessageEncoding.CDR:
            raise RecordingError(f"{self.path}: topic {channel.topic} is encoded "
                                 f"{quoted(channel.message_encoding)}, not cdr")
        assert schema is not None
        decode = None if ros_type(type_).frames else self._decoder(channel, schema, type_)
        return Feed(channel.topic, type_, routes, decode)

    def _decoder(self, channel: Channel, schema: Schema, type_: str) -> Callable[[bytes], Any]:
        if schema.encoding != SchemaEncoding.ROS2 or not schema.data:  # e.g. ros2idl, none
            schema = Schema(id=schema.id, name=schema.name, encoding=SchemaEncoding.ROS2,
                            data=msgdefs.complete_definition(type_).encode())
        try:
            decoder = DecoderFactory().decoder_for(MessageEncoding.CDR, schema)
        except Exception as exc:  # mcap-ros2-support's parser: any failure is a bad schema
            raise RecordingError(f"{self.path}: topic {channel.topic}: its definition of "
                                 f"{quoted(schema.name)} cannot be used: "
                                 f"{quoted(exc)}") from None
        assert decoder is not None
        return decoder

    def sources(self, pipeline: Pipeline, on_end: OnEnd) -> list[Source]:
        """A handle per topic route (a Source feeds one route), all on this one replay."""
        routes = [name for routes in self._wanted.values() for name in routes]
        handles = [ReplayHandle(name, self) for name in routes]

        def ended() -> None:
            for name in routes:
                on_end(name)

        self._thread = threading.Thread(target=self._run, args=(pipeline, ended),
                                        name="replay", daemon=True)
        return list(handles)

    def start(self) -> None:
        if self._thread is not None and not self._started:
            self._started = True
            self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self, pipeline: Pipeline, ended: Callable[[], None]) -> None:
        started = time.monotonic()
        try:
            self._play(pipeline)
        except RecordingError as exc:
            self.damaged = True
            log.error("%s; the replay ends here", exc)
        except Exception:  # a bug must still end the replay, or the gateway never exits
            self.damaged = True
            log.exception("%s: the replay failed; it ends here", self.path)
        finally:
            self._file.close()
        seconds = time.monotonic() - started
        log.info("%s: %d messages played in %.1f s (%.1f/s), %d of other topics skipped%s",
                 self.path, self.played, seconds, self.played / max(seconds, 1e-9),
                 self.skipped, f", {self.undecodable} undecodable" if self.undecodable else "")
        if self._file.summary is None:
            for topic in sorted(set(self._wanted) - self._seen):
                log.warning("%s: no messages on %s (routes %s)", self.path, topic,
                            ", ".join(self._wanted[topic]))
        while not self._stop.is_set() and not pipeline.idle(ROOM_WAIT_S):
            pass  # the last messages are still in the routes
        ended()

    def _play(self, pipeline: Pipeline) -> None:
        for record in self._file.records():
            if self._stop.is_set():
                return
            if isinstance(record, Schema):
                self._schemas[record.id] = record
            elif isinstance(record, Channel):
                if record.id not in self._feeds:
                    self._feeds[record.id] = self._checked(record)
            elif (feed := self._feeds.get(record.channel_id)) is None:
                self.skipped += 1
            else:
                self._stop.wait(self._pace.wait_s(record.log_time, time.monotonic()))
                self._deliver(pipeline, feed, record)

    def _checked(self, channel: Channel) -> Feed | None:
        """A channel met in the data (no summary): refused ones are logged and skipped."""
        try:
            return self._feed(channel)
        except RecordingError as exc:
            log.error("%s; its messages are skipped", exc)
            return None

    def _deliver(self, pipeline: Pipeline, feed: Feed, message: Message) -> None:
        loaders = self._loaders(feed, message)
        if loaders is None:
            return
        self.played += 1
        self._seen.add(feed.topic)
        if self.recorder is not None:
            self.recorder.write(feed.topic, feed.type, message.data, time.time_ns(),
                                message.publish_time)
        for route, load in loaders.items():
            if self.rate == 0:  # every message processed: wait for room, never drop
                worker = pipeline.workers[route]
                while not worker.wait_room(ROOM_WAIT_S) and not self._stop.is_set():
                    pass
            pipeline.submit(route, linked(load, message.publish_time))

    def _loaders(self, feed: Feed, message: Message) -> dict[str, Loader] | None:
        """A loader per route for one message, None if it cannot be decoded (logged)."""
        data = message.data
        if feed.decode is None:  # frames taken when stamped, else when recorded
            return {route: timed(input_loader(feed.type, data), message.log_time)
                    for route in feed.routes}
        try:
            decoded = feed.decode(data)
        except Exception as exc:  # mcap-ros2-support raises whatever its reader meets
            self.undecodable += 1
            self._throttle.warning(f"decode:{feed.topic}", "%s: a message on %s (%s) cannot "
                                   "be decoded (%s); skipped", self.path, feed.topic,
                                   feed.type, quoted(exc or type(exc).__name__))
            return None
        return {route: input_loader(feed.type, decoded, config.sample_rate, config.channels)
                for route, config in feed.routes.items()}

    def close(self) -> int:
        """Ends the replay and closes its recorder; the exit code: 1 if the file was damaged
        partway, else 0."""
        self.stop()
        self._file.close()
        if self.recorder is not None:
            self.recorder.close()
        return 1 if self.damaged else 0


class ReplayHandle:
    """One route's view of a replay (sources.base.Source); the replay starts with the first
    handle started and stops with the first stopped."""

    def __init__(self, route: str, replay: Replay) -> None:
        self.route = route
        self._replay = replay

    def start(self) -> None:
        self._replay.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._replay.stop(timeout)

