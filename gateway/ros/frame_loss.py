"""Camera frames that never reached the gateway, told apart from frames it let DDS replace.

A camera receiver keeps one frame (history depth 1): while its route works on a frame, a
newer one replaces the one waiting, and the publisher's sequence numbers show a gap. Those
frames are the gateway's choice. But the replaced frames all arrived while the route was
busy, at the publisher's pace: a gap longer than the busy time can hold, or any gap in
front of a frame the receiver sat idle waiting for, is frames that never arrived. They were
lost on the way, typically raw frames fragmented by a camera process whose DDS settings
cannot carry them whole, from a best-effort publisher that never resends a lost fragment.
`FrameLoss` counts them and says when they are too many to be chance, so the receiver can
warn once.

No ROS import here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# A warning needs at least this many lost frames, and this share of the frames published:
# a frame lost now and then on a busy link is not worth one.
MIN_LOST = 5
MIN_LOST_SHARE = 0.1
# A frame this large goes whole over LARGE_DATA's shared memory and TCP once max_msg_size is
# above it; sockets_size also sizes the shared-memory segment (twice its value).
LARGE_DATA = "LARGE_DATA?max_msg_size={mb}MB&sockets_size={mb}MB"


def replaceable(gap: int, waited: bool, busy_s: float, span_s: float) -> int:
    """How many of the `gap` frames missing in front of a frame may have been replaced by
    newer ones. None if the receiver was idle waiting for it: a frame that arrived while the
    route was busy would still have been there. Otherwise as many as arrive at the
    publisher's pace (`span_s`: the time between the publication of the two frames taken)
    while the route was busy (`busy_s`: since it took the previous frame), with half a frame
    of leeway for uneven arrivals; all of them if the pace is unknown."""
    if waited:
        return 0
    if gap <= 0 or span_s <= 0:
        return max(gap, 0)
    interval = span_s / (gap + 1)
    return min(gap, math.floor(busy_s / interval + 0.5))


@dataclass
class FrameLoss:
    published: int = 0  # frames the publisher sent since counting began (sequence numbers)
    lost: int = 0  # of those, frames that never arrived
    warned: bool = False  # set by the caller once it has warned

    def add(self, gap: int, replaceable: int) -> int:
        """One frame arrived, `gap` frames after the previous one, of which `replaceable` may
        have been replaced (see replaceable()); the others never arrived. Returns how many
        were replaced."""
        lost = gap - min(gap, replaceable)
        self.published += 1 + gap
        self.lost += lost
        return gap - lost

    @property
    def warning_due(self) -> bool:
        """The losses call for a warning that was not given yet."""
        return (not self.warned and self.lost >= MIN_LOST
                and self.lost >= MIN_LOST_SHARE * self.published)

    def restart(self) -> None:
        """Counts again from the next frame (a new subscription); a warning given stays given."""
        self.published = self.lost = 0


def camera_side_fix(frame_bytes: int) -> str:
    """What to set where the camera driver is started, for frames of this size."""
    megabytes = max(1, math.ceil((frame_bytes + 65536) / 1_000_000))
    return ("Where the camera driver is started, set FASTRTPS_DEFAULT_PROFILES_FILE to ORICF's "
            "Fast DDS profile (python -m oricf.gateway.ros.dds prints its path), or "
            f"FASTDDS_BUILTIN_TRANSPORTS='{LARGE_DATA.format(mb=megabytes)}' (not with "
            "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, where ROS replaces Fast DDS's builtin "
            "transports; the gateway then needs the TCP profile, python -m "
            "oricf.gateway.ros.dds --tcp); or publish reliable, or publish "
            "sensor_msgs/CompressedImage. See docs/ros.md, Camera drivers")
