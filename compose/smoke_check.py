"""Request bodies and answer checks for compose/smoke-test.sh (which calls grpcurl).

    python compose/smoke_check.py request detector|asr|llm   > request.json
    grpcurl ... -d @ < request.json | python compose/smoke_check.py check detector|asr|llm

`check` prints what it found and exits 1 when the answer is wrong.
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


def main(argv: list[str]) -> int:
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
