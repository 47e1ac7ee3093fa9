"""Real model services, the agent pipeline and a ROS driver for the agent tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.gateway.agents.scene import RosListener, pipeline_yaml, ros_listener
from tests.support.services import RunningService


@pytest.fixture(scope="module")
def services(detector: RunningService, llm: RunningService, asr: RunningService
             ) -> dict[str, RunningService]:
    return {"detector": detector, "llm": llm, "asr": asr}


@pytest.fixture(scope="module")
def pipeline(services: dict[str, RunningService], tmp_path_factory: pytest.TempPathFactory
             ) -> Path:
    folder = tmp_path_factory.mktemp("agent")
    return pipeline_yaml(folder, services["detector"].address, services["llm"].address,
                         services["asr"].address)


@pytest.fixture()
def driver(ros_env: dict[str, str]) -> Iterator[RosListener]:
    with ros_listener() as listener:
        yield listener
