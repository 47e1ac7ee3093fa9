"""vision_msgs/Detection2DArray written without ROS: a decoder that knows only the complete
definition the recording carries reads back every field of every detection."""

from __future__ import annotations

import pytest
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from oricf.gateway.topics import cdr
from oricf.gateway.topics import definitions as msgdefs
from oricf.gateway.topics.codec import serialize
from oricf.imaging import Box, Detection

TYPE = "vision_msgs/Detection2DArray"


def decode(data: bytes) -> object:
    schema = Schema(id=1, name=msgdefs.schema_name(TYPE), encoding="ros2msg",
                    data=msgdefs.complete_definition(TYPE).encode())
    decoder = DecoderFactory().decoder_for("cdr", schema)
    assert decoder is not None
    return decoder(data)


@pytest.mark.parametrize("count", [0, 1, 3])
def test_detections_read_back_field_by_field(count: int) -> None:
    detections = [Detection("person" if i % 2 else "dog", i, 0.25 + i / 10,
                            Box(10.5 * i, 20, 30.5 * i + 40, 100), track_id=i or None)
                  for i in range(count)]
    data = serialize(TYPE, detections, cdr.Stamp(1700, 5, "front_camera"))
    message = decode(data)
    assert (message.header.stamp.sec, message.header.frame_id) == (1700, "front_camera")
    assert len(message.detections) == count
    for d, m in zip(detections, message.detections, strict=True):
        b = d.box
        assert m.id == ("" if d.track_id is None else str(d.track_id))
        assert m.header.frame_id == "front_camera"
        assert [(r.hypothesis.class_id, r.hypothesis.score) for r in m.results] == \
            [(d.label, pytest.approx(d.score))]
        assert m.results[0].pose.pose.orientation.w == 1.0
        assert list(m.results[0].pose.covariance) == [0.0] * 36
        assert (m.bbox.center.position.x, m.bbox.center.position.y, m.bbox.center.theta,
                m.bbox.size_x, m.bbox.size_y) == pytest.approx(
            ((b.x_min + b.x_max) / 2, (b.y_min + b.y_max) / 2, 0.0, b.x_max - b.x_min,
             b.y_max - b.y_min))


def test_a_value_that_is_no_list_of_detections_is_a_type_error() -> None:
    for value in (3, ["person"]):
        with pytest.raises(TypeError):
            serialize(TYPE, value)
