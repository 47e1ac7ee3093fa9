"""Logging set-up, called once by each entry point (never at import)."""

from __future__ import annotations

import logging
import os

FORMAT = "%(asctime)s %(levelname)-5s %(name)s: %(message)s"


def setup_logging(level: str | None = None) -> None:
    level_name = (level or os.environ.get("ORICF_LOG_LEVEL") or "INFO").upper()
    logging.basicConfig(level=level_name, format=FORMAT, datefmt="%H:%M:%S", force=True)
