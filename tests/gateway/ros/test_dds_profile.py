"""The shipped Fast DDS profile: Fast DDS accepts it, the gateway picks it up, and its
writer setting does what configs/pipelines/dds/fastdds.xml says it does."""

from __future__ import annotations

import importlib.metadata
import json
import os
import queue
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32

from oricf.errors import ConfigError
from oricf.gateway.ros.dds import dds_profile, fast_dds_3, use_dds_profile
from tests.gateway.ros.gateway_node import spinning

PUBLISHED = 40
NAMESPACE = "{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}"


def test_the_gateway_uses_the_shipped_profile_unless_told_otherwise(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("FASTRTPS_DEFAULT_PROFILES_FILE", raising=False)
    monkeypatch.delenv("FASTDDS_DEFAULT_PROFILES_FILE", raising=False)
    monkeypatch.delenv("RMW_IMPLEMENTATION", raising=False)
    use_dds_profile()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(dds_profile())

    monkeypatch.setenv("FASTRTPS_DEFAULT_PROFILES_FILE", "/etc/robot/fastdds.xml")
    use_dds_profile()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == "/etc/robot/fastdds.xml"

    monkeypatch.delenv("FASTRTPS_DEFAULT_PROFILES_FILE")
    monkeypatch.setenv("FASTDDS_DEFAULT_PROFILES_FILE", "/etc/robot/fastdds.xml")
    use_dds_profile()  # Fast DDS 3's own variable names the user's profile as well
    assert "FASTRTPS_DEFAULT_PROFILES_FILE" not in os.environ
    monkeypatch.delenv("FASTDDS_DEFAULT_PROFILES_FILE")

    monkeypatch.setenv("RMW_IMPLEMENTATION", "rmw_cyclonedds_cpp")
    use_dds_profile()
    assert "FASTRTPS_DEFAULT_PROFILES_FILE" not in os.environ


@pytest.mark.parametrize(("profile", "requested", "localhost_only", "left"), [
    (None, "LOCALHOST", None, "SYSTEM_DEFAULT"),
    (None, "localhost", None, "SYSTEM_DEFAULT"),  # rcl reads a value it does not know so
    (None, "SUBNET", "1", "SYSTEM_DEFAULT"),  # the deprecated setting overrides the range
    ("shipped", "LOCALHOST", None, "SYSTEM_DEFAULT"),  # the shipped file, named by hand
    ("shipped tcp", "LOCALHOST", None, "SYSTEM_DEFAULT"),  # the TCP one, named by hand
    (None, "SUBNET", None, "SUBNET"),
    (None, "OFF", "0", "OFF"),
    (None, None, None, None),
    ("/etc/robot/fastdds.xml", "LOCALHOST", "1", "LOCALHOST"),  # a profile of the user's
])
def test_the_shipped_profile_decides_the_discovery_range_instead_of_localhost(
        monkeypatch: pytest.MonkeyPatch, profile: str | None, requested: str | None,
        localhost_only: str | None, left: str | None) -> None:
    """Under ROS's LOCALHOST range rmw_fastrtps adds a UDP transport on every interface to
    the profile's loopback-only ones (tests/gateway/ros/test_dds_loopback.py sees it)."""
    monkeypatch.delenv("RMW_IMPLEMENTATION", raising=False)
    shipped = {"shipped": str(dds_profile()), "shipped tcp": str(dds_profile(tcp=True))}
    for name, value in (("FASTRTPS_DEFAULT_PROFILES_FILE", shipped.get(profile or "", profile)),
                        ("ROS_AUTOMATIC_DISCOVERY_RANGE", requested),
                        ("ROS_LOCALHOST_ONLY", localhost_only)):
        if value is None:
            monkeypatch.delenv(name, raising=False)
        else:
            monkeypatch.setenv(name, value)
    use_dds_profile()
    assert os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == left
    if left == "SYSTEM_DEFAULT":
        assert "ROS_LOCALHOST_ONLY" not in os.environ
    else:
        assert os.environ.get("ROS_LOCALHOST_ONLY") == localhost_only



def test_a_missing_profile_stops_the_gateway_instead_of_being_skipped(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("FASTRTPS_DEFAULT_PROFILES_FILE", raising=False)
    monkeypatch.delenv("RMW_IMPLEMENTATION", raising=False)
    monkeypatch.setenv("ORICF_CONFIG_DIR", str(tmp_path))
    fast_dds = "fastdds3/" if fast_dds_3() else ""  # Fast DDS 3's form (Kilted)
    with pytest.raises(ConfigError, match=f"{tmp_path}/pipelines/dds/{fast_dds}fastdds.xml: "
                                          f"the Fast DDS profile is missing"):
        use_dds_profile()
    assert "FASTRTPS_DEFAULT_PROFILES_FILE" not in os.environ


def test_the_fast_dds_generation_follows_the_ros_in_use(monkeypatch: pytest.MonkeyPatch) -> None:
    """A sourced ROS 2 by its name; the wheels by theirs (Kilted's carry ros-fastdds)."""
    monkeypatch.delenv("ROS_DISTRO", raising=False)
    wheels = {d.metadata["Name"].lower() for d in importlib.metadata.distributions()}
    assert fast_dds_3() == ("ros-fastdds" in wheels) != ("ros-fastrtps" in wheels)
    assert dds_profile().parent.name == ("fastdds3" if fast_dds_3() else "dds")
    for distro, three in (("humble", False), ("jazzy", False), ("kilted", True),
                          ("rolling", True)):
        monkeypatch.setenv("ROS_DISTRO", distro)
        assert fast_dds_3() is three


@pytest.mark.parametrize("name", ["fastdds.xml", "fastdds-tcp.xml"])
def test_the_fast_dds_3_profiles_are_the_fast_dds_2_ones(name: str) -> None:
    """configs/pipelines/dds/fastdds3/ holds the same settings in Fast DDS 3's spelling."""
    folder = dds_profile().parents[1] if dds_profile().parent.name == "fastdds3" \
        else dds_profile().parent
    two = ET.tostring(ET.parse(folder / name).getroot())
    three = ET.tostring(ET.parse(folder / "fastdds3" / name).getroot())
    assert three.replace(b"nack_supression_duration", b"nackSupressionDuration") == two


@pytest.fixture()
def counts(ros_context: Context) -> Iterator[tuple[str, queue.Queue[int]]]:
    """A reliable subscriber in this process (another participant than the publisher's)."""
    topic = "/profile_test_count"
    received: queue.Queue[int] = queue.Queue()
    node = Node("profile_test_subscriber", context=ros_context)
    node.create_subscription(Int32, topic, lambda msg: received.put(msg.data),
                             QoSProfile(depth=PUBLISHED, reliability=ReliabilityPolicy.RELIABLE))
    try:
        with spinning(ros_context, node):
            yield topic, received
    finally:
        node.destroy_node()


def publish_from_another_process(topic: str, profile: Path) -> tuple[dict[str, int], str]:
    env = {**os.environ, "FASTRTPS_DEFAULT_PROFILES_FILE": str(profile)}
    done = subprocess.run(
        [sys.executable, "-m", "tests.gateway.ros.event_thread_publisher", topic, str(PUBLISHED)],
        env=env, capture_output=True, text=True, timeout=120,
        cwd=Path(__file__).resolve().parents[3])
    assert done.returncode == 0, done.stdout + done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


def without_writer_profile(folder: Path) -> Path:
    tree = ET.parse(dds_profile())
    root = tree.getroot()
    for writer in root.findall(f"{NAMESPACE}data_writer"):
        root.remove(writer)
    path = folder / "fastdds_transport_only.xml"
    tree.write(path)
    return path


def drain(received: queue.Queue[int]) -> list[int]:
    values = []
    while True:
        try:
            values.append(received.get(timeout=2))
        except queue.Empty:
            return values


@pytest.mark.parametrize("tcp", [False, True], ids=["default profile", "tcp profile"])
def test_fast_dds_accepts_the_shipped_profiles_and_stays_reliable(
        counts: tuple[str, queue.Queue[int]], tcp: bool) -> None:
    topic, received = counts
    _, log = publish_from_another_process(topic, dds_profile(tcp))
    assert "XMLPARSER" not in log, log  # Fast DDS logs a profile it cannot parse, and goes on
    assert drain(received) == list(range(PUBLISHED))  # every sample, in order


@pytest.mark.thirdparty
def test_reliable_writers_do_not_wake_the_event_thread_for_every_sample(
        counts: tuple[str, queue.Queue[int]], tmp_path: Path) -> None:
    """What the profile's writer setting buys, counted in Fast DDS's own event thread (its
    name and how often it sleeps are Fast DDS's internals, so this is a `thirdparty` test:
    `.venv/bin/python -m pytest -m thirdparty`)."""
    topic, received = counts

    shipped, _ = publish_from_another_process(topic, dds_profile())
    assert drain(received) == list(range(PUBLISHED))

    default, _ = publish_from_another_process(topic, without_writer_profile(tmp_path))
    assert drain(received) == list(range(PUBLISHED))

    # Fast DDS's default: the event thread wakes at least once per sample (twice, mostly).
    # The shipped profile: a few times over the whole run (its 500 ms window, 0.8 s here).
    assert default["wakeups"] >= PUBLISHED, default
    assert shipped["wakeups"] <= PUBLISHED // 4, shipped


def test_the_tcp_profile_is_the_default_one_with_a_tcp_transport() -> None:
    """Two files, one set of settings: without its TCP transport, its TCP discovery address
    and its comment, the TCP profile is the default one (a setting changed in one file
    only fails here)."""
    root = ET.parse(dds_profile(tcp=True)).getroot()
    removed = 0
    for parent in root.iter():
        for child in list(parent):
            tcp_descriptor = child.findtext(f"{NAMESPACE}transport_id") == "tcp"
            tcp_locator = child.find(f"{NAMESPACE}tcpv4") is not None
            tcp_user = child.tag == f"{NAMESPACE}transport_id" and child.text == "tcp" \
                and parent.tag == f"{NAMESPACE}userTransports"
            if tcp_descriptor or tcp_locator or tcp_user:
                parent.remove(child)
                removed += 1
    assert removed == 3
    assert canonical(root) == canonical(ET.parse(dds_profile()).getroot())


def canonical(element: ET.Element) -> str:
    """The element as canonical XML, whitespace between elements left out."""
    return ET.canonicalize(ET.tostring(element, encoding="unicode"), strip_text=True)
