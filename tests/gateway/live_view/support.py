"""A pipeline with its live view in this process (the people_video pipeline on vtest.avi and
a real detector), and what a viewer receives, decoded with the protobuf schemas the server
advertises (google.protobuf, not the SDK's own classes)."""

from __future__ import annotations

import base64
import contextlib
import json
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from oricf.config import config_dir, deep_merge, read_yaml
from oricf.gateway.config import PipelineConfig, parse_pipeline
from oricf.gateway.host.gateway import Gateway
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Record
from tests.support.data import video_path

PIPELINE = config_dir() / "pipelines" / "people_video.yaml"
SUBPROTOCOL = "foxglove.sdk.v1"


def video_pipeline(detector: str, foxglove: dict[str, Any] | None = None,
                   fps: float = 20, post: list[dict[str, Any]] | None = None
                   ) -> PipelineConfig:
    """people_video.yaml on vtest.avi at `fps` (with other post steps if given), counts to
    a product (plotted), with a live view on a free loopback port."""
    route: dict[str, Any] = {"input": {"url": str(video_path()), "fps": fps, "loop": True},
                             "outputs": [{"product": "people_count", "from": "count"}]}
    if post is not None:
        route["post"] = post
    data = deep_merge(read_yaml(PIPELINE), {
        "endpoints": {"detector": {"address": detector}}, "routes": {"people": route},
        "foxglove": {"listen": "127.0.0.1:0", **(foxglove or {})}})
    return parse_pipeline(data, f"{PIPELINE} (test overlay)", PIPELINE.parent)


@dataclass
class Running:
    gateway: Gateway
    records: list[Record] = field(default_factory=list)

    @property
    def pipeline(self) -> Pipeline:
        return self.gateway.pipeline

    @property
    def url(self) -> str:
        assert self.gateway.live_view is not None
        return self.gateway.live_view.url


class Kept:
    """A route watcher keeping a copy of each record it is shown."""

    def __init__(self, records: list[Record]) -> None:
        self.records = records
        self._lock = threading.Lock()

    def show(self, route: str, record: Record) -> None:
        with self._lock:
            self.records.append(dict(record))


@contextmanager
def running(config: PipelineConfig) -> Iterator[Running]:
    """The pipeline started with its sources; every record the route finished is kept."""
    gateway = Gateway(config)
    gateway.configure()
    run = Running(gateway)
    kept = Kept(run.records)
    for route in gateway.pipeline.routes.values():
        route.watchers.append(kept)
    gateway.activate()
    try:
        yield run
    finally:
        gateway.deactivate()
        gateway.cleanup()


class Decoder:
    """Channels as advertised, and their messages decoded by schema (protobuf from the
    advertised FileDescriptorSet, or JSON)."""

    def __init__(self) -> None:
        self.channels: dict[int, dict[str, Any]] = {}
        self._pool = descriptor_pool.DescriptorPool()
        self._types: dict[str, Any] = {}

    def advertise(self, channels: list[dict[str, Any]]) -> None:
        for channel in channels:
            self.channels[channel["id"]] = channel
            if channel["encoding"] == "protobuf" and channel["schemaName"] not in self._types:
                files = descriptor_pb2.FileDescriptorSet.FromString(
                    base64.b64decode(channel["schema"]))
                for file in files.file:
                    with contextlib.suppress(TypeError):  # added by another schema
                        self._pool.Add(file)
                self._types[channel["schemaName"]] = message_factory.GetMessageClass(
                    self._pool.FindMessageTypeByName(channel["schemaName"]))

    def decode(self, channel_id: int, data: bytes) -> tuple[str, Any]:
        """(topic, message) of a message on an advertised channel."""
        channel = self.channels[channel_id]
        if channel["encoding"] == "json":
            return channel["topic"], json.loads(data)
        return channel["topic"], self._types[channel["schemaName"]].FromString(data)


def message_data(frame: bytes) -> tuple[int, int, bytes]:
    """A binary Message Data frame (op 1): (subscription id, log time ns, payload)."""
    assert frame[0] == 1, frame[:1]
    return (int.from_bytes(frame[1:5], "little"), int.from_bytes(frame[5:13], "little"),
            frame[13:])


def subscribe_all(decoder: Decoder, topics: set[str] | None = None) -> str:
    """The Subscribe message for every advertised channel (or those of `topics`); the
    subscription id is the channel id."""
    return json.dumps({"op": "subscribe", "subscriptions": [
        {"id": cid, "channelId": cid} for cid, ch in decoder.channels.items()
        if topics is None or ch["topic"] in topics]})
