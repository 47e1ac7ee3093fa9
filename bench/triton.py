"""NVIDIA Triton Inference Server serving YOLOX-Nano (scripts/triton-server.sh: the server
that PyPI's nvidia-pytriton bundles) in a process group of its own on loopback, for
`oricf bench models` and the tests (`-m triton`) to call. Its environment is installed once,
apart from ORICF's, by `scripts/triton-server.sh --install`."""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import grpc

from oricf.config import REPO_ROOT
from oricf.launch.health import free_port
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc

SCRIPT = REPO_ROOT / "scripts" / "triton-server.sh"
INSTALL = "scripts/triton-server.sh --install"
MODELS = ("yolox-nano", "yolox-nano-decoded")  # scripts/triton_yolox.py
START_S = 180.0  # the server and one back-end process per model, on two busy cores
POLL_S = 0.2


class NotInstalled(RuntimeError):
    """Triton's environment is not there: the message says what to run."""


def installed() -> bool:
    folder = Path(os.environ.get("ORICF_TRITON_DIR") or Path.home() / ".cache/oricf/triton")
    return SCRIPT.exists() and any(folder.glob("installed-*"))


def _ready(stub: oip_grpc.GRPCInferenceServiceStub, process: subprocess.Popen[str],
           log: Path) -> bool:
    if process.poll() is not None:
        raise RuntimeError(f"Triton exited ({process.returncode}): {log.read_text()[-4000:]}")
    try:
        return all(stub.ModelReady(oip.ModelReadyRequest(name=name), timeout=1).ready
                   for name in MODELS)
    except grpc.RpcError:
        return False


def _wait_ready(address: str, process: subprocess.Popen[str], log: Path) -> None:
    with grpc.insecure_channel(address) as channel:
        stub = oip_grpc.GRPCInferenceServiceStub(channel)
        deadline = time.monotonic() + START_S
        while not _ready(stub, process, log):
            if time.monotonic() > deadline:
                raise TimeoutError(f"Triton's models at {address}: not ready in {START_S} s")
            time.sleep(POLL_S)


@contextmanager
def triton_server(*flags: str) -> Iterator[str]:
    """Triton's gRPC address once both models are ready; the whole group stops after.
    flags: scripts/triton_yolox.py's (--restrict-shared-memory)."""
    if not installed():
        raise NotInstalled(f"Triton is not installed: run {INSTALL} "
                           f"(and oricf models pull yolox-nano)")
    grpc_port = free_port()
    # A file, not a pipe: Triton logs a lot, and a pipe nobody reads would block it.
    with tempfile.TemporaryDirectory(prefix="oricf-triton-") as folder:
        log = Path(folder) / "triton.log"
        with log.open("w") as out:
            process = subprocess.Popen(
                [str(SCRIPT), "--grpc-port", str(grpc_port), "--http-port", str(free_port()),
                 *flags], stdout=out, stderr=subprocess.STDOUT, text=True,
                start_new_session=True)
        address = f"127.0.0.1:{grpc_port}"
        try:
            _wait_ready(address, process, log)
            yield address
        finally:
            stop_group(process)


def stop_group(process: subprocess.Popen[str]) -> None:
    """SIGINT to pytriton (it stops tritonserver and its back ends), SIGKILL to what is left
    of the group after that."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
        with suppress(subprocess.TimeoutExpired):
            process.wait(timeout=60)
    with suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()
