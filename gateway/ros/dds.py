"""The Fast DDS profile the gateway (and any process publishing raw camera frames) needs.

configs/pipelines/dds/fastdds.xml (shipped inside the package by `pip install`, see
oricf.config.config_dir) does two things, both explained in the file:

- it gives each participant a 16 MB shared-memory segment. Fast DDS's default segment is
  512 KB: a raw 640x480 frame (900 KB) does not fit, goes out as fragmented UDP instead, and
  most frames are lost on best-effort topics. The publisher's setting is the one that
  matters, so camera nodes need it as well:

      export FASTRTPS_DEFAULT_PROFILES_FILE=$(python -m oricf.gateway.ros.dds)

- it keeps reliable writers (the count, the answers) from arming a timer for every sample,
  which woke Fast DDS's event thread twice per published message;

- it keeps DDS on this machine: every socket on 127.0.0.1, discovery by unicast there. Under
  ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (or the older ROS_LOCALHOST_ONLY=1) rmw_fastrtps
  would add a UDP transport of its own on every interface, so with this profile the range is
  left to the profile (SYSTEM_DEFAULT). docs/security.md says how to open DDS to a network.

Fast DDS 3 (ROS 2 Kilted and later) reads the same profiles in its own spelling
(configs/pipelines/dds/fastdds3/; fast_dds_3() tells which Fast DDS is installed). Its
variable is FASTDDS_DEFAULT_PROFILES_FILE, but Kilted's rmw_fastrtps still reads
FASTRTPS_DEFAULT_PROFILES_FILE (with a warning that it is deprecated), and with both set
both files are loaded, which Fast DDS refuses as duplicate profiles: ORICF sets the one
variable every distribution reads, FASTRTPS_DEFAULT_PROFILES_FILE, and leaves a profile
named by either to the user.

fastdds-tcp.xml beside it adds a TCP transport, for camera drivers on Fast DDS's LARGE_DATA
transports; it is chosen by hand (`python -m oricf.gateway.ros.dds --tcp` prints its path)
and treated as shipped. It is not the default: Fast DDS 2.14's TCP transport now and then
hangs or aborts the process while a participant is deleted (docs/ros.md, Camera drivers).

No ROS import here: call use_dds_profile() before rclpy.init().
"""

from __future__ import annotations

import argparse
import importlib.metadata
import logging
import os
import sys
from pathlib import Path

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.logs import quoted

log = logging.getLogger(__name__)


# rcl's values that leave Fast DDS's transports to the profile; any other value (LOCALHOST, or
# one rcl does not know, which it reads as LOCALHOST) makes rmw_fastrtps add its own.
RANGES_LEFT_TO_THE_PROFILE = ("", "OFF", "SUBNET", "SYSTEM_DEFAULT")


PROFILE, TCP_PROFILE = "fastdds.xml", "fastdds-tcp.xml"
# The distributions on Fast DDS 2, whose profiles differ from Fast DDS 3's in spelling.
FAST_DDS_2_DISTROS = ("humble", "iron", "jazzy")
PROFILE_VARIABLE, FAST_DDS_3_VARIABLE = ("FASTRTPS_DEFAULT_PROFILES_FILE",
                                         "FASTDDS_DEFAULT_PROFILES_FILE")


def fast_dds_3() -> bool:
    """Whether the ROS 2 in use runs Fast DDS 3: a sourced install says by its ROS_DISTRO,
    the PyPI wheels by their name (Fast DDS 3 is `ros-fastdds`, Fast DDS 2 `ros-fastrtps`)."""
    distro = os.environ.get("ROS_DISTRO")
    if distro:
        return distro not in FAST_DDS_2_DISTROS
    try:
        importlib.metadata.version("ros-fastdds")
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


def shipped_profile_path(tcp: bool = False) -> Path:
    folder = config_dir() / "pipelines" / "dds"
    return (folder / "fastdds3" if fast_dds_3() else folder) / (TCP_PROFILE if tcp else PROFILE)


def dds_profile(tcp: bool = False) -> Path:
    """A shipped profile (in the checkout's or the installed package's configs); a missing
    one is a ConfigError, never skipped: without it raw frames are silently lost."""
    path = shipped_profile_path(tcp)
    if not path.is_file():
        raise ConfigError(f"{path}: the Fast DDS profile is missing (reinstall ORICF, or set "
                          f"{PROFILE_VARIABLE} to a profile of your own)")
    return path


def use_dds_profile() -> None:
    """Points Fast DDS at the shipped profile unless the user chose a profile or another RMW;
    while the shipped profile is the one in use, the discovery range is left to it."""
    if os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return
    chosen = os.environ.get(PROFILE_VARIABLE) or os.environ.get(FAST_DDS_3_VARIABLE)
    if not chosen:
        profile = dds_profile()
        os.environ[PROFILE_VARIABLE] = str(profile)
        log.info("Fast DDS profile: %s (DDS on 127.0.0.1 only)", profile)
    elif Path(chosen).resolve() not in {shipped_profile_path(tcp).resolve()
                                         for tcp in (False, True)}:
        return
    leave_discovery_range_to_the_profile()


def leave_discovery_range_to_the_profile() -> None:
    """The shipped profile keeps discovery on 127.0.0.1; ROS's LOCALHOST range would add
    sockets on every interface to it (see the top)."""
    requested = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "")
    localhost_only = os.environ.get("ROS_LOCALHOST_ONLY", "").startswith("1")
    if requested in RANGES_LEFT_TO_THE_PROFILE and not localhost_only:
        return
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SYSTEM_DEFAULT"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    log.info("ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT instead of %s: the Fast DDS profile "
             "keeps discovery on 127.0.0.1, where rmw_fastrtps's LOCALHOST range would add a "
             "UDP transport on every interface",
             "ROS_LOCALHOST_ONLY=1" if localhost_only
             else f"ROS_AUTOMATIC_DISCOVERY_RANGE={quoted(requested, 40)}")


def main(argv: list[str] | None = None) -> int:
    """Prints the profile's path, for camera nodes started by hand (see the top); with
    --tcp, the TCP profile's."""
    parser = argparse.ArgumentParser(prog="python -m oricf.gateway.ros.dds",
                                     description=main.__doc__)
    parser.add_argument("--tcp", action="store_true",
                        help="the profile with a TCP transport, for LARGE_DATA cameras")
    args = parser.parse_args(argv)
    try:
        print(dds_profile(args.tcp))
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
