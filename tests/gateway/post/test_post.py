"""Post-processors on real detections of a real frame."""

from __future__ import annotations

import numpy as np
import pytest

from oricf.errors import InvalidInput
from oricf.gateway import post
from oricf.gateway.config import PostStep
from oricf.gateway.values import Frame, Record
from oricf.imaging import Box, Detection
from tests.support.data import video_frames


def step(**kwargs: object) -> PostStep:
    return PostStep.model_validate(kwargs)


def record() -> Record:
    return {"image": Frame.from_pixels(video_frames([0])[0]),
            "detections": [Detection("person", 0, 0.85, Box(10, 10, 60, 150)),
                           Detection("person", 0, 0.40, Box(200, 30, 240, 120)),
                           Detection("bicycle", 1, 0.70, Box(300, 200, 380, 260))]}


def test_map_filter_count_template_in_order() -> None:
    steps = post.PostSteps([step(map_labels={"person": "human"}),
                            step(filter={"labels": ["human"], "min_score": 0.5}),
                            step(count={"label": "human", "into": "humans"}),
                            step(count={}),
                            step(template={"text": "I see {humans} human(s).",
                                           "into": "said"})])
    result = record()
    steps.run(result)
    assert [d.label for d in result["detections"]] == ["human"]
    assert (result["humans"], result["count"], result["said"]) == (1, 1, "I see 1 human(s).")


@pytest.mark.parametrize(("steps", "counts"), [
    ([{"filter": {"min_score": 0.5}}], {"person": 1, "bicycle": 1}),
    ([{"filter": {"labels": ["bicycle"]}}], {"person": 0, "bicycle": 1}),
    ([{"map_labels": {"bicycle": "person"}}], {"person": 3}),
    ([{"map_labels": {"person": "human", "bicycle": "human"}},
      {"filter": {"min_score": 0.6}}], {"human": 2}),
], ids=["by-score", "by-label", "merged-labels", "merged-then-filtered"])
def test_counts_always_agree_with_the_detections(steps: list[dict[str, object]],
                                                 counts: dict[str, int]) -> None:
    """A label counted after steps that rename or drop detections counts what is left
    (0 when none is)."""
    result = record()
    post.PostSteps([*(step(**s) for s in steps),
                    *(step(count={"label": label, "into": label}) for label in counts)]).run(result)
    assert {label: result[label] for label in counts} == counts
    assert sum(counts.values()) == len(result["detections"])


def test_annotate_draws_on_the_input_image() -> None:
    result = record()
    post.PostSteps([step(annotate={})]).run(result)
    annotated = result["annotated"]
    original = result["image"].pixels()
    assert (annotated.width, annotated.height, annotated.encoding) == (768, 576, "bgr8")
    changed = np.any(annotated.pixels() != original, axis=2)
    assert changed[10, 10:60].all()       # the top edge of the first box
    assert not changed[500:, :200].any()  # far from every box


def test_template_with_a_missing_field_is_an_input_error() -> None:
    with pytest.raises(InvalidInput, match="cannot fill 'nobody'"):
        post.PostSteps([step(template={"text": "{nobody}"})]).run(record())
