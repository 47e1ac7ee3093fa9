"""compose/stack.sh, the container route's one entry point, run for real: its help and
commands in the default run; in the engines suite (`-m engines`, docs/testing.md) its
`check` and `env` on Docker (compose v1 or v2) and on podman, and the podman-compose version
check that refuses the robot side to Debian's 1.0.3 (the check a `grep -q` under pipefail
never fired). Building and starting the stack is compose/smoke-test.sh's job
(tests/compose/test_smoke_test.py)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from oricf.config import REPO_ROOT

COMPOSE = REPO_ROOT / "compose"
STACK = COMPOSE / "stack.sh"
SCRIPTS = sorted([*COMPOSE.glob("*.sh"), *COMPOSE.glob("kubernetes/*.sh")])
DEBIAN_PODMAN_COMPOSE = Path("/usr/bin/podman-compose")


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(STACK), *args], capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})}, check=False)


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_scripts_parse(script: Path) -> None:
    assert subprocess.run(["bash", "-n", str(script)], check=False).returncode == 0


def test_scripts_pass_shellcheck() -> None:
    assert shutil.which("shellcheck"), "shellcheck is missing: scripts/setup.sh --dev installs it"
    # -x: follow what a script sources (scripts/llama-wheel.sh), named from the root
    result = subprocess.run(["shellcheck", "-x", *map(str, SCRIPTS)], capture_output=True,
                            text=True, check=False, cwd=REPO_ROOT)
    assert result.returncode == 0, result.stdout


def test_help_names_every_command_it_dispatches() -> None:
    result = run("--help")
    assert result.returncode == 0
    documented = set(re.findall(r"^  ([a-z][a-z-]+)(?: |$)", result.stdout, re.MULTILINE))
    text = STACK.read_text()
    dispatched = {"install-podman-compose"}           # runs before an engine is picked
    dispatched |= set(re.findall(r"^    ([a-z|]+)\) ;;$", text, re.MULTILINE)[0].split("|"))
    assert documented == dispatched


def test_an_unknown_command_is_refused() -> None:
    result = run("start")
    assert result.returncode == 2 and "COMMAND" in result.stderr


def test_the_smoke_test_builds_and_starts_through_the_entry_point_only() -> None:
    code = [line for line in (COMPOSE / "smoke-test.sh").read_text().splitlines()
            if not line.lstrip().startswith("#")]
    assert any("STACK=(compose/stack.sh)" in line for line in code)
    for own_copy in ("ENGINE build", "podman build", "docker build", "podman-compose",
                     "docker compose", "--format docker"):
        assert not [line for line in code if own_copy in line], own_copy


@pytest.mark.engines
@pytest.mark.parametrize("engine", ["docker", "podman"])
def test_check_names_the_engine_and_starts_a_container(engine: str) -> None:
    """Fails, saying what is missing, where the engine or its compose tool is not installed
    (compose/install-engines.sh installs both)."""
    result = run("check", env={"ORICF_ENGINE": engine})
    assert result.returncode == 0, result.stderr
    lines = dict(line.split(":", 1) for line in result.stdout.splitlines())
    assert lines["engine"].split()[0] == engine
    assert re.search(r"\d+\.\d+\.\d+", lines["compose"])
    if engine == "podman":
        assert lines["CONTAINERS_CONF"].strip().endswith("compose/containers.conf")
    else:  # the robot side's network_mode: host runs on every docker compose
        assert "(robot side: yes)" in lines["compose"]
    exported = run("env", env={"ORICF_ENGINE": engine}).stdout
    assert f"export ORICF_ENGINE={engine}\n" in exported


@pytest.mark.engines
def test_the_robot_side_is_refused_to_a_podman_compose_older_than_1_0_6() -> None:
    assert DEBIAN_PODMAN_COMPOSE.exists(), "no Debian podman-compose: compose/install-engines.sh"
    env = {"ORICF_ENGINE": "podman", "ORICF_PODMAN_COMPOSE": str(DEBIAN_PODMAN_COMPOSE)}
    version = run("check", env=env)
    match = re.search(r"^compose: +\S+ (\d+)\.(\d+)\.(\d+)", version.stdout, re.MULTILINE)
    assert match, version.stdout + version.stderr
    robot = run("--robot", "check", env=env)
    if tuple(map(int, match.groups())) >= (1, 0, 6):
        assert robot.returncode == 0, robot.stderr
    else:
        assert robot.returncode == 1
        assert "needs podman-compose >= 1.0.6" in robot.stderr
        assert "compose/stack.sh install-podman-compose" in robot.stderr
