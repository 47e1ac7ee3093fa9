"""KServe's own Python ModelServer (the `kserve` package) serving YOLOX-Nano through a small
custom predictor: a third-party Open Inference Protocol server for the gateway to call.

    python kserve_server.py --grpc_port PORT --http_port PORT MODEL.onnx

KServe parses its flags from the command line itself. It binds every interface; the two
patches below keep it on loopback, as a test server should be.
"""

from __future__ import annotations

import sys

import grpc.aio
import kserve
import onnxruntime as ort
import uvicorn
from kserve import InferOutput, InferRequest, InferResponse

_config_init = uvicorn.Config.__init__
_add_port = grpc.aio._server.Server.add_insecure_port


def _loopback_config(self: uvicorn.Config, *args: object, **kwargs: object) -> None:
    kwargs["host"] = "127.0.0.1"
    _config_init(self, *args, **kwargs)  # type: ignore[arg-type]


def _loopback_port(self: grpc.aio.Server, address: str) -> int:
    return _add_port(self, address.replace("[::]", "127.0.0.1"))


uvicorn.Config.__init__ = _loopback_config  # type: ignore[method-assign]
grpc.aio._server.Server.add_insecure_port = _loopback_port  # type: ignore[method-assign]


class OnnxPredictor(kserve.Model):
    """Runs one ONNX file on its first input; returns its first output."""

    def __init__(self, name: str, path: str) -> None:
        super().__init__(name)
        self.path = path
        self.session: ort.InferenceSession | None = None
        self.load()

    def load(self) -> bool:
        self.session = ort.InferenceSession(self.path, providers=["CPUExecutionProvider"])
        self.ready = True
        return self.ready

    def predict(self, payload: InferRequest, headers: dict[str, str] | None = None,
                response_headers: dict[str, str] | None = None) -> InferResponse:
        assert self.session is not None
        tensor = payload.inputs[0].as_numpy()
        name = self.session.get_inputs()[0].name
        output = self.session.run(None, {name: tensor})[0]
        result = InferOutput(name=self.session.get_outputs()[0].name, shape=list(output.shape),
                             datatype="FP32", data=output)
        return InferResponse(response_id=payload.id, model_name=self.name,
                             infer_outputs=[result])


if __name__ == "__main__":
    kserve.ModelServer().start([OnnxPredictor("kserve-yolox", sys.argv[-1])])
