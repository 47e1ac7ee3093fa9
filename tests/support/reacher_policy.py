"""reacher-camera's policy that sees (oricf.bench.train_camera_policy, its default
settings: half a minute's training on two cores), trained once per test session into the
session's model root and found there by every test that asks."""

from __future__ import annotations

from pathlib import Path

from oricf.bench.train_camera_policy import trained_policy
from tests.support.chunk_policy import session_root

# The trainer's defaults: trained with seeds 0 to 4 they reached the target in 36 to 40
# of 40 unseen episodes each.
SETTINGS: dict[str, int] = {}


def reacher_policy() -> Path:
    """The declaration of the session's camera policy (trained on first use)."""
    return trained_policy(root=session_root(), **SETTINGS)
