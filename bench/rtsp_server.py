"""An RTSP server for tests and benchmarks: GStreamer's gst-rtsp-server, relaying an H.264
RTP stream that arrives on a UDP port (FFmpeg sends it: see bench/rtsp_camera.py) to every
RTSP client of rtsp://127.0.0.1:PORT/MOUNT.

Runs under the system Python, which has GStreamer's introspection bindings (Debian
python3-gi, gir1.2-gst-rtsp-server-1.0, gstreamer1.0-plugins-good/-bad); it imports nothing
of ORICF. Prints "ready" once it accepts clients.

    /usr/bin/python3 bench/rtsp_server.py PORT RTP_PORT [MOUNT]
"""

import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtspServer  # noqa: E402

CAPS = "application/x-rtp,media=video,clock-rate=90000,encoding-name=H264,payload=96"


def main() -> None:
    port, rtp_port = sys.argv[1], int(sys.argv[2])
    mount = sys.argv[3] if len(sys.argv) > 3 else "/cam"
    Gst.init(None)
    server = GstRtspServer.RTSPServer()
    server.set_address("127.0.0.1")
    server.set_service(port)
    factory = GstRtspServer.RTSPMediaFactory()
    # Re-payloaded, not re-encoded: the server adds no decoding work of its own.
    factory.set_launch(f'( udpsrc port={rtp_port} caps="{CAPS}" ! rtph264depay ! h264parse '
                       f'! rtph264pay name=pay0 pt=96 config-interval=1 )')
    factory.set_shared(True)  # one feed, however many clients
    server.get_mount_points().add_factory(mount, factory)
    if server.attach(None) == 0:
        sys.exit(f"cannot listen on 127.0.0.1:{port}")
    print("ready", flush=True)
    GLib.MainLoop().run()


if __name__ == "__main__":
    main()
