"""What a viewer that stops reading costs the gateway's memory, measured: `oricf gateway` on
vtest.avi in a process of its own, its view sending every frame the route finishes as a
large JPEG; a viewer subscribes to the frames and never reads again, and the gateway's
resident memory (VmRSS) is sampled while frames keep coming. It must stay within what the
configuration lets a stalled viewer hold, while a second viewer that reads gets frames and
the route goes on."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
import yaml

from oricf.config import config_dir
from oricf.gateway.live_view.front import RELAY_QUEUE, WRITE_LIMIT_BYTES
from tests.gateway.live_view.processes import gateway_with_view
from tests.gateway.live_view.viewers import stalled_viewer, watch_images
from tests.support.data import video_path
from tests.support.services import RunningService

PIPELINE = config_dir() / "pipelines" / "people_video.yaml"
FPS = 25          # frames of the video handed to the route per second, at most
MAX_FPS = 30.0    # the view's cap, above FPS: every frame the route finishes is sent
QUALITY = 95      # large frames (about 150 kB at 768x576), so a leak would show at once
BACKLOG = 16      # messages the SDK queues for one viewer
WARM_UP_S = 8.0   # the stalled viewer's kernel buffers fill, the gateway reaches its size
MEASURE_S = 20.0
# Memory the gateway's own work moves around in the window whatever the viewers do: the
# Python heap and the allocator's arenas (decoded frames, replies, JPEG buffers) settle
# in steps of a few MiB.
MARGIN_BYTES = 12 << 20
MiB = 1 << 20


def overlay(folder: Path, detector: str) -> Path:
    path = folder / "here.yaml"
    path.write_text(yaml.safe_dump({
        "endpoints": {"detector": {"address": detector, "deadline_ms": 10_000}},
        "routes": {"people": {"input": {"url": str(video_path()), "fps": FPS, "loop": True}}},
        "foxglove": {"max_fps": MAX_FPS, "jpeg_quality": QUALITY, "backlog": BACKLOG}}))
    return path


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no VmRSS for process {pid}")


@pytest.mark.long
def test_a_stalled_viewer_holds_no_more_than_the_configuration_allows(
        detector: RunningService, tmp_path: Path) -> None:
    with gateway_with_view(tmp_path, "--config", str(PIPELINE), "--overlay",
                           str(overlay(tmp_path, detector.address))) as gateway, \
            stalled_viewer(gateway.url, "/people/image"):
        time.sleep(WARM_UP_S)
        pid, counted, start = gateway.process.pid, len(gateway.out), time.monotonic()
        samples = [rss_bytes(pid)]
        sizes: list[int] = []
        reader = threading.Thread(target=lambda: sizes.extend(
            watch_images(gateway.url, MEASURE_S / 2)))
        reader.start()  # a second viewer, reading, in the middle of the window
        while time.monotonic() - start < MEASURE_S:
            time.sleep(0.5)
            samples.append(rss_bytes(pid))
        reader.join()
        frames = len(gateway.out) - counted
        assert gateway.process.poll() is None, "".join(gateway.log)[-3000:]
    assert frames >= 5 * MEASURE_S, frames  # the route went on
    assert len(sizes) >= 10, sizes          # the reading viewer got frames
    # All a stalled viewer may hold: the SDK's backlog for it, the messages its relay read
    # ahead and the one it is writing (each at most the largest frame a viewer got), and
    # the bytes the relay wrote towards it before waiting; the rest is kernel buffers.
    bound = (BACKLOG + RELAY_QUEUE + 1) * max(sizes) + WRITE_LIMIT_BYTES + MARGIN_BYTES
    growth = max(samples) - samples[0]
    print(f"RSS {samples[0] / MiB:.1f} MiB at the start, grew {growth / MiB:.1f} MiB at most "
          f"over {MEASURE_S:.0f} s ({frames} frames, largest {max(sizes) / 1e3:.0f} kB); "
          f"bound {bound / MiB:.1f} MiB")
    # Held without a bound, the frames offered to the stalled viewer in the window would
    # pass the bound twice over: a leak cannot hide under it.
    assert min(frames, MAX_FPS * MEASURE_S) * min(sizes) > 2 * bound
    assert growth < bound, [round(s / MiB, 1) for s in samples]
