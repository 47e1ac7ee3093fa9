"""The demo run that test_demo.py and test_demo_speech.py both read (tests/demo/spoken.py)."""

from __future__ import annotations

import pytest

from tests.demo.spoken import DemoRun, spoken_demo_run


@pytest.fixture(scope="session")
def spoken_demo(tmp_path_factory: pytest.TempPathFactory) -> DemoRun:
    return spoken_demo_run(tmp_path_factory.mktemp("spoken_demo"))
