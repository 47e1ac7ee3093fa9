"""Triton's own client and shared-memory utilities (tritonclient.utils.shared_memory) against
an Open Inference Protocol server: `python triton_shm_client.py ADDRESS INPUT.npy OUTPUT.npy`
registers an input and an output region, infers through them, reads the status, unregisters,
and prints a JSON summary. A process of its own, as triton_client.py explains.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import tritonclient.grpc as triton
import tritonclient.utils.shared_memory as shm
from google.protobuf.json_format import MessageToDict

OUTPUT_SHAPE = [1, 3549, 85]


def main(address: str, input_path: str, output_path: str) -> None:
    client = triton.InferenceServerClient(address)
    tensor = np.load(input_path)
    out_bytes = int(np.prod(OUTPUT_SHAPE)) * 4
    client.unregister_system_shared_memory()
    input_region = shm.create_shared_memory_region("input_data", "/triton_in", tensor.nbytes)
    output_region = shm.create_shared_memory_region("output_data", "/triton_out", out_bytes)
    try:
        shm.set_shared_memory_region(input_region, [tensor])
        client.register_system_shared_memory("input_data", "/triton_in", tensor.nbytes)
        client.register_system_shared_memory("output_data", "/triton_out", out_bytes)
        status = client.get_system_shared_memory_status(as_json=True)
        inputs = [triton.InferInput("images", list(tensor.shape), "FP32")]
        inputs[0].set_shared_memory("input_data", tensor.nbytes)
        outputs = [triton.InferRequestedOutput("output")]
        outputs[0].set_shared_memory("output_data", out_bytes)
        result = client.infer("yolox-nano", inputs, outputs=outputs)
        # (get_output with as_json=True returns nothing in tritonclient 2.73)
        placed = MessageToDict(result.get_output("output"), preserving_proto_field_name=True)
        served = shm.get_contents_as_numpy(output_region, np.float32, OUTPUT_SHAPE)
        np.save(output_path, served)
        client.unregister_system_shared_memory("input_data")
        after_one = client.get_system_shared_memory_status(as_json=True)
        client.unregister_system_shared_memory()
        after_all = client.get_system_shared_memory_status(as_json=True)
    finally:
        shm.destroy_shared_memory_region(input_region)
        shm.destroy_shared_memory_region(output_region)
    print(json.dumps({"status": status, "placed": placed, "after_one": after_one,
                      "after_all": after_all}))


if __name__ == "__main__":
    main(*sys.argv[1:4])
