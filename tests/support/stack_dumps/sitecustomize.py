"""Loaded by every Python process that tests start with `oricf_process` (this folder leads
their PYTHONPATH): SIGUSR1 makes the process write where each of its threads stands, so a
test that finds a process hung can say where it hung (tests/support/processes.py)."""

import faulthandler
import signal

faulthandler.register(signal.SIGUSR1, all_threads=True)
