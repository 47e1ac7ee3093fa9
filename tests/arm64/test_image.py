"""The edge image for arm64: compose/build-image.sh builds it from an arm64 base that
debootstrap makes (compose/make-base-image.sh), and compose/smoke-test.sh passes with it
under emulation for the detector: SERVING through the container's health check, answering
over mTLS with the token, refusing callers without credentials, torn down. On Docker and on
podman, each running the arm64 container through qemu-user-static (binfmt_misc);
`compose/install-engines.sh` installs and starts both. An engine that does not answer fails
the test, naming what to run."""

from __future__ import annotations

import os
import subprocess

import pytest

from oricf.config import REPO_ROOT
from tests.arm64.root import require_tools

pytestmark = pytest.mark.arm64
IMAGE = "oricf:arm64"
SERVICES = "detector"


@pytest.mark.parametrize("engine", ["docker", "podman"])
def test_the_arm64_image_passes_the_smoke_test_for_the_detector(arm64_root: str,
                                                                 engine: str) -> None:
    # arm64_root: its set-up cross-compiled the Arm llama.cpp wheel that the image installs.
    require_tools()
    answers = subprocess.run([engine, "info"], capture_output=True, check=False)
    if answers.returncode != 0:
        pytest.fail(f"no {engine} engine answers: compose/install-engines.sh")
    result = subprocess.run(
        [str(REPO_ROOT / "compose" / "smoke-test.sh")], cwd=REPO_ROOT, capture_output=True,
        text=True, timeout=3 * 3600, check=False,
        env={**os.environ, "ORICF_ENGINE": engine, "ORICF_ARCH": "arm64",
             "ORICF_IMAGE": IMAGE, "ORICF_SMOKE_SERVICES": SERVICES,
             "ORICF_SMOKE_TIMEOUT": "1800"})
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-6000:]
    architecture = subprocess.run([engine, "image", "inspect", "-f", "{{.Architecture}}",
                                   IMAGE], capture_output=True, text=True, check=True)
    assert architecture.stdout.strip() == "arm64"
    assert "detector SERVING after" in result.stdout
    assert "ok   detector: " in result.stdout
    assert "ok   detector refuses: no token" in result.stdout
    assert "PASS: edge stack built" in result.stdout
