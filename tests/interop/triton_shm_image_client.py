"""Triton's own client and shared-memory utilities with an image instead of the network's
tensor: `python triton_shm_image_client.py ADDRESS INPUT.npy OUTPUT.npy IMAGE JPEG_OUTPUT.npy`
puts the image's pixels (UINT8 [H, W, 3], rgb8) and then the image file itself (one BYTES
element, serialised as Triton lays BYTES out: a 4-byte little-endian length before each
element) in regions, infers from each with the output in a region, and prints a JSON
summary. INPUT.npy (the FP32 tensor) is not used: the server pre-processes the image.
A process of its own, as triton_client.py explains.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np
import tritonclient.grpc as triton
import tritonclient.utils.shared_memory as shm
from tritonclient.utils import (
    InferenceServerException,
    serialize_byte_tensor,
    serialized_byte_size,
)

OUTPUT_SHAPE = [1, 3549, 85]


def infer_from(client: triton.InferenceServerClient, output: shm.SharedMemoryRegion,
               region: str, datatype: str, shape: list[int], byte_size: int) -> np.ndarray:
    """One inference with the input in `region` and the output in the region "output",
    zeroed first so that nothing an earlier call wrote there passes for this one's."""
    shm.set_shared_memory_region(output, [np.zeros(OUTPUT_SHAPE, np.float32)])
    inputs = [triton.InferInput("images", shape, datatype)]
    inputs[0].set_shared_memory(region, byte_size)
    outputs = [triton.InferRequestedOutput("output")]
    outputs[0].set_shared_memory("output", int(np.prod(OUTPUT_SHAPE)) * 4)
    client.infer("yolox-nano", inputs, outputs=outputs)
    return shm.get_contents_as_numpy(output, np.float32, OUTPUT_SHAPE)


def refusal(call: object) -> list[str]:
    try:
        call()  # type: ignore[operator]
    except InferenceServerException as exc:
        return [str(exc.status()), str(exc.message())]
    return ["accepted", ""]


def main(address: str, _input: str, output_path: str, image_path: str,
         jpeg_output_path: str) -> None:
    client = triton.InferenceServerClient(address)
    pixels = np.ascontiguousarray(cv2.imread(image_path)[:, :, ::-1])  # BGR -> rgb8
    encoded = serialize_byte_tensor(np.array([Path(image_path).read_bytes()], dtype=np.object_))
    sizes = {"pixels": pixels.nbytes, "jpeg": serialized_byte_size(encoded),
             "output": int(np.prod(OUTPUT_SHAPE)) * 4}
    regions = {name: shm.create_shared_memory_region(name, f"/triton_{name}", size)
               for name, size in sizes.items()}
    try:
        shm.set_shared_memory_region(regions["pixels"], [pixels])
        shm.set_shared_memory_region(regions["jpeg"], [encoded])
        for name, size in sizes.items():
            client.register_system_shared_memory(name, f"/triton_{name}", size)
        status = client.get_system_shared_memory_status(as_json=True)
        np.save(output_path, infer_from(client, regions["output"], "pixels", "UINT8",
                                        list(pixels.shape), sizes["pixels"]))
        np.save(jpeg_output_path, infer_from(client, regions["output"], "jpeg", "BYTES", [1],
                                             sizes["jpeg"]))
        # The element's length prefix claims more bytes than the tensor is said to have.
        cut = refusal(lambda: infer_from(client, regions["output"], "jpeg", "BYTES", [1],
                                         sizes["jpeg"] - 10))
        client.unregister_system_shared_memory()
        after = client.get_system_shared_memory_status(as_json=True)
    finally:
        for region in regions.values():
            shm.destroy_shared_memory_region(region)
    print(json.dumps({"status": status, "sizes": sizes, "after": after, "cut": cut,
                      "input_shape": list(pixels.shape[:2])}))


if __name__ == "__main__":
    main(*sys.argv[1:6])
