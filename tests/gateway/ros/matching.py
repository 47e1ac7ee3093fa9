"""For the publisher processes the tests start: wait until the subscriber under test has
matched (plain rclpy, nothing of ORICF, so a camera process stays one we did not write)."""

from __future__ import annotations

import time
from typing import Any

MATCH_TIMEOUT_S = 30.0


def wait_for_subscriber(publisher: Any, timeout_s: float = MATCH_TIMEOUT_S) -> bool:
    deadline = time.monotonic() + timeout_s
    while publisher.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True
