"""Merge modes as a table: a mode is one entry of MERGES, named in the pipeline YAML with its
own keys (`merge: NAME` or `merge: {mode: NAME, ...}`), its defaults as the queue had them."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydantic import Field

from oricf.errors import ConfigError
from oricf.gateway.config import PipelineConfig, load_pipeline
from oricf.gateway.control.merge import MERGES, Ensemble, MergeMode, Weighted
from oricf.gateway.control.queue import ActionQueue

PIPELINE = """
endpoints:
  arm_policy: {address: 127.0.0.1:50099}
routes:
  arm:
    input:
      control:
        rate_hz: 50
        action_dim: 2
        state: [{topic: /arm/state, type: std_msgs/Float64MultiArray, size: 4}]
        target: {topic: /arm/command}
        merge: MERGE
    call: {method: Act, service: arm_policy}
"""


def pipeline(tmp_path: Path, merge: str) -> PipelineConfig:
    path = tmp_path / "arm.yaml"
    path.write_text(PIPELINE.replace("MERGE", merge))
    return load_pipeline(path)


def merge_of(config: PipelineConfig) -> Any:
    return config.routes["arm"].input.control.merge


def overlapped(merge: MergeMode) -> np.ndarray:
    """The action for step 3 where two chunks overlap: the older says 0, the newer 1."""
    queue = ActionQueue(2, merge=merge)
    queue.put(np.zeros((4, 2)), start_step=1, now=0)
    queue.put(np.ones((4, 2)), start_step=3, now=2)
    action = queue.take(3)
    assert action is not None
    return action


class Scaled(MergeMode):
    """A mode only this test knows: the newer chunk's action times `scale`."""

    scale: float = Field(1.0, gt=0)

    def combine(self, actions: Sequence[np.ndarray]) -> np.ndarray:
        return actions[-1] * self.scale


def test_a_mode_added_to_the_table_is_taken_from_yaml_with_its_keys(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(MERGES, "scaled", Scaled)
    merge = merge_of(pipeline(tmp_path, "{mode: scaled, scale: 3}"))
    assert merge == Scaled(scale=3)
    assert overlapped(merge).tolist() == [3.0, 3.0]
    assert merge_of(pipeline(tmp_path, "scaled")) == Scaled()  # its defaults
    with pytest.raises(ConfigError, match=r"merge: .*scaled: scale: .*greater than 0"):
        pipeline(tmp_path, "{mode: scaled, scale: -1}")


def test_today_s_names_keep_their_defaults(tmp_path: Path) -> None:
    assert merge_of(pipeline(tmp_path, "weighted")) == Weighted(weight=0.7)
    assert overlapped(merge_of(pipeline(tmp_path, "weighted"))) == pytest.approx([0.7, 0.7])
    assert merge_of(pipeline(tmp_path, "ensemble")) == Ensemble(k=0.01)
    assert overlapped(merge_of(pipeline(tmp_path, "latest"))).tolist() == [1.0, 1.0]
    # exp(-0.01 * i): the older chunk weighs 1, the newer exp(-0.01)
    newer = np.exp(-0.01)
    assert overlapped(merge_of(pipeline(tmp_path, "ensemble"))) == pytest.approx(
        [newer / (1 + newer)] * 2)


def test_a_mode_s_keys_are_set_in_yaml(tmp_path: Path) -> None:
    merge = merge_of(pipeline(tmp_path, "{mode: weighted, weight: 0.5}"))
    assert overlapped(merge) == pytest.approx([0.5, 0.5])
    assert merge_of(pipeline(tmp_path, "{mode: ensemble, k: 0.5}")) == Ensemble(k=0.5)


@pytest.mark.parametrize(("merge", "said"), [
    ("median", r"merge: .*a merge mode: latest \| weighted \| ensemble"),
    ("{weight: 0.5}", r"merge: .*a merge mode"),
    ("{mode: latest, weight: 0.5}", r"merge: .*latest: weight: Extra inputs"),
    ("{mode: weighted, k: 0.5}", r"merge: .*weighted: k: Extra inputs"),
])
def test_an_unknown_mode_or_another_mode_s_key_is_refused_naming_the_key(
        tmp_path: Path, merge: str, said: str) -> None:
    with pytest.raises(ConfigError, match=said):
        pipeline(tmp_path, merge)
