"""The arm64 suite's scripts, checked in the default run (the suite itself is `-m arm64`):
they pass shellcheck, and each says what it does when given nothing to do."""

from __future__ import annotations

import shutil
import subprocess

from oricf.config import REPO_ROOT

SCRIPTS = [REPO_ROOT / "scripts" / name for name in ("arm64-root.sh", "arm64-setup.sh")]


def test_the_arm64_scripts_pass_shellcheck() -> None:
    assert shutil.which("shellcheck"), "shellcheck is missing: scripts/setup.sh --dev installs it"
    result = subprocess.run(["shellcheck", "-x", *map(str, SCRIPTS)], capture_output=True,
                            text=True, check=False, cwd=REPO_ROOT)
    assert result.returncode == 0, result.stdout


def test_the_root_script_without_a_command_prints_its_usage() -> None:
    result = subprocess.run([str(SCRIPTS[0])], capture_output=True, text=True, check=False)
    assert result.returncode == 2
    for command in ("make", "setup", "run CMD", "path"):
        assert f"scripts/arm64-root.sh {command}" in result.stderr
