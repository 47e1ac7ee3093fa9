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
import hashlib
import importlib.metadata
import json
import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from oricf.bench.chunk_demos import chunks, demo_seed
from oricf.bench.chunk_mlp import Fit, Layers, forward, train
from oricf.bench.sims.metaworld import MetaworldSim, expert
from oricf.bench.train_chunk_policy import staging, yaml_list
from oricf.errors import ConfigError
from oricf.gateway.actions.loop import ControlLoop
from oricf.gateway.actions.queue import ActionQueue, Origin
from oricf.models.mlp_source import model_bytes
from oricf.models.policy import committed_window
from oricf.store import default_root, sha256_of

log = logging.getLogger(__name__)

FORMAT = 1
ROLLOUT_SEEDS = 3_000_000
DIM = 4  # metaworld's actions


@dataclass(frozen=True)
class Settings:
    task: str = "pick-place-v3"
    lead: int = 8
    rounds: int = 2          # DAgger rounds after the behaviour cloning
    rollouts: int = 16       # episodes a round
    rollout_steps: int = 160  # steps an episode at most: past it the arm is lost anyway
    demos: int = 60
    chunk: int = 16
    seed: int = 0
    epochs: int = 300
    noise: float = 0.1
    hidden: int = 256


@dataclass
class Data:
    observations: list[np.ndarray]
    committed: list[np.ndarray]    # [lead * DIM] each
    targets: list[np.ndarray]      # [chunk * DIM] each


def cache_key(settings: Settings) -> str:
    text = json.dumps({**asdict(settings), "metaworld": importlib.metadata.version("metaworld"),
                       "format": FORMAT, "kind": "committed"}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def committed_policy(task: str = "pick-place-v3", *, root: Path | None = None,
                     **settings: int | float) -> Path:
    """The declaration of the policy with these settings, trained first when not cached."""
    folder = (root or default_root()) / "trained" / cache_key(Settings(task=task, **settings))  # type: ignore[arg-type]
    if not (folder / "policy.yaml").is_file():
        train_and_write(Settings(task=task, **settings), folder)  # type: ignore[arg-type]
    return folder / "policy.yaml"


def demonstrations(settings: Settings, sim: MetaworldSim) -> Data:
    act = expert(settings.task)
    data = Data([], [], [])
    kept = tried = 0
    while kept < settings.demos and tried < 3 * settings.demos:
        seed = demo_seed(settings.seed, tried)
        tried += 1
        rng = np.random.default_rng(seed)
        observation = sim.reset(seed)
        observations, clean, executed, success = [], [], [], False
        for _ in range(sim.max_steps):
            action = act(observation)
            observations.append(observation)
            clean.append(action)
            executed.append(np.clip(action + rng.normal(0.0, settings.noise, action.shape),
                                    sim.action_low, sim.action_high))
            step = sim.step(executed[-1])
            observation = step.observation
            if step.done:
                success = step.success
                break
        if success:
            kept += 1
            data.observations += observations
            data.committed += list(chunks(np.asarray(executed), settings.lead))
            data.targets += list(chunks(np.asarray(clean), settings.chunk, settings.lead))
    if kept < settings.demos:
        raise ConfigError(f"{settings.task}: the expert succeeded in {kept} of {tried} "
                          f"episodes: too few demonstrations")
    return data


class Fitted:
    """The MLP on [the normalised observation, the committed actions], as the service runs
    it: answers clipped to [-1, 1]."""

    def __init__(self, data: Data, settings: Settings) -> None:
        observations = np.asarray(data.observations)
        self.mean = observations.mean(axis=0)
        std = observations.std(axis=0)
        self.std = np.where(std < 1e-3, 1.0, std)
        inputs = np.concatenate([(observations - self.mean) / self.std,
                                 np.asarray(data.committed)], axis=1)
        self.layers: Layers = train(inputs, np.asarray(data.targets),
                                    [settings.hidden, settings.hidden],
                                    Fit(settings.epochs), settings.seed)

    def act(self, observation: np.ndarray, committed: np.ndarray) -> np.ndarray:
        x = np.concatenate([(observation - self.mean) / self.std, committed])[None]
        return np.clip(forward(self.layers, x.astype(np.float32))[-1][0], -1.0, 1.0)


def rollout(settings: Settings, sim: MetaworldSim, policy: Fitted, seed: int
            ) -> tuple[list[tuple[int, np.ndarray, np.ndarray]], list[np.ndarray]]:
    """One episode through the loop behind `lead` steps: each request (step, observation,
    committed window) and every action played."""
    lead, chunk = settings.lead, settings.chunk
    loop = ControlLoop(ActionQueue(DIM, "skip", "latest"), np.zeros(DIM), request_at=chunk,
                       deadline=lead + 1, hold_steps=settings.rollout_steps,
                       send_committed=True)
    due: dict[int, list[tuple[np.ndarray, int, Origin]]] = {}
    observation = sim.reset(seed)
    requests, played = [], []
    for step in range(settings.rollout_steps):
        for answer in due.pop(step, []):
            loop.deliver(*answer, now=step - 1)
        request = loop.ask(step, observation, now_ns=step)
        if request is not None:
            first, actions = request.committed or (step, np.zeros((0, DIM)))
            window = committed_window((first - step, actions), lead, DIM).reshape(-1)
            requests.append((step, observation.copy(), window))
            answer_ = policy.act(observation, window).reshape(chunk, DIM)
            due.setdefault(step + lead, []).append((answer_, step + lead, Origin(step, step)))
        played.append(loop.act(step).action)
        result = sim.step(played[-1])
        observation = result.observation
        if result.done:
            break
    return requests, played


def label(settings: Settings, sim: MetaworldSim, seed: int, played: list[np.ndarray],
          step: int) -> np.ndarray | None:
    """The expert's chunk from `step + lead` on, after the actions played until then."""
    act = expert(settings.task)
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
    sim, replay = MetaworldSim(settings.task), MetaworldSim(settings.task)
    try:
        data = demonstrations(settings, sim)
        demonstrated = len(data.targets)
        policy = Fitted(data, settings)
        for round_ in range(settings.rounds):
            added = 0
            for episode in range(settings.rollouts):
                seed = ROLLOUT_SEEDS + 1000 * round_ + episode
                requests, played = rollout(settings, sim, policy, seed)
                for step, observation, window in requests:
                    target = label(settings, replay, seed, played, step)
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
    write(folder, settings, policy, {"demonstrated_pairs": demonstrated,
                                     "dagger_pairs": len(data.targets) - demonstrated,
                                     "seconds": round(time.monotonic() - started, 1)})


def write(folder: Path, settings: Settings, policy: Fitted, counts: dict[str, float]) -> None:
    with staging(folder) as staged:
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
    from onnx import TensorProto, helper, numpy_helper

    nodes = [helper.make_node("Concat", ["observation", "committed"], ["x0"], axis=1)]
    inits, x = [], "x0"
    for i, (weights, bias) in enumerate(layers):
        inits += [numpy_helper.from_array(weights, f"w{i}"), numpy_helper.from_array(bias, f"b{i}")]
        last = i == len(layers) - 1
        nodes += [helper.make_node("MatMul", [x, f"w{i}"], [f"m{i}"]),
                  helper.make_node("Add", [f"m{i}", f"b{i}"], ["action" if last else f"d{i}"])]
        if not last:
            nodes.append(helper.make_node("Relu", [f"d{i}"], [f"r{i}"]))
            x = f"r{i}"
    value = helper.make_tensor_value_info
    observations = layers[0][0].shape[0] - settings.lead * DIM
    graph = helper.make_graph(
        nodes, f"committed-{settings.task}",
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
