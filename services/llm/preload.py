"""llama.cpp's libraries load first in a process that serves the language model.

With llama-cpp-python built for CUDA, a process that had loaded grpc's, numpy's or OpenCV's
native libraries before llama.cpp's crashed (SIGSEGV) as the model loaded, at any
`gpu_layers`, while one that loaded llama.cpp's first served (an H200, CUDA 13, numpy 2.5.2,
grpcio 1.85, 2026-11-28; docs/platforms.md). `oricf serve llm` therefore imports llama_cpp
before anything else that is native: after reading its configuration's YAML, before the
service's own modules. OpenMP reads OMP_WAIT_POLICY when llama.cpp's library loads, so the
configuration's `model.omp_wait_policy` is put in the environment first (one already set
there wins, as it always has).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from typing import Any

log = logging.getLogger(__name__)

POLICIES = ("PASSIVE", "ACTIVE")


def load_llama_first(settings: Mapping[str, Any]) -> None:
    """Imports llama_cpp (its libraries) now, given the service's YAML as read; nothing when
    it is not installed or does not load: the service's own load says so then."""
    model = settings.get("model")
    policy = model.get("omp_wait_policy", "PASSIVE") if isinstance(model, Mapping) else "PASSIVE"
    if policy in POLICIES:  # anything else is refused with the configuration, later
        os.environ.setdefault("OMP_WAIT_POLICY", policy)
    try:
        import llama_cpp  # noqa: F401
    except (ImportError, OSError) as exc:
        log.debug("llama_cpp not loaded ahead: %s", exc)
