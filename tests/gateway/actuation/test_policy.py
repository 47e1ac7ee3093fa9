"""The agent policy without an agent: its YAML refused with the key named, commands clamped
or refused by content, rate and approval, and approval by a person on a real text channel
(a TCP client answering yes or no) before a line goes out on another channel."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.actuation.actuation import Actuation
from oricf.gateway.actuation.approval import ChannelApprover
from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.actuation.policy import AgentPolicy, Refused
from oricf.gateway.actuation.senders import ChannelSender, Senders
from oricf.gateway.channels.server import ChannelConfig, Channels
from oricf.gateway.config import load_pipeline
from oricf.gateway.ros.commands import RosSender
from tests.gateway.agents.scene import ARM_TOPIC, ros_listener
from tests.support.processes import free_port
from tests.support.waiting import wait_for

TWIST = {"topic": "/cmd_vel", "type": "geometry_msgs/Twist",
         "bounds": {"linear.x": [-0.3, 0.3], "angular.z": [-0.5, 0.5]}}


def policy(**target: Any) -> AgentPolicy:
    return AgentPolicy.model_validate({"targets": {"t": {**TWIST, **target}}})


@pytest.mark.parametrize(("target", "error"), [
    ({"bounds": {"data": [0, 1]}}, "no numeric field 'data'"),
    ({"bounds": {"linear.x": [1, -1]}}, "min 1.0 is above max -1.0"),
    ({"channel": "say"}, "exactly one of topic or channel"),
    ({"approval": "channel"}, "approval_channel"),
    ({"type": "std_msgs/String", "bounds": {}, "deadman_ms": 100}, "no zero command"),
    ({"max_rate_hz": 0}, "greater than 0"),
    ({"speed": 1}, "Extra inputs"),
])
def test_policy_yaml_refused(target: dict[str, Any], error: str) -> None:
    with pytest.raises(ValueError, match=error):
        policy(**target)


def test_pipeline_names_the_bad_key(tmp_path: Path) -> None:
    data = {"endpoints": {"d": {"address": "127.0.0.1:1"}},
            "routes": {"r": {"input": {"url": "x.avi"}, "call": {"service": "d",
                                                              "method": "Detect"},
                             "outputs": [{"product": "n", "from": "detections"}]}},
            "agent": {"targets": {"speak": {"channel": "loud"}}}}
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"agent.targets.speak.channel: no channel 'loud'"):
        load_pipeline(path)
    data["control"] = {"listen": "127.0.0.1:7100"}
    data["agent"] = {}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"control.*needs auth"):
        load_pipeline(path)


def test_content_clamped_or_refused() -> None:
    clamp = policy(beyond_bounds="clamp")
    checked = clamp.target("t").check("t", {"linear": {"x": -2}, "angular": {"z": 0.2}})
    assert checked.fields["linear.x"] == -0.3 and checked.fields["angular.z"] == 0.2
    assert checked.clamped == ["linear.x -2.0 -> -0.3"]
    refuse = policy()
    for message, why in [({"linear": {"x": 0.31}}, "outside"),
                         ({"angular": {"x": 0.1}}, "angular.x must be 0"),
                         ({"linear": {"x": True}}, "must be a number"),
                         ({"linear": {"x": "0.1"}}, "must be a number"),
                         ({"linear": "fast"}, "no field 'linear'"),
                         ("publish cmd_vel 5", "JSON object"),
                         ({"a": {"b": {"c": {"d": {"e": 1}}}}}, "nests too deep")]:
        with pytest.raises(Refused, match=why):
            refuse.target("t").check("t", message)
    with pytest.raises(Refused, match="not a target"):
        refuse.target("cmd_vel")


class LineClient:
    """A person at a text channel: reads lines, answers approvals as told."""

    def __init__(self, address: str) -> None:
        host, _, port = address.rpartition(":")
        self.sock = socket.create_connection((host, int(port)), timeout=10)
        self.file = self.sock.makefile("r")

    def line(self) -> str:
        return self.file.readline().strip()

    def say(self, text: str) -> None:
        self.sock.sendall(text.encode() + b"\n")

    def close(self) -> None:
        self.file.close()
        self.sock.close()


@pytest.fixture()
def channels() -> Iterator[Channels]:
    opened = Channels({"approvals": ChannelConfig(listen=f"127.0.0.1:{free_port()}"),
                       "speech": ChannelConfig(listen=f"127.0.0.1:{free_port()}")})
    opened.open_all()
    yield opened
    opened.close()


def test_approval_on_a_text_channel(channels: Channels, tmp_path: Path) -> None:
    rules = AgentPolicy.model_validate({"targets": {"speak": {
        "channel": "speech", "approval": "channel", "approval_channel": "approvals",
        "approval_timeout_s": 2, "max_rate_hz": 1000}}})
    audit = AuditLog(tmp_path / "audit.jsonl")
    actuation = Actuation(rules, ChannelSender(rules, channels), audit, channels)
    person = LineClient(channels.get("approvals").address)
    listener = LineClient(channels.get("speech").address)
    try:
        _wait_clients(channels)
        answers = iter(["yes", "no", None])

        def answer() -> None:
            for reply in answers:
                asked = person.line()
                assert asked.startswith("approve ") and '"hello"' in asked, asked
                number = asked.split()[1].rstrip("?")
                if reply is not None:
                    person.say(f"{reply} {number}")

        helper = threading.Thread(target=answer)
        helper.start()
        assert actuation.send("speak", {"data": "hello"})["sent"] == {"data": "hello"}
        assert listener.line() == "hello"
        time.sleep(0.01)  # the rate: 1000 a second
        with pytest.raises(Refused, match="not approved on channel approvals"):
            actuation.send("speak", {"data": "hello"})
        with pytest.raises(Refused, match="not approved"):  # nobody answered in time
            actuation.send("speak", {"data": "hello"})
        helper.join(10)
    finally:
        person.close()
        listener.close()
        actuation.close()
        audit.close()
    outcomes = [line for line in (tmp_path / "audit.jsonl").read_text().splitlines()]
    assert len(outcomes) == 3 and '"outcome": "sent"' in outcomes[0]


def test_answers_without_a_plain_number_are_told_the_form(channels: Channels) -> None:
    """`yes ²` (a digit to str.isdigit, not to int) and the like are answered with the form
    an answer takes; the approver goes on serving the same client."""
    approver = ChannelApprover(channels.get("approvals"))
    person = LineClient(channels.get("approvals").address)
    try:
        wait_for(lambda: channels.get("approvals").clients, 10, "the approver's client")
        for answer in ("yes \u00b2", "no \u2460", "yes -1", "yes", "yes 1 2"):
            person.say(answer)
            assert person.line() == "answer: yes N or no N", answer
        given: list[bool] = []
        asking = threading.Thread(target=lambda: given.append(approver.ask("q", 10)))
        asking.start()
        number = person.line().split()[1].rstrip("?")
        person.say(f"yes {number}")
        asking.join(10)
        assert given == [True]
    finally:
        person.close()


def _wait_clients(channels: Channels) -> None:
    wait_for(lambda: channels.get("approvals").clients and channels.get("speech").clients, 10,
             "the approval and speech clients")


def test_shipped_mobile_base_policy() -> None:
    shipped = config_dir() / "pipelines"
    config = load_pipeline(shipped / "people_qa.yaml",
                           [shipped / "agents" / "mobile_base.yaml"])
    assert config.agent is not None
    base = config.agent.target("cmd_vel")
    assert base.deadman_ms == 500
    checked = base.check("cmd_vel", {"linear": {"x": 1.0}, "angular": {"z": -1.0}})
    assert (checked.fields["linear.x"], checked.fields["angular.z"]) == (0.3, -0.5)
    with pytest.raises(Refused, match=r"linear\.y must be 0"):
        base.check("cmd_vel", {"linear": {"y": 0.1}})
    assert config.agent.targets["arm_lift"].approval == "elicit"


def test_topic_targets_need_the_callers_ros_sender(channels: Channels) -> None:
    """rclpy stays in ros/: a sender of topic targets comes from the caller, and without one
    the targets are refused at once, not at their first command."""
    with pytest.raises(ConfigError, match=r"agent targets on ROS topics \(t\)"):
        Senders(policy(), channels)


def test_deadman_fires_while_an_approval_waits(channels: Channels, tmp_path: Path,
                                               ros_env: dict[str, str]) -> None:
    rules = AgentPolicy.model_validate({"targets": {"arm": {
        "topic": ARM_TOPIC, "type": "std_msgs/Float64", "bounds": {"data": [0, 1]},
        "approval": "channel", "approval_channel": "approvals", "approval_timeout_s": 5,
        "max_rate_hz": 1000, "deadman_ms": 300}}})
    audit = AuditLog(tmp_path / "audit.jsonl")
    with ros_listener() as driver:
        actuation = Actuation(rules, Senders(rules, channels, RosSender), audit, channels)
        person = LineClient(channels.get("approvals").address)
        try:
            wait_for(lambda: channels.get("approvals").clients, 10, "the approver's client")
            approving = threading.Event()
            approving.set()

            def answer() -> None:
                while True:
                    try:
                        asked = person.line()
                    except (OSError, ValueError):  # closed at the end of the test
                        return
                    if not asked:
                        return
                    if approving.is_set():
                        person.say(f"yes {asked.split()[1].rstrip('?')}")

            threading.Thread(target=answer, daemon=True).start()
            driver.wait_publisher(ARM_TOPIC)
            deadline = time.monotonic() + 10
            while driver.arm.empty():  # until discovery is complete both ways
                assert time.monotonic() < deadline, "nothing reached the arm"
                actuation.send("arm", {"data": 0.5})
                time.sleep(0.1)
            time.sleep(0.5)
            driver.drain()
            actuation.send("arm", {"data": 0.5})
            assert driver.arm.get(timeout=5).data == 0.5
            approving.clear()  # the next command waits for a person who does not answer
            time.sleep(0.01)  # beyond the 1 ms that max_rate_hz leaves between two commands
            refusals: list[str] = []

            def unanswered() -> None:
                try:
                    actuation.send("arm", {"data": 0.9})
                except Refused as exc:
                    refusals.append(str(exc))

            pending = threading.Thread(target=unanswered)
            started = time.monotonic()
            pending.start()
            stop = driver.arm.get(timeout=3)
            assert stop.data == 0.0 and time.monotonic() - started < 2.0
            pending.join(10)
            assert refusals == ["arm: not approved on channel approvals"]
            assert driver.arm.empty()  # the unapproved 0.9 never went out
        finally:
            person.close()
            actuation.close()
            audit.close()
