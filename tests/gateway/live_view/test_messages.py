"""Route values as Foxglove messages: frames, annotations with track ids, numbers, text."""

from __future__ import annotations

import base64
import json
from typing import Any

import cv2
import numpy as np

from oricf.gateway.live_view import messages
from oricf.gateway.shells.main import build_parser, main
from oricf.gateway.values import Frame
from oricf.imaging import Box, Detection, encode_image
from tests.gateway.live_view.support import Decoder
from tests.support.data import video_frames


def decoded(message: object) -> object:
    """An SDK message through its own advertised schema, as a viewer decodes it."""
    schema = message.get_schema()  # type: ignore[attr-defined]
    decoder = Decoder()
    decoder.advertise([{"id": 1, "topic": "/t", "encoding": "protobuf",
                        "schemaName": schema.name,
                        "schema": base64.b64encode(schema.data).decode()}])
    return decoder.decode(1, message.encode())[1]  # type: ignore[attr-defined]


def test_a_raw_frame_is_encoded_and_a_jpeg_passes_as_it_came() -> None:
    pixels = video_frames([0])[0]
    raw: Any = decoded(messages.compressed_image(Frame.from_pixels(pixels), "cam", 5, 70))
    assert raw.format == "jpeg" and raw.frame_id == "cam"
    picture = cv2.imdecode(np.frombuffer(raw.data, np.uint8), cv2.IMREAD_COLOR)
    assert picture.shape == pixels.shape
    assert np.abs(picture.astype(int) - pixels).mean() < 8  # the same picture
    jpeg = encode_image(pixels, "jpeg", 90)
    passed: Any = decoded(messages.compressed_image(Frame(jpeg, "jpeg"), "cam", 5, 70))
    assert passed.data == jpeg and passed.format == "jpeg"


def test_each_detection_is_a_closed_box_with_its_label_track_and_score() -> None:
    tracked = Detection("person", 0, 0.876, Box(10, 20, 110, 220), track_id=7)
    new = Detection("dog", 16, 0.5, Box(1.5, 2.5, 3.5, 4.5))
    annotations: Any = decoded(messages.image_annotations([tracked, new], 1_500_000_001))
    first, second = annotations.points
    assert [(p.x, p.y) for p in first.points] == [(10, 20), (110, 20), (110, 220), (10, 220)]
    assert (second.points[0].x, second.points[0].y) == (1.5, 2.5)
    assert first.type == 2 and first.timestamp.seconds == 1  # LINE_LOOP, the frame's time
    assert first.outline_color != second.outline_color  # a colour per label
    assert [(t.text, t.position.x, t.position.y) for t in annotations.texts] == [
        ("person #7 0.88", 10, 20), ("dog 0.50", 1.5, 2.5)]


def test_numbers_and_their_mappings_are_plottable_and_nothing_else() -> None:
    assert messages.plottable(3) == {"value": 3.0}
    assert messages.plottable(2.5) == {"value": 2.5}
    assert messages.plottable({"in": 4, "out": 1, "zone": "door"}) == {"in": 4.0, "out": 1.0}
    for value in (True, "3", None, float("nan"), [1, 2], {"zone": "door"}):
        assert messages.plottable(value) is None
    assert messages.json_schema({"active": "a:1", "failovers": 0, "on_fallback": False}) == {
        "type": "object", "properties": {"active": {"type": "string"},
                                         "failovers": {"type": "number"},
                                         "on_fallback": {"type": "boolean"}}}


def test_a_log_line_is_clipped() -> None:
    line = messages.log_line("x" * 10_000, "qa", 0)
    assert len(line.encode()) < 5000


def test_the_foxglove_flag_sets_the_listen_address(capsys: object) -> None:
    args = build_parser().parse_args(["--foxglove", "127.0.0.1:9999"])
    assert args.foxglove == "127.0.0.1:9999"
    assert main(["--config", "people_video", "--foxglove", "127.0.0.1:9999", "--check"]) == 0


def test_a_json_channels_schema_is_named_after_its_topic() -> None:
    schema = messages.json_channel_schema("/routes/people/state", {"received": 3})
    assert schema.name == "oricf.routes.people.state" and schema.encoding == "jsonschema"
    assert json.loads(schema.data) == {"type": "object",
                                       "properties": {"received": {"type": "number"}}}


def test_a_frame_without_detections_still_carries_its_time() -> None:
    # Viewers that match annotations to images by time need one annotation with the
    # frame's timestamp, or they never show the frame: an invisible circle.
    annotations: Any = decoded(messages.image_annotations([], 1_500_000_001))
    assert not annotations.points and not annotations.texts
    (circle,) = annotations.circles
    assert (circle.timestamp.seconds, circle.timestamp.nanos) == (1, 500_000_001)
    assert circle.diameter == 0 and circle.outline_color.a == 0 and circle.fill_color.a == 0
