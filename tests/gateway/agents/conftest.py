"""Real model services, the agent pipeline and a ROS driver for the agent tests."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.gateway.agents.scene import RosListener, pipeline_yaml, ros_listener
from tests.support.services import RunningService, running_service


@pytest.fixture(scope="module")
def services() -> Iterator[dict[str, RunningService]]:
    with running_service("detector") as detector, running_service("llm") as llm, \
            running_service("asr") as asr:
        yield {"detector": detector, "llm": llm, "asr": asr}


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
