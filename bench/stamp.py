"""Frames that carry the time they were sent: the wall-clock time in milliseconds as a row of
black and white squares across the top of the frame, big enough to survive H.264.

    python -m oricf.bench.stamp VIDEO FPS     raw BGR frames of VIDEO, looped, stamped and
                                              paced at FPS, on standard output (for FFmpeg)
"""

from __future__ import annotations

import sys
import time

import numpy as np

BITS = 42       # milliseconds since the epoch modulo 2**42: 139 years
SQUARE = 16     # pixels per bit; 42 squares span 672 pixels


def stamp(frame: np.ndarray, at_ms: int) -> np.ndarray:
    marked = frame.copy()
    for bit in range(BITS):
        value = 255 if (at_ms >> bit) & 1 else 0
        marked[:SQUARE, bit * SQUARE:(bit + 1) * SQUARE] = value
    return marked


def read_stamp(frame: np.ndarray) -> int:
    """The milliseconds a stamped frame carries (read at the centre of each square)."""
    row = frame[SQUARE // 2, SQUARE // 2::SQUARE][:BITS]
    bits = row.mean(axis=-1) > 127 if row.ndim == 2 else row > 127
    return sum(1 << bit for bit, on in enumerate(bits) if on)


def age_ms(frame: np.ndarray, now_s: float) -> float:
    """How long ago the frame was sent (same clock: this machine)."""
    now_ms = int(now_s * 1000)
    return float((now_ms - read_stamp(frame)) % (1 << BITS))


def main(argv: list[str] | None = None) -> int:
    import cv2

    video, fps = (argv or sys.argv[1:])[:2]
    period = 1 / float(fps)
    out = sys.stdout.buffer
    capture = cv2.VideoCapture(video)
    next_at = time.monotonic()
    while True:
        ok, frame = capture.read()
        if not ok:
            capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            continue
        time.sleep(max(0.0, next_at - time.monotonic()))
        next_at += period
        try:
            out.write(stamp(frame, int(time.time() * 1000)).tobytes())
            out.flush()
        except BrokenPipeError:
            return 0


if __name__ == "__main__":
    sys.exit(main())
