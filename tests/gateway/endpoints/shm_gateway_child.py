"""A gateway's Detect route through shared memory, alone in a process, for the SIGKILL test:
`python shm_gateway_child.py ADDRESS` calls the detector over and over with vtest.avi
frames, printing the first count, until it is killed."""

from __future__ import annotations

import sys
from typing import Any

from oricf.gateway.endpoints import Endpoint, EndpointConfig
from oricf.gateway.methods.detect import METHOD, DetectCall
from oricf.gateway.values import Frame
from tests.support.data import video_frames


def main(address: str) -> None:
    endpoint = Endpoint("detector", EndpointConfig(address=address, deadline_ms=30_000,
                                                   image={"transport": "shm"}), METHOD)
    products: Any = None  # Detect reads no data products
    invoke = METHOD.open(DetectCall(method="Detect", service="detector", labels=["person"]),
                         endpoint, products)
    frame = Frame.from_pixels(video_frames([0])[0])
    print(len(invoke({"image": frame}).detections), flush=True)
    while True:
        invoke({"image": frame})


if __name__ == "__main__":
    main(sys.argv[1])
