"""round: a post step added as one module (gateway/post/round.py): the pipeline schema takes
its key from the registry, checks the fields it reads, and names its keys in errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from oricf.errors import ConfigError, InvalidInput
from oricf.gateway.components import PostSteps
from oricf.gateway.config import PostStep, parse_pipeline

PIPELINE: dict[str, Any] = {
    "endpoints": {"detector": {"address": "127.0.0.1:50051"}},
    "routes": {"people": {
        "input": {"url": "video.mp4"},
        "call": {"service": "detector", "method": "Detect"},
        "outputs": [{"jsonl": "-", "from": "count"}]}}}


def pipeline(post: list[dict[str, Any]]) -> dict[str, Any]:
    route = {**PIPELINE["routes"]["people"], "post": post}
    return {**PIPELINE, "routes": {"people": route}}


def test_rounds_into_a_field_or_in_place() -> None:
    record: dict[str, Any] = {"speed": 1.26, "count": 3}
    PostSteps([PostStep.model_validate({"round": {"field": "speed", "digits": 1,
                                                  "into": "shown"}}),
               PostStep.model_validate({"round": {"field": "speed"}})]).run(record)
    assert record == {"speed": 1, "shown": 1.3, "count": 3}
    assert isinstance(record["speed"], int)


def test_a_value_that_is_no_number_is_bad_input() -> None:
    steps = PostSteps([PostStep.model_validate({"round": {"field": "label"}})])
    with pytest.raises(InvalidInput, match="round: label is not a number"):
        steps.run({"label": "person"})


def test_a_pipeline_takes_the_key_and_checks_its_fields(tmp_path: Path) -> None:
    post = [{"count": {}}, {"round": {"field": "count", "into": "shown"}}]
    config = parse_pipeline(pipeline(post), "p.yaml", tmp_path)
    assert config.routes["people"].post[1].kind == "round"
    with pytest.raises(ConfigError, match=r"p.yaml: routes.people.post\[0\].round: "
                                          r"no field 'speed'"):
        parse_pipeline(pipeline([{"round": {"field": "speed"}}]), "p.yaml", tmp_path)


def test_its_settings_are_checked_naming_the_key(tmp_path: Path) -> None:
    post = [{"count": {}}, {"round": {"field": "count", "digits": -1}}]
    with pytest.raises(ConfigError, match=r"p.yaml: routes.people.post\[1\].round.digits: "):
        parse_pipeline(pipeline(post), "p.yaml", tmp_path)
