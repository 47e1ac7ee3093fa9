"""`oricf serve llm` and `oricf bench llm` as real processes."""

import signal
import subprocess
import sys
from pathlib import Path

import grpc
import pytest

from oricf.config import config_dir
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc
from tests.support.processes import free_port, oricf_process, wait_serving


def test_serve_answers_and_sigterm_lets_the_answer_finish() -> None:
    address = f"127.0.0.1:{free_port()}"
    with oricf_process("serve", "llm", "--listen", address) as process:
        wait_serving(address, timeout=120, process=process)
        with grpc.insecure_channel(address) as channel:
            stub = language_pb2_grpc.LanguageModelStub(channel)
            count = common_pb2.Fact(name="people_count", integer=3)
            request = language_pb2.GenerateRequest(prompt="How many people do you see?",
                                                   facts=[count])
            stream = stub.GenerateStream(request, timeout=30)
            first = next(stream)
            process.send_signal(signal.SIGTERM)  # drains: the answer in flight completes
            rest = list(stream)
        assert rest[-1].finish_reason == "stop"
        assert "3" in first.text + "".join(m.text for m in rest)
        assert process.wait(timeout=20) == 0
        output = process.stdout.read() if process.stdout else ""
        assert "gemma3-270m loaded" in output and "draining" in output


def serve_with(config: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "oricf", "serve", "llm", "--config", str(config)],
        capture_output=True, text=True, timeout=60, check=False)


def test_a_broken_prompt_file_is_refused_at_start(tmp_path: Path) -> None:
    prompt = tmp_path / "bad-prompt.yaml"
    prompt.write_text('format: {turn: "{question} {mood}", answer: " {answer}"}\n')
    config = tmp_path / "llm.yaml"
    config.write_text(f"prompts: {{gemma3-270m: {prompt.name}}}\n")
    result = serve_with(config)
    assert result.returncode == 2
    assert f"{prompt}: format: " in result.stderr and "{mood}" in result.stderr


def test_a_model_without_a_prompt_is_refused_at_start(tmp_path: Path) -> None:
    config = tmp_path / "llm.yaml"
    prompt = config_dir() / "prompts" / "gemma3-270m.yaml"
    config.write_text("model: {name: smollm2-135m-instruct}\n"
                      f"prompts: {{gemma3-270m: {prompt}}}\n")
    result = serve_with(config)
    assert result.returncode == 2
    assert f"{config}: (top level): prompts: no prompt template for model " \
           "'smollm2-135m-instruct'" in result.stderr


@pytest.mark.bench
def test_bench_runs_and_prints_its_table() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "--log-level", "WARNING", "bench", "llm",
         "--model", "smollm2-135m-instruct", "--questions", "8"],
        capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    row = next(line for line in result.stdout.splitlines()
               if line.startswith("smollm2-135m-instruct "))
    assert "/8" in row and "ms" in row


def test_serve_llm_loads_llama_cpp_before_grpc_numpy_and_opencv(tmp_path: Path) -> None:
    """A CUDA build of llama.cpp loaded after those libraries crashed the process
    (services/llm/preload.py): their order of import, as Python reports it."""
    overlay = tmp_path / "bad.yaml"
    overlay.write_text("model: {threads: 0, omp_wait_policy: ACTIVE}\n")  # refused, after
    result = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "oricf", "serve", "llm", "--overlay",
         str(overlay)], capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode != 0 and "model.threads" in result.stderr
    # -X importtime lists a module once its imports are done: llama_cpp's own line comes
    # after numpy (which it imports itself, after its libraries) but before grpc's.
    order = [line.rsplit("|", 1)[1].strip() for line in result.stderr.splitlines()
             if line.startswith("import time:") and "|" in line]
    assert order.index("llama_cpp") < order.index("grpc")
    assert "cv2" not in order[:order.index("llama_cpp")]
    assert "numpy" not in order[:order.index("llama_cpp.llama_cpp")]
