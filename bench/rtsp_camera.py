"""An IP camera on this machine, for tests and `oricf bench rtsp`: FFmpeg encodes frames to
H.264 (as a camera does) and sends them as RTP to a GStreamer RTSP server
(bench/rtsp_server.py), which serves rtsp://127.0.0.1:PORT/cam. The frames come from a
video file played in real time and looped, or stamped with the time each was sent
(bench/stamp.py), so a benchmark can tell how old a frame is when its count comes out.

The server can be stopped and started again while FFmpeg keeps sending, as when a camera's
RTSP service restarts. Needs ffmpeg and the server's packages (scripts/setup.sh --dev); a
camera without them raises MissingPackage, which names them.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import IO

from oricf.bench.entry import MissingPackage, need_tools
from oricf.launch.health import free_port

SERVER = Path(__file__).with_name("rtsp_server.py")
SYSTEM_PYTHON = "/usr/bin/python3"  # the one with GStreamer's gi bindings
ENCODE = ["-an", "-c:v", "libx264", "-preset", "ultrafast", "-tune", "zerolatency",
          "-g", "10", "-pix_fmt", "yuv420p", "-f", "rtp"]
# The server's GStreamer bindings, asked of the system Python when the server did not start.
GI_PROBE = ("import gi; gi.require_version('Gst', '1.0'); "
            "gi.require_version('GstRtspServer', '1.0')")
PACKAGES = ("Debian: ffmpeg python3-gi gir1.2-gst-rtsp-server-1.0 gstreamer1.0-plugins-good "
            "gstreamer1.0-plugins-bad; scripts/setup.sh --dev installs them")
PURPOSE = "an RTSP camera (oricf.bench.rtsp_camera)"


class RtspCamera:
    def __init__(self, port: int | None = None) -> None:
        need_tools(("ffmpeg", SYSTEM_PYTHON), PACKAGES, PURPOSE)
        self.port = port or free_port()
        self.rtp_port = free_port()
        self.url = f"rtsp://127.0.0.1:{self.port}/cam"
        self.server: subprocess.Popen[str] | None = None
        self.feed: subprocess.Popen[bytes] | None = None
        self.stamper: subprocess.Popen[bytes] | None = None

    def start_server(self) -> None:
        self.server = subprocess.Popen([SYSTEM_PYTHON, str(SERVER), str(self.port),
                                        str(self.rtp_port)], stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE, text=True)
        assert self.server.stdout is not None
        if self.server.stdout.readline().strip() != "ready":
            _, err = self.server.communicate(timeout=10)
            self.server = None
            probe = subprocess.run([SYSTEM_PYTHON, "-c", GI_PROBE], capture_output=True,
                                   timeout=30, check=False)
            if probe.returncode != 0:
                raise MissingPackage(f"{PURPOSE} needs GStreamer's RTSP server for "
                                     f"{SYSTEM_PYTHON} ({PACKAGES})")
            raise RuntimeError(f"the RTSP server did not start: {err[-1000:]}")

    def stop_server(self) -> None:
        """As when the camera's server dies: killed, no goodbye to its clients."""
        if self.server is not None:
            self.server.kill()
            self.server.wait(10)
            self.server = None

    def play_file(self, video: Path) -> None:
        """Sends the file in real time, looped, for as long as the camera runs."""
        self._start_feed(["-re", "-stream_loop", "-1", "-i", str(video)])

    def play_stamped(self, video: Path, fps: float) -> None:
        """Sends the file's frames at `fps`, each stamped with the time it was sent
        (stamp.py), from a process of its own so the sender's work is not the reader's."""
        self.stamper = subprocess.Popen(
            [sys.executable, "-m", "oricf.bench.stamp", str(video), str(fps)],
            stdout=subprocess.PIPE)
        width, height = frame_size(video)
        self._start_feed(["-f", "rawvideo", "-pix_fmt", "bgr24", "-s", f"{width}x{height}",
                          "-r", str(fps), "-i", "-"], stdin=self.stamper.stdout)

    def _start_feed(self, source: list[str], stdin: IO[bytes] | None = None) -> None:
        quiet = ["-hide_banner", "-loglevel", "error", *(["-nostdin"] if stdin is None else [])]
        self.feed = subprocess.Popen(
            ["ffmpeg", *quiet, *source, *ENCODE, f"rtp://127.0.0.1:{self.rtp_port}"],
            stdin=stdin, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def close(self) -> None:
        self.stop_server()
        for process in (self.stamper, self.feed):
            if process is not None:
                process.kill()
                process.wait(10)

    def __enter__(self) -> RtspCamera:
        self.start_server()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def frame_size(video: Path) -> tuple[int, int]:
    import cv2

    capture = cv2.VideoCapture(str(video))
    size = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
    capture.release()
    return size
