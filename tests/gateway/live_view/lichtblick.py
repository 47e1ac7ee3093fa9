"""Lichtblick's web app (scripts/lichtblick.sh builds it) opened in headless Chromium on a live
view, with the live view's layout (docs/live-view-layout.json): what the browser shows, read
from its DOM and from the pixels of its screenshot."""

from __future__ import annotations

import json
import subprocess
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import cv2
import numpy as np
import pytest

from oricf.gateway.live_view.messages import PALETTE
from tests.gateway.live_view.chromium import Page
from tests.support.scripts import SCRIPTS, load_script

IMAGE_PANEL = "Image!people"
COUNT_PANEL = "RawMessages!count"
# The outline colour of a person's box (gateway/live_view/messages.py: label_color), BGR.
PERSON_BGR = np.array([round(c * 255) for c in reversed(PALETTE[zlib.crc32(b"person")
                                                                 % len(PALETTE)])])
TOLERANCE = 40  # per channel: the outline is antialiased and drawn over the frame

# Lichtblick's workspace as it stores it, with both sidebars closed: the panels get the
# whole window. Seeded before the app loads, where the browser has none of its own.
WORKSPACE = {"state": {"featureTours": {"shown": []},
                       "layoutBrowser": {"expandedSections": {"personal": True, "shared": True}},
                       "playbackControls": {"repeat": False, "syncInstances": False},
                       "sidebars": {"left": {"open": False}, "right": {"open": False}}},
             "version": 1}


def lichtblick_web() -> Path:
    """The built web app; not built is a failure naming the command."""
    result = subprocess.run([str(SCRIPTS / "lichtblick.sh"), "--where"], capture_output=True,
                            text=True, check=False)
    if result.returncode != 0:
        pytest.fail("Lichtblick's web app is not built: run scripts/lichtblick.sh "
                    f"({result.stderr.strip()})")
    return Path(result.stdout.strip())


def app_url(base: str, view: str) -> str:
    """Lichtblick's address with the connection to the view in its query."""
    return f"{base}/?" + urlencode({"ds": "foxglove-websocket", "ds.url": view})


def open_app(page: Page, base: str, view: str) -> None:
    """Lichtblick at `base`, connecting to the live view at `view`, sidebars closed."""
    seed = json.dumps(json.dumps(WORKSPACE))
    page.call("Page.addScriptToEvaluateOnNewDocument", source=(
        f"if (!localStorage.getItem('fox.workspace')) "
        f"localStorage.setItem('fox.workspace', {seed});"))
    page.call("Page.navigate", url=app_url(base, view))


def panel_box(page: Page, panel: str) -> tuple[int, int, int, int] | None:
    """(x, y, width, height) of the canvas of a panel of the layout, in screen pixels."""
    box = page.evaluate(f"""(() => {{
        const c = document.querySelector('[data-testid~="{panel}"] canvas');
        if (!c) return null;
        const r = c.getBoundingClientRect();
        return [r.x, r.y, r.width, r.height].map(Math.round);
    }})()""")
    return None if box is None or box[2] * box[3] == 0 else tuple(box)


def shown_count(page: Page) -> tuple[str, str]:
    """What the count's panel shows: (its caption, the value); empty before a message."""
    texts = page.evaluate(f"""(() => {{
        const panel = document.querySelector(
            '[data-testid~="{COUNT_PANEL}"] [data-testid=panel-scroll-container]');
        const text = (css) => panel?.querySelector(css)?.textContent.trim() ?? "";
        return [text('.MuiTypography-caption'), text('.MuiTypography-body1')];
    }})()""")
    return str(texts[0]), str(texts[1])


def outline_pixels(pixels: np.ndarray) -> int:
    """Pixels of the person outline's colour."""
    return int(np.all(np.abs(pixels.astype(int) - PERSON_BGR) <= TOLERANCE, axis=2).sum())


def frame_shape(image: np.ndarray) -> tuple[int, int] | None:
    """(height, width) of what the image panel draws over its own background colour (its
    top-left pixel, above or beside the frame); None for a blank panel. Only rows and
    columns mostly drawn count: a panel border crossing the canvas is not a frame."""
    drawn = np.any(np.abs(image.astype(int) - image[0, 0].astype(int)) > 12, axis=2)
    rows = np.flatnonzero(drawn.mean(axis=1) > 0.5)
    cols = np.flatnonzero(drawn.mean(axis=0) > 0.5)
    if rows.size == 0 or cols.size == 0:
        return None
    frame = image[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    if frame.std() < 25:  # a flat fill or a message, not a photograph
        return None
    return int(rows[-1] - rows[0] + 1), int(cols[-1] - cols[0] + 1)


@dataclass
class Shown:
    """The screenshot (BGR), the image panel's part of it, the count's panel (its caption,
    naming the schema and the time, and the value), the console."""

    screen: np.ndarray
    image: np.ndarray
    count_caption: str
    count: str
    console: list[str]


def look(page: Page) -> Shown | None:
    """What the browser shows now; None while the image panel has no canvas."""
    box = panel_box(page, IMAGE_PANEL)
    if box is None:
        return None
    screen = cv2.imdecode(np.frombuffer(page.screenshot(), np.uint8), cv2.IMREAD_COLOR)
    assert screen is not None, "the screenshot is not a PNG"
    x, y, w, h = box
    return Shown(screen, screen[y:y + h, x:x + w], *shown_count(page), list(page.console))


def serving_module() -> Any:
    return load_script("lichtblick_serve")
