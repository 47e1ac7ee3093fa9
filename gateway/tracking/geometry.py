"""Where a tracked box is, for zones and lines: its anchor point, inside a polygon or not,
and which side of a line."""

from __future__ import annotations

from typing import Literal

import numpy as np

from oricf.imaging import Box

Point = tuple[float, float]
Anchor = Literal["bottom", "center"]


def anchor_point(box: Box, anchor: Anchor) -> Point:
    """The box's bottom centre (where a person stands) or its centre."""
    x = (box.x_min + box.x_max) / 2
    return (x, box.y_max) if anchor == "bottom" else (x, (box.y_min + box.y_max) / 2)


class Polygon:
    def __init__(self, points: list[Point]) -> None:
        self._contour = np.array(points, dtype=np.float32).reshape(-1, 1, 2)

    def contains(self, point: Point) -> bool:
        """Inside or on the edge."""
        import cv2  # here: a pipeline's schema, which names zone steps, loads no OpenCV

        return cv2.pointPolygonTest(self._contour, (float(point[0]), float(point[1])),
                                    False) >= 0


def side(start: Point, end: Point, point: Point) -> float:
    """> 0: right of the line from start to end as seen in the image (y down); < 0: left."""
    return ((end[0] - start[0]) * (point[1] - start[1])
            - (end[1] - start[1]) * (point[0] - start[0]))


def segments_cross(a: Point, b: Point, start: Point, end: Point) -> bool:
    """Whether the move from a to b crosses the segment start-end (not just its line)."""
    return (side(start, end, a) * side(start, end, b) < 0
            and side(a, b, start) * side(a, b, end) <= 0)
