"""The Fast DDS profile the gateway (and any process publishing raw camera frames) needs.

configs/pipelines/dds/fastdds.xml does two things, both explained in the file:

- it gives each participant a 16 MB shared-memory segment. Fast DDS's default segment is
  512 KB: a raw 640x480 frame (900 KB) does not fit, goes out as fragmented UDP instead, and
  most frames are lost on best-effort topics. The publisher's setting is the one that
  matters, so camera nodes need it as well:

      export FASTRTPS_DEFAULT_PROFILES_FILE=.../configs/pipelines/dds/fastdds.xml

- it keeps reliable writers (the count, the answers) from arming a timer for every sample,
  which woke Fast DDS's event thread twice per published message.

No ROS import here: call use_dds_profile() before rclpy.init().
"""

from __future__ import annotations

import logging
import os

from oricf.config import config_dir

log = logging.getLogger(__name__)

DDS_PROFILE = config_dir() / "pipelines" / "dds" / "fastdds.xml"


def use_dds_profile() -> None:
    """Points Fast DDS at the shipped profile unless the user chose a profile or another RMW."""
    if os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or \
            os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return
    if DDS_PROFILE.is_file():
        os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(DDS_PROFILE)
        log.info("Fast DDS profile: %s", DDS_PROFILE)
