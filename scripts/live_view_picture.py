"""Draws what the live view sends for one frame of vtest.avi: `python
scripts/live_view_picture.py OUT.jpg` (docs/img/live-view-frame.jpg).

Runs the detector service and the people_video pipeline, tracking people (`track`,
`count_tracks`), with its live view; connects as a
viewer, takes a /people/image message and the /people/detections message logged with it,
decodes both with the protobuf schemas the server advertises, and draws the annotations'
outlines and captions on the JPEG as a viewer's image panel does. Nothing is drawn from the
gateway's side: the picture is the two messages a viewer receives.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import json
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from oricf.bench.common import served
from oricf.config import config_dir
from oricf.gateway.config import load_pipeline
from oricf.gateway.inputs import pipeline_sources
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.store import ModelStore

MIN_BOXES = 3


def message_class(pool: Any, channel: dict[str, Any]) -> Any:
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    for file in files.file:
        with contextlib.suppress(TypeError):  # already added with another schema
            pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


def one_frame(url: str, timeout: float = 60) -> tuple[Any, Any]:
    """(CompressedImage, ImageAnnotations) logged together, with at least MIN_BOXES boxes,
    each with its track id."""
    pool, types, topics, images = descriptor_pool.DescriptorPool(), {}, {}, {}
    deadline = time.monotonic() + timeout
    with connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1")], max_size=None) as viewer:
        while time.monotonic() < deadline:
            message = viewer.recv(timeout=timeout)
            if isinstance(message, str):
                advertised = json.loads(message)
                if advertised["op"] != "advertise":
                    continue
                wanted = [c for c in advertised["channels"]
                          if c["topic"] in ("/people/image", "/people/detections")]
                for channel in wanted:
                    topics[channel["id"]] = channel["topic"]
                    types[channel["id"]] = message_class(pool, channel)
                viewer.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": c["id"], "channelId": c["id"]} for c in wanted]}))
                continue
            channel, log_time = (int.from_bytes(message[1:5], "little"),
                                 int.from_bytes(message[5:13], "little"))
            decoded = types[channel].FromString(message[13:])
            if topics[channel] == "/people/image":
                images[log_time] = decoded
            elif len(decoded.points) >= MIN_BOXES and log_time in images \
                    and all("#" in t.text for t in decoded.texts):  # tracked
                return images[log_time], decoded
    raise TimeoutError("no frame with enough people came")


def draw(image: Any, annotations: Any) -> np.ndarray:
    pixels = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
    for outline in annotations.points:
        c = outline.outline_color
        points = np.array([[p.x, p.y] for p in outline.points], np.int32)
        cv2.polylines(pixels, [points], True, (c.b * 255, c.g * 255, c.r * 255),
                      max(1, round(outline.thickness)))
    for text in annotations.texts:
        x, y = int(text.position.x), int(text.position.y)
        (w, h), _ = cv2.getTextSize(text.text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
        b = text.background_color
        cv2.rectangle(pixels, (x, y - h - 4), (x + w + 4, y), (b.b * 255, b.g * 255,
                                                               b.r * 255), -1)
        cv2.putText(pixels, text.text, (x + 2, y - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (255, 255, 255), 1, cv2.LINE_AA)
    return pixels


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    video = ModelStore().path("vtest-video", "vtest.avi")
    with served("detector") as (address, _):
        config = load_pipeline(config_dir() / "pipelines" / "people_video.yaml", sets=[
            f"endpoints.detector.address={address}", f"routes.people.input.url={video}",
            "routes.people.post=[{track: {labels: [person]}}, "
            "{count_tracks: {label: person, into: count}}]",
            "routes.people.outputs=[{product: people_count, from: count}]",
            "foxglove.listen=127.0.0.1:0"])
        outlets = Outlets(config)
        pipeline = Pipeline(config, outlets)
        sources = pipeline_sources(pipeline, outlets.channels, lambda route: None)
        pipeline.start()
        for source in sources:
            source.start()
        try:
            assert pipeline.live_view is not None
            image, annotations = one_frame(pipeline.live_view.url)
        finally:
            for source in sources:
                source.stop()
            pipeline.stop()
    cv2.imwrite(str(args.out), draw(image, annotations), [cv2.IMWRITE_JPEG_QUALITY, 85])
    print(f"{args.out}: {len(annotations.points)} boxes: "
          f"{', '.join(t.text for t in annotations.texts)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
