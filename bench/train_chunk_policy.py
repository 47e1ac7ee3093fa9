"""A chunk policy for a metaworld v3 task, behaviour-cloned from its scripted expert.

    python -m oricf.bench.train_chunk_policy --task pick-place-v3 [--demos 60] [--chunk 16]
        [--seed 0] [--epochs N] [--noise SIGMA] [--lead STEPS]

Collects seeded expert demonstrations, fits an MLP (observation -> the next `chunk`
actions) in numpy, and writes it as a declared policy: `policy.onnx` (MatMul/Add/Relu, as
oricf.models.mlp_source writes pybullet's) and `policy.yaml` beside it (task kind policy,
the demonstrations' mean and std, chunk, 80 Hz) in `<model store root>/trained/<key>/`,
key a hash of the task, the settings, the seed and metaworld's version. A second run with
the same arguments finds them and trains nothing. Only the benchmark trains: ORICF itself
serves what this writes like any declared model.

DART-style noise: the executed actions are the expert's plus Gaussian noise (`--noise`),
while the recorded labels stay the expert's clean actions, so the demonstrations cover the
states a slightly late or imperfect policy drifts into and show how to recover from them.

With `--lead L` the policy acts ahead of a round trip of L steps: the targets for the
observation of step t are the expert's actions for t+L .. t+L+chunk-1, and the declaration
says `lead_steps: L`, so the policy service answers chunks that start L steps after the
observation (the step they arrive at, behind that round trip).

Demonstration episodes are reset with seeds from 1,000,000 on (chunk_demos.demo_seed):
an evaluation on seeds below that is on episodes the policy has not seen.
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

from oricf.bench.chunk_demos import Demos, collect
from oricf.bench.chunk_mlp import Fit, Layers, train
from oricf.files import staged_folder
from oricf.models.mlp_source import LAYERS, to_onnx
from oricf.store import default_root, sha256_of

log = logging.getLogger(__name__)

FORMAT = 2  # bump when what a cached policy holds changes


@dataclass(frozen=True)
class Settings:
    task: str = "pick-place-v3"
    demos: int = 60
    chunk: int = 16
    seed: int = 0
    epochs: int = 300
    noise: float = 0.1
    hidden: int = 256
    batch: int = 256
    lr: float = 1e-3
    lead: int = 0  # steps after the observation the chunk's first action is for


@dataclass(frozen=True)
class Trained:
    """A trained policy's declaration, and whether this call trained it (False: cached)."""

    declaration: Path
    trained: bool


def cache_key(settings: Settings) -> str:
    version = importlib.metadata.version("metaworld")
    text = json.dumps({**asdict(settings), "metaworld": version, "format": FORMAT},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def trained_policy(task: str = "pick-place-v3", *, root: Path | None = None,
                   **settings: int | float) -> Path:
    """The declaration (policy.yaml) of the chunk policy for `task` with these settings
    (Settings' fields), trained and cached under the model store's root when absent."""
    return train_or_find(Settings(task=task, **settings), root).declaration  # type: ignore[arg-type]


def train_or_find(settings: Settings, root: Path | None = None) -> Trained:
    folder = (root or default_root()) / "trained" / cache_key(settings)
    declaration = folder / "policy.yaml"
    if declaration.is_file():
        log.info("%s: cached in %s", settings.task, folder)
        return Trained(declaration, trained=False)
    started = time.monotonic()
    demos = collect(settings.task, settings.demos, settings.seed, settings.noise, settings.chunk,
                    settings.lead)
    collected = time.monotonic()
    mean, std = demos.normalisation()
    layers = train((demos.observations - mean) / std, demos.targets,
                   [settings.hidden, settings.hidden],
                   Fit(settings.epochs, settings.batch, settings.lr), settings.seed)
    done = time.monotonic()
    log.info("%s: %d demonstrations (%d steps) in %.1f s, trained in %.1f s", settings.task,
             settings.demos, len(demos.observations), collected - started, done - collected)
    write(folder, settings, demos, layers, {"collect_s": round(collected - started, 2),
                                           "train_s": round(done - collected, 2)})
    return Trained(declaration, trained=True)


def yaml_list(array: np.ndarray) -> str:
    """`[v, ...]`: the values of a 1-D array in a YAML flow list, 9 significant digits."""
    return "[" + ", ".join(f"{float(v):.9g}" for v in array) + "]"


def write(folder: Path, settings: Settings, demos: Demos, layers: Layers,
          timings: dict[str, float]) -> None:
    """policy.onnx, policy.yaml and training.json, made in a temporary folder and moved
    into place whole, so a reader never sees half of them."""
    with staged_folder(folder) as staged:
        arrays = {name: array for (w_name, b_name), (w, b) in zip(LAYERS, layers, strict=True)
                  for name, array in ((w_name, w), (b_name, b))}
        model = staged / "policy.onnx"
        model.write_bytes(to_onnx(arrays, (layers[0][0].shape[0], layers[-1][0].shape[1]),
                                  f"bc-{settings.task}"))
        mean, std = demos.normalisation()
        (staged / "policy.yaml").write_text(declaration_text(settings, folder.name, model,
                                                             mean, std))
        (staged / "training.json").write_text(json.dumps(
            {**asdict(settings), "steps": len(demos.observations), **timings}, indent=1))


def declaration_text(settings: Settings, key: str, model: Path, mean: np.ndarray,
                     std: np.ndarray) -> str:
    return (
        f"# A chunk policy behaviour-cloned from metaworld's scripted expert for "
        f"{settings.task}\n# (python -m oricf.bench.train_chunk_policy; training.json: "
        f"its settings).\n"
        f"name: bc-{settings.task}-{key[:8]}\n"
        f'description: "{settings.task}: an MLP, observation -> {settings.chunk} actions from '
        f'{settings.lead} steps on, cloned from {settings.demos} expert demonstrations"\n'
        f"license: MIT\n"
        f"weights: {{path: ./{model.name}, sha256: {sha256_of(model)}}}\n"
        f"backend: {{engine: onnxruntime, threads: 1}}\n"
        f"task:\n  kind: policy\n"
        f"  state:\n    input: observation\n    size: {mean.size}\n"
        f"    mean: {yaml_list(mean)}\n    std: {yaml_list(std)}\n"
        f"  action: {{output: action, dim: 4, low: -1.0, high: 1.0}}\n"
        f"  chunk: {settings.chunk}\n  rate_hz: 80\n  lead_steps: {settings.lead}\n")


def main(argv: list[str] | None = None) -> int:
    defaults = Settings()
    parser = argparse.ArgumentParser(prog="python -m oricf.bench.train_chunk_policy",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default=defaults.task, help="a metaworld v3 task")
    parser.add_argument("--demos", type=int, default=defaults.demos)
    parser.add_argument("--chunk", type=int, default=defaults.chunk)
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--epochs", type=int, default=defaults.epochs)
    parser.add_argument("--noise", type=float, default=defaults.noise,
                        help="std of the noise added to the executed actions (0: none)")
    parser.add_argument("--lead", type=int, default=defaults.lead,
                        help="steps after the observation the chunk's first action is for")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    result = train_or_find(Settings(task=args.task, demos=args.demos, chunk=args.chunk,
                                    seed=args.seed, epochs=args.epochs, noise=args.noise,
                                    lead=args.lead))
    print(f"{result.declaration} ({'trained' if result.trained else 'cached'})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
