"""annotate: {into: annotated} draws the detections on the input image (a new frame; the
input is left as it came)."""

from __future__ import annotations

from oricf.config import Schema
from oricf.gateway.post.base import Step, StepKind
from oricf.gateway.values import Frame, Record
from oricf.imaging import draw_detections


class AnnotateStep(Schema):
    into: str = "annotated"


class Annotate(Step[AnnotateStep]):
    reads = frozenset({"image", "detections"})

    def __init__(self, settings: AnnotateStep) -> None:
        super().__init__(settings)
        self.writes = settings.into

    def run(self, record: Record) -> None:
        frame: Frame = record["image"]
        record[self.settings.into] = Frame.from_pixels(draw_detections(frame.pixels(),
                                                                       record["detections"]))


COMPONENT = StepKind("annotate", AnnotateStep, Annotate, rank=3)
