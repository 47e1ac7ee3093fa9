"""Triton's own client (tritonclient[grpc]) against an Open Inference Protocol server:
`python triton_client.py ADDRESS INPUT.npy OUTPUT.npy` prints a JSON summary.

Run as a process of its own: tritonclient brings its own copy of the protocol's messages,
which cannot share a process with another copy (ORICF's, KServe's).
"""

from __future__ import annotations

import json
import sys

import numpy as np
import tritonclient.grpc as triton
from tritonclient.utils import InferenceServerException


def refusal(call: object) -> str:
    try:
        call()  # type: ignore[operator]
    except InferenceServerException as exc:
        return str(exc.status())
    return "accepted"


def main(address: str, input_path: str, output_path: str) -> None:
    client = triton.InferenceServerClient(address)
    tensor = np.load(input_path)
    meta = client.get_model_metadata("yolox-nano", as_json=True)
    inputs = [triton.InferInput("images", list(tensor.shape), "FP32")]
    inputs[0].set_data_from_numpy(tensor)
    result = client.infer("yolox-nano", inputs, request_id="triton-1",
                          outputs=[triton.InferRequestedOutput("output")])
    np.save(output_path, result.as_numpy("output"))
    wrong = [triton.InferInput("pixels", list(tensor.shape), "FP32")]
    wrong[0].set_data_from_numpy(tensor)
    print(json.dumps({
        "live": client.is_server_live(), "ready": client.is_server_ready(),
        "model_ready": client.is_model_ready("yolox-nano"),
        "server": client.get_server_metadata(as_json=True)["name"],
        "inputs": meta["inputs"], "outputs": meta["outputs"],
        "id": result.get_response().id,
        "unknown_model": refusal(lambda: client.infer("nope", inputs)),
        "unknown_input": refusal(lambda: client.infer("yolox-nano", wrong)),
    }))


if __name__ == "__main__":
    main(*sys.argv[1:4])
