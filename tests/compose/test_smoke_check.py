"""compose/smoke_check.py's check of the policy service's answer (what the compose smoke test
and the Kubernetes pod tests rely on): it passes the answer the same policy gives here, in
grpcurl's JSON and in protobuf's, and fails one for another observation or with other
actions."""

from __future__ import annotations

from typing import Any

import pytest

from tests.compose.smoke import smoke_check

CHECK = smoke_check()


def right_answer() -> dict[str, Any]:
    """The reply as grpcurl prints it: proto field names, 64-bit integers as strings."""
    return {"start_step": str(CHECK.HOPPER_STEP), "observation_step": str(CHECK.HOPPER_STEP),
            "capture_time_ns": str(CHECK.CAPTURE_TIME_NS), "action_dim": 3,
            "actions": CHECK.expected_actions(), "model": "pybullet-hopper"}


def test_the_policys_own_answer_passes_by_either_field_name() -> None:
    answer = right_answer()
    assert CHECK.policy_check(answer) is None
    camel = {"observationStep": answer["observation_step"],
             "captureTimeNs": answer["capture_time_ns"], "actionDim": 3,
             "actions": answer["actions"]}
    assert CHECK.policy_check(camel) is None


@pytest.mark.parametrize(("key", "value", "problem"), [
    ("observation_step", "21", "not for the observation sent"),
    ("capture_time_ns", "0", "not for the observation sent"),
    ("action_dim", 2, "not one Hopper action"),
    ("actions", [0.0, 0.0, 0.0], "the same policy here gives"),
])
def test_a_wrong_answer_fails_naming_what_is_wrong(key: str, value: Any, problem: str) -> None:
    answer = right_answer() | {key: value}
    message = CHECK.policy_check(answer)
    assert message is not None and problem in message
