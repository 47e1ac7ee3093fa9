"""A chunk policy that acts `lead` steps ahead of its observation and takes the `lead` actions
already committed before its chunk starts (real-time chunking), for a metaworld v3 task:
behaviour-cloned from the scripted expert, then DAgger through the control loop.

    python -m oricf.bench.train_committed_policy --task pick-place-v3 --lead 8 [--rounds 2]

Behind a round trip of `lead` steps the loop plays, between an observation and the chunk
that answers it, actions the previous chunk committed: the observation alone does not say
where they take the arm, so a policy that sees only it must guess (docs/control.md: 30%
behind 100 ms). This one takes them as a second input (`task.committed` in its declaration;
the loop sends them with `send_committed`), so its targets are well defined: the expert's
actions from `lead` steps on, after those committed actions.

- Demonstrations: as train_chunk_policy's (DART noise on the executed actions), the input
  the observation and the `lead` actions executed from its step on, the target the
  expert's clean actions from `lead` steps on.
- DAgger, `rounds` times: the policy drives the task through the loop behind `lead` steps
  (the gateway's ControlLoop and ActionQueue, the actions committed sent with each
  request); each request's observation and committed actions are labelled with the
  expert's `chunk` actions from `lead` steps on, found by replaying the episode's actions
  up to then from its seed; the pairs join the data and the policy is fitted again.

Written like train_chunk_policy's (policy.onnx: Concat of the two inputs, then the MLP;
policy.yaml; training.json) into `<model store root>/trained/<key>/`, and found there again.
Rollout episodes use seeds from 3,000,000 on, demonstrations from 1,000,000: evaluations
below that are on unseen episodes.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from oricf.bench.chunk_demos import Demos, chunks, demonstrations
from oricf.bench.chunk_mlp import Fit, Layers, forward, train
from oricf.bench.control_run import Wire, control_loop, setting
from oricf.bench.sims.metaworld import MetaworldSim, expert
from oricf.bench.train_chunk_policy import Settings as ChunkSettings
from oricf.bench.train_chunk_policy import cache_key, yaml_list
from oricf.files import staged_folder
from oricf.gateway.control.queue import Origin
from oricf.models.mlp_source import dense_layers, model_bytes
from oricf.models.policy import committed_window
from oricf.store import default_root, sha256_of

log = logging.getLogger(__name__)

ROLLOUT_SEEDS = 3_000_000
DIM = 4  # metaworld's actions
Act = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Settings(ChunkSettings):
    """train_chunk_policy's settings (its cache key too: these fields make the keys
    distinct), acting 8 steps ahead by default, and the DAgger rounds."""

    lead: int = 8
    rounds: int = 2          # DAgger rounds after the behaviour cloning
    rollouts: int = 16       # episodes a round
    rollout_steps: int = 160  # steps an episode at most: past it the arm is lost anyway


@dataclass
class Data:
    observations: list[np.ndarray]
    committed: list[np.ndarray]    # [lead * DIM] each
    targets: list[np.ndarray]      # [chunk * DIM] each


def committed_policy(task: str = "pick-place-v3", *, root: Path | None = None,
                     **settings: int | float) -> Path:
    """The declaration of the policy with these settings, trained first when not cached."""
    chosen = Settings(task=task, **settings)  # type: ignore[arg-type]
    folder = (root or default_root()) / "trained" / cache_key(chosen)
    if not (folder / "policy.yaml").is_file():
        train_and_write(chosen, folder)
    return folder / "policy.yaml"


def demonstrated(settings: Settings) -> Data:
    """The expert's demonstrations as pairs: each observation with the `lead` actions
    executed from it on, its target the clean actions from `lead` steps on."""
    data = Data([], [], [])
    for demo in demonstrations(settings.task, settings.demos, settings.seed, settings.noise):
        data.observations += list(demo.observations)
        data.committed += list(chunks(demo.executed, settings.lead))
        data.targets += list(chunks(demo.clean, settings.chunk, settings.lead))
    return data


class Fitted:
    """The MLP on [the normalised observation, the committed actions], as the service runs
    it: answers clipped to [-1, 1]."""

    def __init__(self, data: Data, settings: Settings) -> None:
        observations, targets = np.asarray(data.observations), np.asarray(data.targets)
        self.mean, self.std = Demos(observations, targets).normalisation()
        inputs = np.concatenate([(observations - self.mean) / self.std,
                                 np.asarray(data.committed)], axis=1)
        self.layers: Layers = train(inputs, targets, [settings.hidden, settings.hidden],
                                    Fit(settings.epochs, settings.batch, settings.lr),
                                    settings.seed)

    def act(self, observation: np.ndarray, committed: np.ndarray) -> np.ndarray:
        x = np.concatenate([(observation - self.mean) / self.std, committed])[None]
        return np.clip(forward(self.layers, x.astype(np.float32))[-1][0], -1.0, 1.0)


def rollout(settings: Settings, sim: MetaworldSim, policy: Fitted, seed: int
            ) -> tuple[list[tuple[int, np.ndarray, np.ndarray]], list[np.ndarray]]:
    """One episode through the loop behind `lead` steps, as `edge-committed` runs it in the
    bench: each request (step, observation, committed window) and every action played."""
    lead, chunk = settings.lead, settings.chunk
    loop = control_loop(sim, setting("edge-committed", lead, chunk), settings.rollout_steps)
    wire = Wire(lead)
    observation = sim.reset(seed)
    requests, played = [], []
    for step in range(settings.rollout_steps):
        wire.arrive(loop, step, chunk, DIM)
        request = loop.ask(step, observation, now_ns=step)
        if request is not None:
            first, actions = request.committed or (step, np.zeros((0, DIM)))
            window = committed_window((first - step, actions), lead, DIM).reshape(-1)
            requests.append((step, observation.copy(), window))
            answer = policy.act(observation, window).tolist()
            wire.send(step, answer, step + lead, Origin(step, step))
        played.append(loop.act(step).action)
        result = sim.step(played[-1])
        observation = result.observation
        if result.done:
            break
    return requests, played


def label(settings: Settings, sim: MetaworldSim, act: Act, seed: int,
          played: list[np.ndarray], step: int) -> np.ndarray | None:
    """The expert's chunk from `step + lead` on, after the actions played until then."""
    if step + settings.lead > len(played):
        return None
    observation = sim.reset(seed)
    for action in played[:step + settings.lead]:
        result = sim.step(action)
        observation = result.observation
        if result.done:
            return None
    actions: list[np.ndarray] = []
    while len(actions) < settings.chunk:
        actions.append(act(observation))
        result = sim.step(np.clip(actions[-1], sim.action_low, sim.action_high))
        observation = result.observation
        if result.done:
            break
    return np.concatenate(actions + [actions[-1]] * (settings.chunk - len(actions)))


def train_and_write(settings: Settings, folder: Path) -> None:
    started = time.monotonic()
    data = demonstrated(settings)
    demonstrations = len(data.targets)
    sim, replay, act = MetaworldSim(settings.task), MetaworldSim(settings.task), expert(
        settings.task)
    try:
        policy = Fitted(data, settings)
        for round_ in range(settings.rounds):
            added = 0
            for episode in range(settings.rollouts):
                seed = ROLLOUT_SEEDS + 1000 * round_ + episode
                requests, played = rollout(settings, sim, policy, seed)
                for step, observation, window in requests:
                    target = label(settings, replay, act, seed, played, step)
                    if target is not None:
                        data.observations.append(observation)
                        data.committed.append(window)
                        data.targets.append(target)
                        added += 1
            log.info("%s: DAgger round %d: %d pairs added", settings.task, round_ + 1, added)
            policy = Fitted(data, settings)
    finally:
        sim.close()
        replay.close()
    write(folder, settings, policy, {"demonstrated_pairs": demonstrations,
                                     "dagger_pairs": len(data.targets) - demonstrations,
                                     "seconds": round(time.monotonic() - started, 1)})


def write(folder: Path, settings: Settings, policy: Fitted, counts: dict[str, float]) -> None:
    with staged_folder(folder) as staged:
        model = staged / "policy.onnx"
        model.write_bytes(to_onnx(policy.layers, settings))
        (staged / "policy.yaml").write_text(
            f"# A chunk policy for {settings.task} acting {settings.lead} steps ahead and taking "
            f"the actions committed before its chunk\n# (python -m "
            f"oricf.bench.train_committed_policy; training.json: its settings).\n"
            f"name: bc-committed-{settings.task}-{folder.name[:8]}\nlicense: MIT\n"
            f"weights: {{path: ./{model.name}, sha256: {sha256_of(model)}}}\n"
            f"backend: {{engine: onnxruntime, threads: 1}}\n"
            f"task:\n  kind: policy\n"
            f"  state:\n    input: observation\n    size: {policy.mean.size}\n"
            f"    mean: {yaml_list(policy.mean)}\n    std: {yaml_list(policy.std)}\n"
            f"  committed: {{input: committed, steps: {settings.lead}}}\n"
            f"  action: {{output: action, dim: {DIM}, low: -1.0, high: 1.0}}\n"
            f"  chunk: {settings.chunk}\n  rate_hz: 80\n  lead_steps: {settings.lead}\n")
        (staged / "training.json").write_text(json.dumps(
            {**asdict(settings), **counts}, indent=1))


def to_onnx(layers: Layers, settings: Settings) -> bytes:
    """observation [batch, 39] and committed [batch, lead x 4] -> action [batch, chunk x 4]:
    Concat, then MatMul/Add/Relu."""
    from onnx import TensorProto, helper

    concat = helper.make_node("Concat", ["observation", "committed"], ["joined"], axis=1)
    nodes, inits = dense_layers(layers, "joined", "action")
    value = helper.make_tensor_value_info
    observations = layers[0][0].shape[0] - settings.lead * DIM
    graph = helper.make_graph(
        [concat, *nodes], f"committed-{settings.task}",
        [value("observation", TensorProto.FLOAT, ["batch", observations]),
         value("committed", TensorProto.FLOAT, ["batch", settings.lead * DIM])],
        [value("action", TensorProto.FLOAT, ["batch", settings.chunk * DIM])], inits)
    return model_bytes(graph)


def main(argv: list[str] | None = None) -> int:
    defaults = Settings()
    parser = argparse.ArgumentParser(prog="python -m oricf.bench.train_committed_policy",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default=defaults.task, help="a metaworld v3 task")
    for name in ("lead", "rounds", "rollouts", "demos", "chunk", "seed", "epochs"):
        parser.add_argument(f"--{name}", type=int, default=getattr(defaults, name))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    print(committed_policy(**vars(args)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
