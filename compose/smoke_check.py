"""Request bodies and answer checks for compose/smoke-test.sh (which calls grpcurl).

    python compose/smoke_check.py request detector|asr|llm|tts|policy   > request.json
    grpcurl ... -d @ < request.json | python compose/smoke_check.py check SERVICE
    python compose/smoke_check.py ros     (the robot side: a gateway on this DDS domain)
    python compose/smoke_check.py protoset > oricf.protoset

`check` prints what it found and exits 1 when the answer is wrong. `ros` publishes vtest.avi
frames on camera/image_raw until /human_counter answers, then a question on /question,
and checks that /answer states the count. `protoset` writes the schemas grpcurl needs (the
five services' and grpc.health.v1), since the services serve no reflection.
"""

from __future__ import annotations

import base64
import json
import re
import sys
import time
from collections.abc import Callable
from typing import Any

QUESTION = "How many people do you see?"
PEOPLE = 3
# pybullet's Hopper 20 steps after a reset with no action (its observation, already
# normalised by the environment): the policy service's state.
HOPPER_STATE = [-0.0428, 0.0, 1.0, -0.0524, 0.0, -0.0075, 0.0, -0.1474, 0.8902, -0.0773,
                1.0317, 0.0001, -0.0618, -0.002, 1.0]
HOPPER_STEP = 20
CAPTURE_TIME_NS = 1_234_567_890_123   # below 2**53: exact wherever JSON makes it a float


def detector_request() -> dict[str, Any]:
    from oricf.store import ModelStore

    jpeg = ModelStore().path("darknet-images", "person.jpg").read_bytes()
    return {"image": {"data": base64.b64encode(jpeg).decode(), "encoding": "jpeg"},
            "labels": ["person"]}


def asr_request() -> dict[str, Any]:
    from oricf.audio import synthesize

    samples = synthesize(QUESTION)
    return {"audio": {"data": base64.b64encode(samples.tobytes()).decode(),
                      "encoding": "pcm_s16le", "sample_rate": 16000, "channels": 1},
            "language": "en"}


def llm_request() -> dict[str, Any]:
    return {"prompt": QUESTION, "facts": [{"name": "people_count", "integer": PEOPLE}]}


def tts_request() -> dict[str, Any]:
    return {"text": f"I can see {PEOPLE} people.", "voice": "joe"}


def policy_request() -> dict[str, Any]:
    return {"step": HOPPER_STEP, "capture_time_ns": CAPTURE_TIME_NS, "state": HOPPER_STATE}


def detector_check(reply: dict[str, Any]) -> str | None:
    people = sum(d.get("label") == "person" for d in reply.get("detections", []))
    return None if people >= 1 else f"no person found in person.jpg: {reply}"


def asr_check(reply: dict[str, Any]) -> str | None:
    words = re.findall(r"[a-z]+", reply.get("text", "").lower())
    return None if {"how", "many", "people"} <= set(words) else f"wrong transcript: {reply}"


def llm_check(reply: dict[str, Any]) -> str | None:
    text = reply.get("text", "").lower()
    return None if re.search(r"\b(3|three)\b", text) else f"answer lacks the count 3: {reply}"


def tts_check(reply: dict[str, Any]) -> str | None:
    audio = base64.b64decode(reply.get("audio", {}).get("data", ""))
    seconds = reply.get("duration_s", reply.get("durationS", 0.0))  # proto or JSON name
    said = reply.get("text")
    if len(audio) > 20_000 and 0.8 < seconds < 5 and said == "I can see three people.":
        return None
    return f"no plausible speech: {len(audio)} bytes, {seconds} s, text {reply.get('text')!r}"


def field(reply: dict[str, Any], name: str, default: Any = None) -> Any:
    """A field by its proto name or its JSON name (grpcurl's: camelCase)."""
    head, *rest = name.split("_")
    return reply.get(name, reply.get(head + "".join(w.title() for w in rest), default))


def expected_actions() -> list[float]:
    """What the policy the service's YAML names answers HOPPER_STATE with, here."""
    import numpy as np

    from oricf.config import config_dir, load_config
    from oricf.models.declaration import load_declaration
    from oricf.models.policy import PolicyModel
    from oricf.services.policy.service import PolicyConfig
    from oricf.store import ModelStore

    config = load_config(config_dir() / "services" / "policy.yaml", PolicyConfig)
    policy = PolicyModel(load_declaration(config.model), ModelStore())
    policy.load()
    try:
        return [float(a) for a in policy.act(np.asarray(HOPPER_STATE)).ravel()]
    finally:
        policy.close()


def policy_check(reply: dict[str, Any]) -> str | None:
    actions = [float(a) for a in reply.get("actions", [])]
    echoed = (int(field(reply, "observation_step", 0)), int(field(reply, "capture_time_ns", 0)))
    if echoed != (HOPPER_STEP, CAPTURE_TIME_NS):
        return f"the answer is not for the observation sent: step, capture time {echoed}"
    expected = expected_actions()
    if int(field(reply, "action_dim", 0)) != 3 or len(actions) != len(expected):
        return f"not one Hopper action (3 values): {reply}"
    if any(abs(a - e) > 1e-4 for a, e in zip(actions, expected, strict=True)):
        return f"actions {actions}, the same policy here gives {expected}"
    return None


REQUESTS: dict[str, Callable[[], dict[str, Any]]] = {
    "detector": detector_request, "asr": asr_request, "llm": llm_request, "tts": tts_request,
    "policy": policy_request}
CHECKS: dict[str, Callable[[dict[str, Any]], str | None]] = {
    "detector": detector_check, "asr": asr_check, "llm": llm_check, "tts": tts_check,
    "policy": policy_check}


def ros_check(timeout_s: float = 120.0) -> int:
    """A vtest.avi frame -> /human_counter, then /question -> an /answer with that count."""
    import rclpy

    from oricf.demo.node import DemoNode, ros_context

    frame = first_video_frame()
    context = ros_context()
    node = DemoNode(context)
    deadline = time.monotonic() + timeout_s
    try:
        count = first_count(node, frame, deadline)
        answer = typed_answer(node, deadline) if count is not None else None
    finally:
        node.close()
        rclpy.try_shutdown(context=context)
    if count is None or answer is None or str(count) not in answer:
        print(f"FAIL ros: /human_counter {count}, /answer {answer!r}")
        return 1
    print(f"ok   gateway: /human_counter {count}, /answer {answer!r}")
    return 0


def first_video_frame() -> Any:
    import cv2

    from oricf.store import ModelStore

    capture = cv2.VideoCapture(str(ModelStore().path("vtest-video", "vtest.avi")))
    ok, frame = capture.read()
    capture.release()
    if not ok:
        raise RuntimeError("cannot read vtest.avi")
    return frame


def first_count(node: Any, frame: Any, deadline: float) -> int | None:
    """Publishes the frame twice a second until the gateway counts it."""
    from oricf.demo.node import COUNT, image_from_pixels

    while time.monotonic() < deadline:
        node.camera.publish(image_from_pixels(frame, "bgr8"))
        received = node.next(COUNT, timeout=0.5)
        if received is not None:
            return int(received.value)
    return None


def typed_answer(node: Any, deadline: float) -> str | None:
    """Asks once the gateway listens on /question; asks again every 5 s without an answer."""
    from oricf.demo.node import ANSWER

    while time.monotonic() < deadline:
        if node.question.get_subscription_count() > 0:
            node.type(QUESTION)
            received = node.next(ANSWER, timeout=5.0)
            if received is not None:
                return str(received.value)
        else:
            time.sleep(0.2)
    return None


def protoset() -> bytes:
    """A FileDescriptorSet of the five services and grpc.health.v1, dependencies first."""
    from google.protobuf import descriptor_pb2
    from grpc_health.v1 import health_pb2

    from oricf.v1 import detector_pb2, language_pb2, policy_pb2, speech_pb2, synthesis_pb2

    files = descriptor_pb2.FileDescriptorSet()
    added: set[str] = set()

    def add(file: Any) -> None:
        if file.name not in added:
            for dependency in file.dependencies:
                add(dependency)
            added.add(file.name)
            file.CopyToProto(files.file.add())

    for module in (detector_pb2, speech_pb2, language_pb2, synthesis_pb2, policy_pb2,
                   health_pb2):
        add(module.DESCRIPTOR)
    return files.SerializeToString()


def main(argv: list[str]) -> int:
    if argv == ["ros"]:
        return ros_check()
    if argv == ["protoset"]:
        sys.stdout.buffer.write(protoset())
        return 0
    if len(argv) != 2 or argv[0] not in ("request", "check") or argv[1] not in REQUESTS:
        print(__doc__, file=sys.stderr)
        return 2
    action, service = argv
    if action == "request":
        json.dump(REQUESTS[service](), sys.stdout)
        return 0
    reply = json.load(sys.stdin)
    problem = CHECKS[service](reply)
    if problem:
        print(f"FAIL {service}: {problem[:500]}")
        return 1
    shown = {k: v for k, v in reply.items() if k in ("text", "timings", "actions")}
    if "detections" in reply:
        shown["labels"] = [d.get("label") for d in reply["detections"]]
    print(f"ok   {service}: {json.dumps(shown)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
