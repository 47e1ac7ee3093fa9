"""scripts/llama-wheel.sh, sourced as scripts/setup.sh sources it (under `set -euo
pipefail`), for other machines: ORICF_ARCH and ORICF_CPUINFO stand for `uname -m` and
/proc/cpuinfo, the latter real texts of Arm machines (tests/data/cpuinfo)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from oricf.config import REPO_ROOT

CPUINFO = REPO_ROOT / "tests" / "data" / "cpuinfo"
X86_CPUINFO = """processor\t: 0
vendor_id\t: GenuineIntel
flags\t\t: fpu vme sse sse2 ssse3 fma sse4_1 sse4_2 avx f16c bmi1 avx2 bmi2 avx512f avx512bw
"""


def build_options(tmp_path: Path, arch: str, cpuinfo: Path) -> tuple[str, str]:
    """CMAKE_ARGS and LLAMA_WHEELS as the script sets them for that machine."""
    script = ('set -euo pipefail; source scripts/llama-wheel.sh; '
              'echo "$CMAKE_ARGS"; echo "$LLAMA_WHEELS"')
    env = {**os.environ, "ORICF_ARCH": arch, "ORICF_CPUINFO": str(cpuinfo),
           "CACHE": str(tmp_path)}
    result = subprocess.run([shutil.which("bash") or "/bin/bash", "-c", script], cwd=REPO_ROOT,
                            env=env, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    args, wheels = result.stdout.splitlines()
    return args, wheels


@pytest.mark.parametrize(("machine", "march"), [
    ("jetson-orin-nx.txt", "armv8.2-a+dotprod+fp16"),            # Cortex-A78AE
    ("graviton3.txt", "armv8.2-a+dotprod+fp16+sve+i8mm"),        # Neoverse V1
])
def test_arm_builds_for_the_cpu_through_ggml_s_arm_option(tmp_path: Path, machine: str,
                                                           march: str) -> None:
    args, _ = build_options(tmp_path, "aarch64", CPUINFO / machine)
    assert args == f"-DGGML_NATIVE=OFF -DGGML_CPU_ARM_ARCH={march}"


def test_an_arm_cpu_without_the_extensions_builds_generic(tmp_path: Path) -> None:
    args, _ = build_options(tmp_path, "aarch64", CPUINFO / "raspberry-pi-4.txt")  # Cortex-A72
    assert args == "-DGGML_NATIVE=OFF"


def test_x86_names_its_instruction_sets(tmp_path: Path) -> None:
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(X86_CPUINFO)
    args, _ = build_options(tmp_path, "x86_64", cpuinfo)
    assert args == ("-DGGML_NATIVE=OFF -DGGML_AVX=ON -DGGML_AVX2=ON -DGGML_FMA=ON -DGGML_F16C=ON "
                    "-DGGML_BMI2=ON -DGGML_AVX512=ON")


@pytest.mark.parametrize(("arch", "machine"), [
    ("x86_64", "jetson-orin-nx.txt"),   # no `flags` line, as in an emulator's cpuinfo
    ("aarch64", None),                  # no `Features` line (an x86 cpuinfo under emulation)
    ("riscv64", "jetson-orin-nx.txt"),  # another architecture
])
def test_a_cpuinfo_without_the_line_builds_generic(tmp_path: Path, arch: str,
                                                   machine: str | None) -> None:
    cpuinfo = CPUINFO / machine if machine else tmp_path / "cpuinfo"
    if machine is None:
        cpuinfo.write_text(X86_CPUINFO)
    args, _ = build_options(tmp_path, arch, cpuinfo)
    assert args == "-DGGML_NATIVE=OFF"


def test_the_cache_folder_is_keyed_by_the_options(tmp_path: Path) -> None:
    jetson = build_options(tmp_path, "aarch64", CPUINFO / "jetson-orin-nx.txt")[1]
    graviton = build_options(tmp_path, "aarch64", CPUINFO / "graviton3.txt")[1]
    again = build_options(tmp_path, "aarch64", CPUINFO / "jetson-orin-nx.txt")[1]
    assert jetson == again != graviton and Path(jetson).parent == tmp_path / "wheels"


def test_generic_builds_of_two_architectures_do_not_share_a_folder(tmp_path: Path) -> None:
    # No options on either (an x86 CPU without AVX, an Arm one without extensions): the key
    # must still tell them apart, or one would take the other's wheel.
    plain_x86 = tmp_path / "x86.txt"
    plain_x86.write_text("processor\t: 0\nflags\t\t: fpu sse sse2\n")
    plain_arm = tmp_path / "arm.txt"
    plain_arm.write_text("processor\t: 0\nFeatures\t: fp asimd\n")
    x86_args, x86 = build_options(tmp_path, "x86_64", plain_x86)
    arm_args, arm = build_options(tmp_path, "aarch64", plain_arm)
    assert x86_args == arm_args == "-DGGML_NATIVE=OFF" and x86 != arm


def test_an_architecture_named_either_way_has_one_folder(tmp_path: Path) -> None:
    # uname -m says aarch64 in the arm64 root; the image scripts say arm64 (Docker's name).
    jetson = CPUINFO / "jetson-orin-nx.txt"
    assert build_options(tmp_path, "arm64", jetson) == build_options(tmp_path, "aarch64", jetson)
