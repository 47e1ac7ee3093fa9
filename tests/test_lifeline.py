"""oricf.lifeline: a child started with child_options() stops when its launcher dies, by
SIGKILL too: first as on SIGTERM, then, if it does not stop within its grace, killed with
everything in its process group. Real processes; the launcher is a Python process of its own
that the test kills."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.launch.helpers import alive

# The launcher: starts CHILD with child_options(), prints the child's pid, then waits.
LAUNCHER = textwrap.dedent("""
    import subprocess, sys, time, os
    from oricf.lifeline import child_options
    env, fds = child_options()
    child = subprocess.Popen([sys.executable, "-c", sys.argv[1], *sys.argv[2:]],
                             env={**os.environ, **env}, pass_fds=fds,
                             start_new_session=True)
    print(child.pid, flush=True)
    time.sleep(600)
""")

# The child: follows its launcher; on SIGTERM writes a note (or ignores it, argv[2] == "deaf");
# starts a grandchild in its process group; writes whether the variable was left for it.
CHILD = textwrap.dedent("""
    import os, signal, subprocess, sys, time
    from pathlib import Path
    from oricf.lifeline import ENV, follow_parent
    folder, mode = Path(sys.argv[1]), sys.argv[2]
    assert follow_parent(grace_s=1.0)
    (folder / "env-left").write_text(str(ENV in os.environ))
    def on_term(signum, frame):
        (folder / "sigterm").write_text("stopping")
        if mode != "deaf":
            sys.exit(0)
    signal.signal(signal.SIGTERM, on_term)
    grandchild = subprocess.Popen(["sleep", "600"])
    (folder / "grandchild").write_text(str(grandchild.pid))
    while True:
        time.sleep(0.1)
""")


def wait_for(condition: Callable[[], bool], timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def start_and_kill_launcher(folder: Path, mode: str) -> int:
    """Starts the launcher and its child, kills the launcher with SIGKILL; the child's pid."""
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCHER, CHILD, str(folder), mode],
                                stdout=subprocess.PIPE, text=True)
    assert launcher.stdout is not None
    child = int(launcher.stdout.readline())
    assert wait_for(lambda: (folder / "grandchild").exists())
    assert alive(child)
    launcher.kill()
    launcher.wait()
    return child


def test_a_child_stops_as_on_sigterm_when_its_launcher_is_killed(tmp_path: Path) -> None:
    child = start_and_kill_launcher(tmp_path, "obedient")
    assert wait_for(lambda: not alive(child)), "the child outlived its launcher"
    assert (tmp_path / "sigterm").read_text() == "stopping"
    assert (tmp_path / "env-left").read_text() == "False"  # not handed down further


def test_a_child_deaf_to_sigterm_is_killed_with_its_group(tmp_path: Path) -> None:
    child = start_and_kill_launcher(tmp_path, "deaf")
    grandchild = int((tmp_path / "grandchild").read_text())
    assert wait_for(lambda: not alive(child) and not alive(grandchild))
    assert (tmp_path / "sigterm").exists()  # it was asked first


def test_without_a_launcher_nothing_is_followed(monkeypatch: pytest.MonkeyPatch) -> None:
    from oricf.lifeline import ENV, follow_parent

    monkeypatch.delenv(ENV, raising=False)
    assert follow_parent() is False
    monkeypatch.setenv(ENV, "not-a-number")
    assert follow_parent() is False
    assert ENV not in os.environ
