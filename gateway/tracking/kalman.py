"""A constant-velocity Kalman filter for one box, in the state ByteTrack and DeepSORT use:
centre x, centre y, aspect ratio (w/h), height, and their rates of change.

Time is in seconds, so velocities are pixels per second whatever the frame rate; noise is
relative to the box's height, so near and far objects are followed alike.
"""

from __future__ import annotations

import numpy as np

from oricf.imaging import Box

# Standard deviations relative to the box height: of a measured position, and of how much
# position and velocity may drift in one second (ByteTrack's per-frame 1/20 and 1/160,
# taken over the 10 frames a second a robot's camera route typically sees).
MEASURE_STD = 1 / 20
POSITION_DRIFT = 1 / 20 * 10 ** 0.5
VELOCITY_DRIFT = 1 / 160 * 10 ** 1.5
ASPECT_STD = 1e-2
ASPECT_DRIFT = 1e-5


def box_to_measure(box: Box) -> np.ndarray:
    w, h = box.x_max - box.x_min, box.y_max - box.y_min
    return np.array([(box.x_min + box.x_max) / 2, (box.y_min + box.y_max) / 2,
                     w / max(h, 1e-6), h])


def measure_to_box(m: np.ndarray) -> Box:
    cx, cy, a, h = (float(v) for v in m[:4])
    w = a * h
    return Box(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)


class BoxFilter:
    """One track's motion: `predict(dt)` moves it on, `update(box)` corrects it."""

    def __init__(self, box: Box) -> None:
        m = box_to_measure(box)
        self.mean = np.concatenate([m, np.zeros(4)])
        h = m[3]
        std = [2 * MEASURE_STD * h, 2 * MEASURE_STD * h, ASPECT_STD, 2 * MEASURE_STD * h,
               10 * VELOCITY_DRIFT * h, 10 * VELOCITY_DRIFT * h, ASPECT_DRIFT,
               10 * VELOCITY_DRIFT * h]
        self.cov = np.diag(np.square(std))

    @property
    def box(self) -> Box:
        return measure_to_box(self.mean)

    @property
    def velocity(self) -> tuple[float, float]:
        """Centre velocity in pixels per second."""
        return float(self.mean[4]), float(self.mean[5])

    def predict(self, dt: float) -> None:
        if dt <= 0:
            return
        h = self.mean[3]
        motion = np.eye(8)
        motion[:4, 4:] = dt * np.eye(4)
        drift = [POSITION_DRIFT * h, POSITION_DRIFT * h, ASPECT_DRIFT, POSITION_DRIFT * h,
                 VELOCITY_DRIFT * h, VELOCITY_DRIFT * h, ASPECT_DRIFT, VELOCITY_DRIFT * h]
        self.mean = motion @ self.mean
        self.cov = motion @ self.cov @ motion.T + np.diag(np.square(drift)) * dt

    def update(self, box: Box) -> None:
        measured = box_to_measure(box)
        h = self.mean[3]
        noise = np.diag(np.square([MEASURE_STD * h, MEASURE_STD * h, ASPECT_STD,
                                   MEASURE_STD * h]))
        projected = self.cov[:4, :4] + noise
        gain = np.linalg.solve(projected, self.cov[:4, :]).T  # cov H^T S^-1, S symmetric
        self.mean = self.mean + gain @ (measured - self.mean[:4])
        self.cov = self.cov - gain @ self.cov[:4, :]
