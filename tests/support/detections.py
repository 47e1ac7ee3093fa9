"""Counting a detector's answer: the service returns detections, and counting them is the
gateway's `count` step, so a test counts the detections it got back."""

from __future__ import annotations

from oricf.v1 import detector_pb2


def count(response: detector_pb2.DetectResponse, label: str = "person") -> int:
    """How many of the response's detections carry `label`."""
    return sum(d.label == label for d in response.detections)
