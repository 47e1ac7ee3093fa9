"""YOLOX-Nano on NVIDIA Triton Inference Server: the server that `nvidia-pytriton` bundles
(`tritonserver`, its Python back end), with onnxruntime running the ONNX file in the
function each model is bound to. It runs in the environment scripts/triton-server.sh makes
(pytriton, onnxruntime, opencv), not in ORICF's: this is the Triton side a team already has.

    python triton_yolox.py MODEL.onnx --grpc-port PORT --http-port PORT

Two models, both on the Open Inference Protocol over gRPC (and HTTP, which pytriton needs
to load them), on 127.0.0.1 only:

- `yolox-nano`: the network as the file has it, `images` FP32 [1, 3, 416, 416] in,
  `output` FP32 [1, 3549, 85] out;
- `yolox-nano-decoded`: a camera frame in, detections out, as a Triton user serves a
  detector with its pre- and post-processing: `images` UINT8 [H, W, 3] (BGR) in, letterboxed
  like ORICF's declaration (top left, padded with 114); `output` FP32 [n, 6] out (x_min,
  y_min, x_max, y_max in the frame's pixels, score, class id), after per-class NMS.
"""

from __future__ import annotations

import argparse
import logging
import os
import stat
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
from pytriton.model_config import ModelConfig, Tensor
from pytriton.proxy.types import Request
from pytriton.triton import DEFAULT_PROTECTED_ENDPOINTS, Triton, TritonConfig, TritonSecurityConfig

log = logging.getLogger("triton_yolox")
MAX_TOKEN_FILE = 64 * 1024

SIZE = 416
STRIDES = (8, 16, 32)
MIN_SCORE = 0.35  # configs/models/yolox-nano.yaml
IOU = 0.45
PAD = 114


def grid() -> tuple[np.ndarray, np.ndarray]:
    """Each output row's cell (x, y) and stride, in the network's order."""
    cells, strides = [], []
    for stride in STRIDES:
        ys, xs = np.meshgrid(np.arange(SIZE // stride), np.arange(SIZE // stride), indexing="ij")
        cells.append(np.stack((xs, ys), axis=-1).reshape(-1, 2))
        strides.append(np.full((cells[-1].shape[0], 1), stride))
    return np.concatenate(cells).astype(np.float32), np.concatenate(strides).astype(np.float32)


def letterbox(frame: np.ndarray) -> tuple[np.ndarray, float]:
    height, width = frame.shape[:2]
    scale = min(SIZE / width, SIZE / height)
    new_w, new_h = max(1, int(width * scale)), max(1, int(height * scale))
    canvas = np.full((SIZE, SIZE, 3), PAD, dtype=np.uint8)
    canvas[:new_h, :new_w] = cv2.resize(frame, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    return canvas.transpose(2, 0, 1)[None].astype(np.float32), scale


def nms(boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """Greedy per-class suppression (classes shifted apart), best first."""
    if len(boxes) == 0:
        return np.empty(0, dtype=np.int64)
    shifted = boxes + (classes.astype(np.float32) * (boxes.max() + 1.0))[:, None]
    areas = (shifted[:, 2] - shifted[:, 0]) * (shifted[:, 3] - shifted[:, 1])
    order, keep = scores.argsort()[::-1], []
    while order.size:
        best, rest = order[0], order[1:]
        keep.append(int(best))
        low = np.maximum(shifted[best, :2], shifted[rest, :2])
        high = np.minimum(shifted[best, 2:], shifted[rest, 2:])
        inter = np.prod(np.clip(high - low, 0, None), axis=1)
        order = rest[inter / (areas[best] + areas[rest] - inter + 1e-9) <= IOU]
    return np.array(keep, dtype=np.int64)


class Yolox:
    """One onnxruntime session on the file, on one thread as ORICF's declaration runs it."""

    def __init__(self, path: str) -> None:
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        self.session = ort.InferenceSession(path, options, providers=["CPUExecutionProvider"])
        self.cells, self.strides = grid()

    def network(self, requests: list[Request]) -> list[dict[str, np.ndarray]]:
        return [{"output": self.session.run(None, {"images": r["images"]})[0]}
                for r in requests]

    def decoded(self, requests: list[Request]) -> list[dict[str, np.ndarray]]:
        return [{"output": self.detect(r["images"])} for r in requests]

    def detect(self, frame: np.ndarray) -> np.ndarray:
        tensor, scale = letterbox(frame)
        rows = self.session.run(None, {"images": tensor})[0][0]
        probabilities = rows[:, 5:] * rows[:, 4:5]
        classes, scores = probabilities.argmax(1), probabilities.max(1)
        keep = scores >= MIN_SCORE
        centres = (rows[keep, :2] + self.cells[keep]) * self.strides[keep]
        sizes = np.exp(rows[keep, 2:4]) * self.strides[keep]
        boxes = np.concatenate((centres - sizes / 2, centres + sizes / 2), axis=1) / scale
        kept = nms(boxes, scores[keep], classes[keep])
        return np.concatenate((boxes[kept], scores[keep][kept, None],
                               classes[keep][kept, None]), axis=1).astype(np.float32)


def read_token(path: Path) -> str:
    """The first token of a token file, by the rules ORICF reads one with (oricf.tls; this
    environment has no ORICF to import): a regular file (a FIFO would wait for a writer
    for ever, /dev/zero never end), of a few KiB at most, the token visible ASCII as gRPC
    metadata carries it. ValueError naming the file otherwise, never quoting the token."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    with open(fd, "rb") as file:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ValueError(f"{path}: not a regular file")
        data = file.read(MAX_TOKEN_FILE + 1)
    lines = [line.strip() for line in data.splitlines() if line.strip()]
    if len(data) > MAX_TOKEN_FILE or not lines:
        raise ValueError(f"{path}: no token, or more than {MAX_TOKEN_FILE} bytes")
    if any(byte not in range(0x21, 0x7F) for byte in lines[0]):
        raise ValueError(f"{path}: the token is visible ASCII only ('!' to '~')")
    return lines[0].decode("ascii")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", help="the YOLOX-Nano ONNX file")
    parser.add_argument("--grpc-port", type=int, default=8001)
    parser.add_argument("--http-port", type=int, default=8000)
    parser.add_argument("--restrict-shared-memory", action="store_true",
                        help="keep pytriton's default: the shared-memory protocol only with "
                             "its access token, which callers other than pytriton lack")
    parser.add_argument("--access-token-file", type=Path, default=None,
                        help="the restricted protocols' access token (a random one when not "
                             "given): callers send it as triton-grpc-protocol-triton-access-"
                             "token")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    try:
        token = read_token(args.access_token_file) if args.access_token_file else None
    except (OSError, ValueError) as exc:
        parser.error(f"--access-token-file: {exc}")
    yolox = Yolox(args.model)
    config = TritonConfig(grpc_address="127.0.0.1", grpc_port=args.grpc_port,
                          http_address="127.0.0.1", http_port=args.http_port,
                          allow_metrics=False)
    # pytriton puts Triton's shared-memory protocol behind a random access token; tritonserver
    # itself leaves it open, as clients on the same host expect.
    restricted = [e for e in DEFAULT_PROTECTED_ENDPOINTS
                  if args.restrict_shared_memory or e != "shared-memory"]
    unbatched = ModelConfig(batching=False)
    with Triton(config=config,
                security_config=TritonSecurityConfig(
                    access_token=token,
                    restricted_endpoints=restricted)) as triton:
        triton.bind("yolox-nano", yolox.network,
                    [Tensor(name="images", dtype=np.float32, shape=(1, 3, SIZE, SIZE))],
                    [Tensor(name="output", dtype=np.float32, shape=(1, 3549, 85))],
                    config=unbatched, strict=True)
        triton.bind("yolox-nano-decoded", yolox.decoded,
                    [Tensor(name="images", dtype=np.uint8, shape=(-1, -1, 3))],
                    [Tensor(name="output", dtype=np.float32, shape=(-1, 6))],
                    config=unbatched, strict=True)
        log.info("serving yolox-nano and yolox-nano-decoded on 127.0.0.1:%d", args.grpc_port)
        triton.serve()


if __name__ == "__main__":
    main()
