"""A chunk policy behaviour-cloned from a metaworld expert, small enough to train in
seconds (oricf.bench.train_chunk_policy), trained once per test session into the session's
model root and found there by every test that asks."""

from __future__ import annotations

import tempfile
from functools import cache
from pathlib import Path

from oricf.bench.train_chunk_policy import trained_policy

# Small and quick, yet far from the edge: trained with seeds 0, 1 and 2 these settings
# solved 20 of 20 unseen episodes each.
TASK = "drawer-close-v3"
SMALL = {"demos": 10, "epochs": 40}


@cache
def session_root() -> Path:
    return Path(tempfile.mkdtemp(prefix="oricf-chunk-policy-"))


def chunk_policy() -> Path:
    """The declaration of the session's chunk policy for TASK (trained on first use)."""
    return trained_policy(TASK, root=session_root(), **SMALL)
