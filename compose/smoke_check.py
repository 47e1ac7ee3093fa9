"""Request bodies and answer checks for compose/smoke-test.sh (which calls grpcurl).

    python compose/smoke_check.py request detector|asr|llm   > request.json
    grpcurl ... -d @ < request.json | python compose/smoke_check.py check detector|asr|llm
    python compose/smoke_check.py ros     (the robot side: a gateway on this DDS domain)

`check` prints what it found and exits 1 when the answer is wrong. `ros` publishes vtest.avi
frames on camera/image_raw until /human_counter answers, then a question on /question,
and checks that /answer states the count.
"""

from __future__ import annotations

import base64
import json
import re
import sys
from collections.abc import Callable
from typing import Any

QUESTION = "How many people do you see?"
PEOPLE = 3


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
    return {"prompt": QUESTION, "context": {"people_count": str(PEOPLE)}}


def detector_check(reply: dict[str, Any]) -> str | None:
    people = int(reply.get("counts", {}).get("person", 0))
    return None if people >= 1 else f"no person found in person.jpg: {reply}"


def asr_check(reply: dict[str, Any]) -> str | None:
    words = re.findall(r"[a-z]+", reply.get("text", "").lower())
    return None if {"how", "many", "people"} <= set(words) else f"wrong transcript: {reply}"


def llm_check(reply: dict[str, Any]) -> str | None:
    text = reply.get("text", "").lower()
    return None if re.search(r"\b(3|three)\b", text) else f"answer lacks the count 3: {reply}"


REQUESTS: dict[str, Callable[[], dict[str, Any]]] = {
    "detector": detector_request, "asr": asr_request, "llm": llm_request}
CHECKS: dict[str, Callable[[dict[str, Any]], str | None]] = {
    "detector": detector_check, "asr": asr_check, "llm": llm_check}


def ros_check(timeout_s: float = 120.0) -> int:
    import queue
    import time

    import cv2
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image
    from std_msgs.msg import Int32, String

    from oricf.gateway.convert import image_from_pixels
    from oricf.gateway.dds import use_large_data_profile
    from oricf.store import ModelStore

    capture = cv2.VideoCapture(str(ModelStore().path("vtest-video", "vtest.avi")))
    ok, frame = capture.read()
    capture.release()
    if not ok:
        print("FAIL ros: cannot read vtest.avi")
        return 1
    use_large_data_profile()  # raw frames between processes (see gateway/dds.py)
    context = Context()
    rclpy.init(context=context)
    node = Node("oricf_smoke_check", context=context)
    counts: queue.Queue[int] = queue.Queue()
    answers: queue.Queue[str] = queue.Queue()
    node.create_subscription(Int32, "/human_counter", lambda m: counts.put(m.data), 10)
    node.create_subscription(String, "/answer", lambda m: answers.put(m.data), 10)
    camera = node.create_publisher(Image, "camera/image_raw", qos_profile_sensor_data)
    question = node.create_publisher(String, "/question", 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout_s
    try:
        count = None
        while count is None and time.monotonic() < deadline:
            camera.publish(image_from_pixels(frame, "bgr8"))
            executor.spin_once(timeout_sec=0.5)
            count = None if counts.empty() else counts.get()
        if count is None:
            print("FAIL ros: no /human_counter from the gateway")
            return 1
        answer = None
        while answer is None and time.monotonic() < deadline:
            if question.get_subscription_count() > 0 and answers.empty():
                question.publish(String(data=QUESTION))
            for _ in range(10):
                executor.spin_once(timeout_sec=0.2)
            answer = None if answers.empty() else answers.get()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    if answer is None or str(count) not in answer:
        print(f"FAIL ros: count {count}, answer {answer!r}")
        return 1
    print(f"ok   gateway: /human_counter {count}, /answer {answer!r}")
    return 0


def main(argv: list[str]) -> int:
    if argv == ["ros"]:
        return ros_check()
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
    shown = {k: v for k, v in reply.items() if k in ("counts", "text", "timings")}
    print(f"ok   {service}: {json.dumps(shown)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
