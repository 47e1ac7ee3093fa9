"""Recording a pipeline's topics into an MCAP file, laid out as rosbag2 writes it.

    oricf gateway --config PIPELINE.yaml --record run.mcap

Every message a topic route takes in, and every message a route sends to a topic, becomes
one MCAP message on the channel of its topic (the full ROS name, e.g. /camera/image_raw),
schema encoding `ros2msg` (the complete definition, oricf.gateway.topics.definitions),
message encoding `cdr` (written by the topic codec, oricf.gateway.topics.codec),
profile `ros2`: `ros2 bag info` and `ros2 bag play`, mcap-ros2-support and Foxglove read it,
and `oricf gateway --replay` plays it back without ROS (replay.py).

Times, in nanoseconds since the epoch:
- an input: log_time = when the gateway received it; publish_time = when its publisher sent
  it (the DDS source timestamp, as rosbag2 records it; in a replay, the recording's own);
- an output: log_time = when the gateway sent it; publish_time = the publish_time of the
  input it came from.
So each output points at its input on the route's input topic, and the outputs of two runs
over the same inputs (a run and its replay) point at the same input messages. Outputs of
routes fed by a data product have no input message: their publish_time is their log_time.

The file is written on a thread of its own: lz4 chunk compression costs milliseconds per
raw camera frame, which a camera route should not wait for. Live, a message that finds
QUEUE_BYTES already waiting (a disk slower than the cameras) is left out of the recording
and counted; a replay waits instead, so its recording is complete.
"""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, BinaryIO

from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType, Writer

from oricf.errors import InvalidInput, OricfError
from oricf.gateway.components import Emitter
from oricf.gateway.config import OutputConfig
from oricf.gateway.route import Loader
from oricf.gateway.sinks.jsonl import jsonable
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.topics import codec
from oricf.gateway.topics import definitions as msgdefs
from oricf.gateway.values import Record

log = logging.getLogger(__name__)

# Record field: the publish time (ns) of the input message a record came from.
INPUT_TIME = "input_publish_ns"
QUEUE_BYTES = 128 * 2**20
CHUNK_BYTES = 2**20


class RecordingError(OricfError):
    """A recording that cannot be written or read; the message names the file."""


def ros_name(topic: str) -> str:
    """A topic as a node in the root namespace names it: relative names get a leading /."""
    return topic if topic.startswith("/") else f"/{topic}"


def linked(load: Loader, input_ns: int) -> Loader:
    """An input message's loader whose record carries INPUT_TIME = input_ns (its publish
    time), so that the outputs made from it can point back at it."""

    def load_linked() -> Record:
        record = load()
        record[INPUT_TIME] = input_ns
        return record

    return load_linked


def message_times(info: dict[str, Any]) -> tuple[int, int]:
    """(received, sent) in ns from rclpy's message info; now for a time the RMW left 0."""
    now = time.time_ns()
    return info.get("received_timestamp") or now, info.get("source_timestamp") or now


class Recorder:
    """One MCAP file being written; write() is safe from any thread."""

    def __init__(self, path: Path, wait_when_full: bool = False) -> None:
        self.path = path
        self.written = 0
        self.dropped = 0
        self._wait_when_full = wait_when_full
        try:
            self._file: BinaryIO = open(path, "xb")  # noqa: SIM115 (closed by close())
        except FileExistsError:
            raise RecordingError(f"{path}: exists already; record into a new file") from None
        except OSError as exc:
            raise RecordingError(f"{path}: cannot create it: {exc.strerror}") from None
        self._writer = Writer(self._file, chunk_size=CHUNK_BYTES,
                              compression=CompressionType.LZ4)
        self._writer.start(profile=Profile.ROS2, library="oricf gateway")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, list[int]]] = {}  # topic -> id, [sequence]
        self._queue: deque[tuple[str, str, bytes, int, int]] = deque()
        self._queued_bytes = 0
        self._cond = threading.Condition()
        self._closing = False
        self._failed = False
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()
        log.info("recording topics into %s", path)

    def write(self, topic: str, type_: str, data: bytes, log_time: int,
              publish_time: int) -> None:
        """Queues one serialized message of a type of msgdefs.DEFINITIONS for writing."""
        with self._cond:
            if self._wait_when_full:
                self._cond.wait_for(lambda: self._queued_bytes < QUEUE_BYTES or self._closing
                                    or self._failed)
            if self._closing:  # a route finishing its last item during shutdown
                return
            if self._failed or self._queued_bytes >= QUEUE_BYTES:
                self.dropped += 1
                return
            self._queue.append((topic, type_, data, log_time, publish_time))
            self._queued_bytes += len(data)
            self._cond.notify_all()

    def input(self, topic: str, type_: str, data: bytes, received_ns: int, sent_ns: int,
              load: Loader) -> Loader:
        """Records one input message; returns its loader, whose record carries INPUT_TIME
        so that the outputs made from it point back at it."""
        self.write(topic, type_, data, received_ns, sent_ns)
        return linked(load, sent_ns)

    def output(self, topic: str, type_: str, value: Any, record: Record) -> None:
        """Records one output message (ValueError or TypeError if the value does not fit)."""
        data = codec.serialize(type_, value, record.get("header"))
        now = time.time_ns()
        self.write(topic, type_, data, now, int(record.get(INPUT_TIME, now)))

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._queue or self._closing)
                if not self._queue:
                    return
                topic, type_, data, log_time, publish_time = self._queue.popleft()
            try:
                self._add(topic, type_, data, log_time, publish_time)
            except Exception as exc:  # e.g. the disk is full: stop recording, keep routing
                if isinstance(exc, OSError):
                    log.error("%s: cannot write (%s): recording stopped", self.path, exc)
                else:
                    log.exception("%s: recording stopped", self.path)
                with self._cond:
                    self._failed = True
                    self.dropped += len(self._queue) + 1
                    self._queue.clear()
                    self._queued_bytes = len(data)
            with self._cond:
                self._queued_bytes -= len(data)
                self._cond.notify_all()

    def _add(self, topic: str, type_: str, data: bytes, log_time: int,
             publish_time: int) -> None:
        if topic not in self._channels:
            if type_ not in self._schemas:
                self._schemas[type_] = self._writer.register_schema(
                    msgdefs.schema_name(type_), SchemaEncoding.ROS2,
                    msgdefs.complete_definition(type_).encode())
            # rosbag2 keeps the publishers' QoS here; "" means unknown (play uses defaults)
            channel = self._writer.register_channel(
                topic, MessageEncoding.CDR, self._schemas[type_],
                {"offered_qos_profiles": ""})
            self._channels[topic] = (channel, [0])
        channel, sequence = self._channels[topic]
        sequence[0] += 1
        self._writer.add_message(channel, log_time, data, publish_time, sequence[0])
        self.written += 1

    def close(self) -> None:
        """Writes what is queued, then the summary (the file's index), and closes it."""
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self._thread.join()
        try:
            if not self._failed:
                self._writer.finish()
        except OSError as exc:
            log.error("%s: cannot finish the file (%s)", self.path, exc)
        finally:
            try:
                self._file.close()
            except OSError as exc:  # the last buffered bytes could not be written
                log.error("%s: cannot close the file (%s)", self.path, exc)
        log.info("recorded %d messages into %s%s", self.written, self.path,
                 f" ({self.dropped} left out: the disk did not keep up or failed)"
                 if self.dropped else "")


class TopicOutputs(Emitter):
    """The pipeline's ROS outputs when no ROS node publishes them (a replay): each topic
    output serialized by the topic codec into the recording, or
    without one to standard output as JSON lines (the jsonl sink's objects plus "topic" and
    "input_ns", the publish time of the input they came from)."""

    def __init__(self, recorder: Recorder | None = None) -> None:
        self._recorder = recorder
        self._lock = threading.Lock()
        self._throttle = ThrottledLog(log)

    def emit(self, output: OutputConfig, value: Any, record: Record) -> None:
        assert output.topic is not None and output.type is not None
        topic = ros_name(output.topic)
        if self._recorder is None:
            line = json.dumps({"route": record.get("route", ""), "time": round(time.time(), 3),
                               "topic": topic, "input_ns": record.get(INPUT_TIME),
                               output.source: jsonable(value)})
            with self._lock:
                sys.stdout.write(line + "\n")
                sys.stdout.flush()
            return
        try:
            self._recorder.output(topic, output.type, value, record)
        except (TypeError, ValueError, InvalidInput) as exc:  # a value that does not fit
            # the topic type, or a type without a writer
            self._throttle.error(f"emit:{topic}", "cannot record %r on %s (%s): %s", value,
                                 topic, output.type, exc)
