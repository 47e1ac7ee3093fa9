"""The Fast DDS profile the gateway (and any process publishing raw camera frames) needs.

configs/pipelines/dds/fastdds.xml (shipped inside the package by `pip install`, see
oricf.config.config_dir) does two things, both explained in the file:

- it gives each participant a 16 MB shared-memory segment. Fast DDS's default segment is
  512 KB: a raw 640x480 frame (900 KB) does not fit, goes out as fragmented UDP instead, and
  most frames are lost on best-effort topics. The publisher's setting is the one that
  matters, so camera nodes need it as well:

      export FASTRTPS_DEFAULT_PROFILES_FILE=$(python -m oricf.gateway.ros.dds)

- it keeps reliable writers (the count, the answers) from arming a timer for every sample,
  which woke Fast DDS's event thread twice per published message.

No ROS import here: call use_dds_profile() before rclpy.init().
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

from oricf.config import config_dir
from oricf.errors import ConfigError

log = logging.getLogger(__name__)


def dds_profile() -> Path:
    """The shipped profile (in the checkout's or the installed package's configs); a missing
    one is a ConfigError, never skipped: without it raw frames are silently lost."""
    path = config_dir() / "pipelines" / "dds" / "fastdds.xml"
    if not path.is_file():
        raise ConfigError(f"{path}: the Fast DDS profile is missing (reinstall ORICF, or set "
                          f"FASTRTPS_DEFAULT_PROFILES_FILE to a profile of your own)")
    return path


def use_dds_profile() -> None:
    """Points Fast DDS at the shipped profile unless the user chose a profile or another RMW."""
    if os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or \
            os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return
    profile = dds_profile()
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
    log.info("Fast DDS profile: %s", profile)


def main() -> int:
    """Prints the profile's path, for camera nodes started by hand (see the top)."""
    try:
        print(dds_profile())
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
