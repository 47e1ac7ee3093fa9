"""annotate: {into: annotated} draws the detections on the input image (a new frame; the
input is left as it came)."""

from __future__ import annotations

from oricf.config import Schema
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Frame, Record
from oricf.imaging import draw_detections


class AnnotateStep(Schema):
    into: str = "annotated"


def build(step: AnnotateStep) -> Step:
    def run(record: Record) -> None:
        frame: Frame = record["image"]
        record[step.into] = Frame.from_pixels(draw_detections(frame.pixels(),
                                                              record["detections"]))

    return Step(frozenset({"image", "detections"}), step.into, run)


COMPONENT = StepKind("annotate", AnnotateStep, build, rank=3)
