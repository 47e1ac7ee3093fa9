"""`oricf mcp --config` with a pipeline that has ROS topics: the gateway's ROS node spins in
the MCP server's process beside the agent's own node; a question published by a plain rclpy
node is answered on its topic while the agent looks and publishes."""

from __future__ import annotations

import queue
import time
from pathlib import Path
from typing import Any

import anyio
import yaml

from tests.gateway.agents.scene import PEOPLE, RosListener
from tests.gateway.agents.session import stdio_session, text_of, wait_product, warm_up


def with_topics(pipeline: Path) -> Path:
    data = yaml.safe_load(pipeline.read_text())
    data["routes"]["typed"] = {
        "input": {"topic": "/agent_test/question", "type": "std_msgs/String"},
        "call": {"service": "llm", "method": "Generate", "prompt": "{text}", "max_tokens": 24,
                 "context": {"products": ["people_count"], "stale": "omit"}},
        "outputs": [{"topic": "/agent_test/answer", "type": "std_msgs/String",
                     "from": "answer"}]}
    path = pipeline.parent / "agent_ros.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_ros_pipeline_in_the_mcp_process(pipeline: Path, driver: RosListener) -> None:
    from std_msgs.msg import String

    answers: queue.Queue[Any] = queue.Queue()
    driver.node.create_subscription(String, "/agent_test/answer", answers.put, 10)
    questions = driver.node.create_publisher(String, "/agent_test/question", 10)

    async def scenario() -> None:
        async with stdio_session("--config", str(with_topics(pipeline))) as session:
            assert (await wait_product(session, "people_count"))["value"] == PEOPLE
            deadline = time.monotonic() + 60
            while answers.empty():  # until discovery is complete both ways
                assert time.monotonic() < deadline, "no answer on /agent_test/answer"
                questions.publish(String(data="How many people do you see?"))
                await anyio.sleep(2.0)
            status = await session.call_tool("status", {})
            assert status.structured_content is not None
            assert status.structured_content["routes"]["typed"]["ok"] >= 1
            await warm_up(session, "cmd_vel", driver.twists)
            look = await session.call_tool("look", {})
            assert not look.is_error, text_of(look)

    anyio.run(scenario)
    assert answers.get_nowait().data.strip()
