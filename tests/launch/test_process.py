"""ManagedProcess with real child processes: output, stop escalation, whole-group kill."""

from __future__ import annotations

import sys
import time

from oricf.launch.deployment import ProcessPlan, Restart
from oricf.launch.process import ManagedProcess, describe_exit, wants_restart
from tests.launch.helpers import alive, group_members

# Ignores SIGTERM, starts a grandchild that does too, then says so.
STUBBORN = """
import signal, subprocess, sys, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)
child = subprocess.Popen([sys.executable, "-c",
    "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); time.sleep(60)"])
print("grandchild", child.pid, flush=True)
time.sleep(60)
"""


def plan(code: str, restart: Restart | None = None) -> ProcessPlan:
    return ProcessPlan("child", [sys.executable, "-c", code], {}, restart or Restart())


def wait_lines(lines: list[tuple[str, str]], count: int, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while len(lines) < count:
        assert time.monotonic() < deadline, lines
        time.sleep(0.05)


def test_output_lines_reach_the_sink_with_the_name() -> None:
    lines: list[tuple[str, str]] = []
    process = ManagedProcess(plan("print('one'); print('two')"), lambda n, s: lines.append((n, s)))
    process.start()
    wait_lines(lines, 2)
    # The child exits by itself once it has printed; stop() before then would end it with
    # SIGTERM, which is another test's behaviour.
    deadline = time.monotonic() + 10
    while process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert process.stop(grace_s=5) == 0
    assert lines == [("child", "one"), ("child", "two")]
    assert list(process.tail) == ["one", "two"]


def test_stop_escalates_to_sigkill_and_takes_the_whole_group() -> None:
    lines: list[tuple[str, str]] = []
    process = ManagedProcess(plan(STUBBORN), lambda n, s: lines.append((n, s)))
    process.start()
    wait_lines(lines, 1)
    grandchild = int(lines[0][1].split()[1])
    assert process.pid is not None and alive(grandchild)
    started = time.monotonic()
    code = process.stop(grace_s=0.5)
    assert code is not None and describe_exit(code) == "killed by SIGKILL"
    assert time.monotonic() - started < 5
    time.sleep(0.2)  # the grandchild's parent is gone: init reaps it
    assert not alive(grandchild)
    assert group_members(process.pid) == []


def test_stop_of_a_process_that_never_started_is_a_no_op() -> None:
    assert ManagedProcess(plan("pass"), lambda n, s: None).stop(grace_s=1) is None


def test_restart_policies() -> None:
    def process(policy: str, restarts: int = 0) -> ManagedProcess:
        managed = ManagedProcess(plan("pass", Restart(policy=policy, max_restarts=2)),
                                 lambda n, s: None)
        managed.restarts = restarts
        return managed

    assert not wants_restart(process("no"), 1)
    assert not wants_restart(process("on-failure"), 0)
    assert wants_restart(process("on-failure"), -9)
    assert wants_restart(process("always"), 0)
    assert not wants_restart(process("always", restarts=2), 1)
    assert describe_exit(3) == "exit code 3"
