"""A network camera on this machine for `oricf bench offload`: vtest.avi frames at 640x480
served as MJPEG over HTTP (multipart/x-mixed-replace, as many IP cameras and USB camera
bridges do), at a fixed rate to every client, looped.

The frames are encoded to JPEG once, at start, as a camera's own encoder would; what the
camera costs the machine it runs on afterwards is sending them. Prints "ready" once it
accepts clients; stops on SIGTERM.

    python -m oricf.bench.mjpeg_camera PORT [--fps 10] [--frames 100]
"""

from __future__ import annotations

import argparse
import http.server
import signal
import sys
import time

BOUNDARY = b"frame"


def encode_frames(count: int, quality: int = 80) -> list[bytes]:
    import cv2

    from oricf.bench.common import load_frames

    return [cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, quality])[1].tobytes()
            for frame in load_frames(count)]


def handler(frames: list[bytes], fps: float) -> type[http.server.BaseHTTPRequestHandler]:
    class Camera(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type",
                             f"multipart/x-mixed-replace; boundary={BOUNDARY.decode()}")
            self.end_headers()
            due, i = time.monotonic(), 0
            try:
                while True:
                    jpeg = frames[i % len(frames)]
                    self.wfile.write(b"--%s\r\nContent-Type: image/jpeg\r\nContent-Length: "
                                     b"%d\r\n\r\n%s\r\n" % (BOUNDARY, len(jpeg), jpeg))
                    i, due = i + 1, due + 1 / fps
                    time.sleep(max(0.0, due - time.monotonic()))
            except (BrokenPipeError, ConnectionResetError):
                return  # the client went away

        def log_message(self, format: str, *args: object) -> None:
            pass

    return Camera


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oricf.bench.mjpeg_camera",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("port", type=int)
    parser.add_argument("--fps", type=float, default=10.0)
    parser.add_argument("--frames", type=int, default=100, help="frames of vtest.avi, looped")
    args = parser.parse_args(argv)
    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", args.port), handler(encode_frames(args.frames), args.fps))
    server.daemon_threads = True
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    print("ready", flush=True)
    try:
        server.serve_forever()
    finally:
        server.server_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
