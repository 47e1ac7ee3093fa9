"""The live view in a real viewer: Lichtblick's web app, built from its source by
scripts/lichtblick.sh, served on 127.0.0.1 and opened in headless Chromium with the
connection in its URL and the live view's layout; `oricf gateway --foxglove` runs the people
route on vtest.avi with the real detector in a process of its own. What the browser shows,
read from its screenshot and its DOM: the camera image, the detector's boxes drawn over it,
and the count. `ORICF_VIEWER_SCREENSHOT=FILE.jpg` keeps the screenshot (docs/img/)."""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from oricf.config import config_dir
from tests.gateway.live_view.chromium import Page, headless_page
from tests.gateway.live_view.lichtblick import (
    Shown,
    frame_shape,
    lichtblick_web,
    look,
    open_app,
    outline_pixels,
    serving_module,
)
from tests.gateway.live_view.processes import ViewedGateway, gateway_with_view
from tests.support.data import video_frames, video_path
from tests.support.services import RunningService
from tests.support.waiting import wait_for

pytestmark = pytest.mark.viewer
log = logging.getLogger(__name__)

PIPELINE = config_dir() / "pipelines" / "people_video.yaml"
SHOWN_TIMEOUT_S = 180.0  # Lichtblick's start and WebGL on SwiftShader, on 2 busy cores
MIN_OUTLINE_PIXELS = 500  # a few boxes' 2-pixel outlines, scaled to the panel
PLOTTED_FRAMES = 150  # counted before the picture is taken (15 s at 10 fps)


@dataclass
class Viewed:
    shown: Shown
    counts: set[int]      # every count the gateway printed


def overlay(folder: Path, detector: str, labels: list[str]) -> Path:
    """vtest.avi at 10 fps, looped, the detector asked for `labels`; 5 frames/s to view."""
    path = folder / "here.yaml"
    path.write_text(yaml.safe_dump({
        "endpoints": {"detector": {"address": detector, "deadline_ms": 10_000}},
        "routes": {"people": {
            "input": {"url": str(video_path()), "fps": 10, "loop": True},
            "call": {"service": "detector", "method": "Detect", "labels": labels}}},
        "foxglove": {"max_fps": 5}}))
    return path


@contextmanager
def lichtblick_on_view(detector: str, folder: Path, labels: list[str]
                       ) -> Iterator[tuple[ViewedGateway, Page]]:
    """The gateway with its view, and Lichtblick opened on it."""
    with gateway_with_view(folder, "--config", str(PIPELINE), "--overlay",
                           str(overlay(folder, detector, labels))) as gateway, \
            serving_module().serving(lichtblick_web()) as base, \
            headless_page(folder / "profile") as page:
        open_app(page, base, gateway.url)
        try:
            yield gateway, page
        finally:
            log.info("browser console:\n%s", "\n".join(page.console))
            log.info("gateway log:\n%s", "".join(gateway.log))


def watch(page: Page, until: Callable[[Shown], bool], folder: Path) -> Shown:
    """What the browser shows once `until` holds for it, or when the time is up; the last
    screenshot is kept in `folder` for whoever reads a failure."""
    deadline, shown = time.monotonic() + SHOWN_TIMEOUT_S, None
    while (shown is None or not until(shown)) and time.monotonic() < deadline:
        time.sleep(1)  # a screenshot a second: each costs the loaded machine
        shown = look(page)
    assert shown is not None, f"no image panel; the console: {page.console[-20:]}"
    cv2.imwrite(str(folder / "lichtblick.png"), shown.screen)
    return shown


def everything_shown(shown: Shown) -> bool:
    return shown.count.isdigit() and outline_pixels(shown.image) >= MIN_OUTLINE_PIXELS


def is_the_frame(image: np.ndarray) -> bool:
    """The panel shows a photograph of vtest.avi's shape (4:3), not a flat fill."""
    shape = frame_shape(image)
    return shape is not None and abs(shape[1] / shape[0] - 768 / 576) < 0.05


@pytest.fixture(scope="module")
def viewed(detector: RunningService, tmp_path_factory: pytest.TempPathFactory
           ) -> Iterator[Viewed]:
    """Lichtblick on the people route, once everything is shown (or the time is up)."""
    folder = tmp_path_factory.mktemp("lichtblick")
    screenshot = os.environ.get("ORICF_VIEWER_SCREENSHOT")
    with lichtblick_on_view(detector.address, folder, ["person"]) as (gateway, page):
        if screenshot:  # a picture with some history in the plot
            wait_for(lambda: len(gateway.out) >= PLOTTED_FRAMES, SHOWN_TIMEOUT_S,
                     f"{PLOTTED_FRAMES} frames counted")
        shown = watch(page, everything_shown, folder)
        counts = {json.loads(line)["count"] for line in gateway.out if '"count"' in line}
    if screenshot:
        cv2.imwrite(screenshot, shown.screen, [cv2.IMWRITE_JPEG_QUALITY, 80])
    yield Viewed(shown, counts)


def test_lichtblick_shows_the_camera_image(viewed: Viewed) -> None:
    assert frame_shape(viewed.shown.image) is not None, "the image panel is blank"
    assert is_the_frame(viewed.shown.image), frame_shape(viewed.shown.image)


def test_lichtblick_draws_the_detectors_boxes_over_the_image(viewed: Viewed) -> None:
    # vtest.avi itself has little of the outline's colour: what is there was drawn.
    assert max(outline_pixels(f) for f in video_frames([0, 200, 400, 600])) \
        < MIN_OUTLINE_PIXELS / 5
    assert outline_pixels(viewed.shown.image) >= MIN_OUTLINE_PIXELS


def test_lichtblick_shows_the_count(viewed: Viewed) -> None:
    assert viewed.shown.count.isdigit(), repr(viewed.shown.count)
    assert int(viewed.shown.count) in viewed.counts, (viewed.shown.count, viewed.counts)
    # The JSON channel's schema by the name the view gives it, not a random one.
    assert viewed.shown.count_caption.startswith("oricf.people.count @ ")


def test_lichtblick_shows_a_frame_without_detections(detector: RunningService,
                                                      tmp_path: Path) -> None:
    # Nothing on vtest.avi is a bicycle: each frame's annotations are empty, and the Image
    # panel, matching annotations to frames by time, still shows the frame.
    with lichtblick_on_view(detector.address, tmp_path, ["bicycle"]) as (_, page):
        shown = watch(page, lambda s: is_the_frame(s.image) and s.count == "0", tmp_path)
    assert is_the_frame(shown.image), frame_shape(shown.image)
    assert outline_pixels(shown.image) < MIN_OUTLINE_PIXELS / 5
    assert shown.count == "0"
