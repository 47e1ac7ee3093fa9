"""A chunk policy that sees, for `reacher-camera`, behaviour-cloned from its scripted expert.

    python -m oricf.bench.train_camera_policy [--demos 400] [--chunk 8] [--seed 0]
        [--epochs 150] [--noise 0.1]

The expert knows where the target is; the policy is given only what a robot would have:
the arm's joints (the state) and the top camera's image. It records the expert's seeded
demonstrations (the executed actions with Gaussian noise, the labels clean: DART), each
image made the model's input by the framework's own `to_tensor` as the declaration says
(CAMERA), fits `oricf.bench.camera_net` in numpy (keypoints found in the image, then an
MLP on [state, keypoints] -> the next `chunk` actions), and writes it as a declared policy
with two inputs: `policy.onnx` (`state` [batch, 6], `image` [batch, 3, 32, 32] RGB in 0-1
-> `action` [batch, chunk x 2]) and `policy.yaml` (`task.images` declaring the camera),
with `training.json`, in `<model store root>/trained/<key>/`, key a hash of the settings
and pybullet's version. A second run with the same arguments trains nothing.

Demonstrations are reset with seeds from 1,000,000 on (chunk_demos.demo_seed), so an
evaluation on lower seeds is on unseen episodes.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.metadata
import json
import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from oricf.bench import camera_net
from oricf.bench.chunk_demos import MIN_STD, chunks, successful
from oricf.bench.chunk_mlp import Fit
from oricf.bench.entry import need
from oricf.bench.sims.reacher_camera import CAMERA, CAMERA_SIZE, NAME, ReacherCameraSim, expert
from oricf.bench.train_chunk_policy import Trained, yaml_list
from oricf.files import staged_folder
from oricf.models.image import to_tensor
from oricf.models.policy_task import CameraInput
from oricf.store import default_root, sha256_of

log = logging.getLogger(__name__)

FORMAT = 1  # bump when what a cached policy holds changes
SCALE = 1 / 255
# The camera as the policy's declaration has it, and as its demonstrations are prepared.
CAMERA_INPUT = CameraInput(name=CAMERA, input="image", size=(CAMERA_SIZE, CAMERA_SIZE),
                           resize="stretch", color="rgb", scale=SCALE)


@dataclass(frozen=True)
class Settings:
    demos: int = 400
    chunk: int = 8
    seed: int = 0
    epochs: int = 150
    joint_epochs: int = 10      # of those, the first with the keypoints' filters fitted too
    noise: float = 0.1
    hidden: int = 128
    keypoints: int = 8
    batch: int = 256
    lr: float = 3e-3


@dataclass(frozen=True)
class Demos:
    states: np.ndarray      # [steps, state]
    images: np.ndarray      # [steps, 3, pixels]: the model's input, flattened per plane
    targets: np.ndarray     # [steps, chunk x dim]

    def normalisation(self) -> tuple[np.ndarray, np.ndarray]:
        std = self.states.std(axis=0)
        return self.states.mean(axis=0), np.where(std < MIN_STD, 1.0, std)


def cache_key(settings: Settings) -> str:
    need("pybullet", "dev", f"the policy for {NAME}")
    text = json.dumps({**asdict(settings), "task": NAME, "format": FORMAT,
                       "pybullet": importlib.metadata.version("pybullet")}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def trained_policy(*, root: Path | None = None, **settings: int | float) -> Path:
    """The declaration (policy.yaml) of the camera policy with these settings (Settings'
    fields), trained and cached under the model store's root when absent."""
    return train_or_find(Settings(**settings), root).declaration  # type: ignore[arg-type]


def image_input(image: np.ndarray) -> np.ndarray:
    """[3, pixels]: a BGR camera image as the policy's model gets it."""
    tensor, _ = to_tensor(image, CAMERA_INPUT, (CAMERA_SIZE, CAMERA_SIZE))
    return tensor.reshape(3, -1)


def episode(sim: ReacherCameraSim, act: Callable[[np.ndarray], np.ndarray], seed: int,
            noise: float) -> tuple[Demos, bool]:
    """One demonstration (its targets the clean actions, one per step) and its success."""
    rng = np.random.default_rng(seed)
    state = sim.reset(seed)
    states, images, actions = [], [], []
    while True:
        clean = act(state)
        states.append(state)
        images.append(image_input(sim.images()[CAMERA]))
        actions.append(clean)
        step = sim.step(clean + rng.normal(0.0, noise, clean.shape))
        state = step.observation
        if step.done:
            return Demos(np.asarray(states), np.asarray(images), np.asarray(actions)), \
                step.success


def collect(settings: Settings) -> Demos:
    """`settings.demos` successful episodes of the expert (at most 2x as many tried)."""
    sim = ReacherCameraSim()
    act = expert(sim)
    try:
        kept = [Demos(demo.states, demo.images, chunks(demo.targets, settings.chunk))
                for demo in successful(
                    lambda seed: episode(sim, act, seed, settings.noise), settings.demos,
                    settings.seed, 2, NAME, settings.noise)]
    finally:
        sim.close()
    return Demos(*(np.concatenate([getattr(d, name) for d in kept])
                   for name in ("states", "images", "targets")))


def train_or_find(settings: Settings, root: Path | None = None) -> Trained:
    folder = (root or default_root()) / "trained" / cache_key(settings)
    declaration = folder / "policy.yaml"
    if declaration.is_file():
        log.info("%s: cached in %s", NAME, folder)
        return Trained(declaration, trained=False)
    started = time.monotonic()
    demos = collect(settings)
    collected = time.monotonic()
    mean, std = demos.normalisation()
    net = camera_net.train((demos.states - mean) / std, demos.images, demos.targets,
                           [settings.hidden, settings.hidden], settings.keypoints,
                           Fit(settings.epochs, settings.batch, settings.lr), settings.seed,
                           (CAMERA_SIZE, CAMERA_SIZE), settings.joint_epochs)
    done = time.monotonic()
    log.info("%s: %d demonstrations (%d steps) in %.1f s, trained in %.1f s", NAME,
             settings.demos, len(demos.states), collected - started, done - collected)
    with staged_folder(folder) as staged:
        model = staged / "policy.onnx"
        model.write_bytes(camera_net.to_onnx(net, demos.states.shape[1],
                                             (CAMERA_SIZE, CAMERA_SIZE), f"bc-{NAME}"))
        (staged / "policy.yaml").write_text(declaration_text(settings, folder.name, model,
                                                             mean, std))
        (staged / "training.json").write_text(json.dumps(
            {**asdict(settings), "steps": len(demos.states),
             "collect_s": round(collected - started, 2), "train_s": round(done - collected, 2)},
            indent=1))
    return Trained(declaration, trained=True)


def declaration_text(settings: Settings, key: str, model: Path, mean: np.ndarray,
                     std: np.ndarray) -> str:
    camera = CAMERA_INPUT
    return (
        f"# A chunk policy that sees, behaviour-cloned from {NAME}'s scripted expert\n"
        f"# (python -m oricf.bench.train_camera_policy; training.json: its settings).\n"
        f"name: bc-{NAME}-{key[:8]}\n"
        f'description: "{NAME}: keypoints of the top camera and the arm\'s joints -> '
        f'{settings.chunk} actions, cloned from {settings.demos} expert demonstrations"\n'
        f"license: MIT\n"
        f"weights: {{path: ./{model.name}, sha256: {sha256_of(model)}}}\n"
        f"backend: {{engine: onnxruntime, threads: 1}}\n"
        f"task:\n  kind: policy\n"
        f"  state:\n    input: state\n    size: {mean.size}\n"
        f"    mean: {yaml_list(mean)}\n    std: {yaml_list(std)}\n"
        f"  images:\n"
        f"    - {{name: {camera.name}, input: {camera.input}, size: {list(camera.size or ())}, "
        f"resize: {camera.resize}, color: {camera.color}, scale: {camera.scale!r}}}\n"
        f"  action: {{output: action, dim: 2, low: -1.0, high: 1.0}}\n"
        f"  chunk: {settings.chunk}\n  rate_hz: {ReacherCameraSim.rate_hz:.9g}\n")


def main(argv: list[str] | None = None) -> int:
    defaults = Settings()
    parser = argparse.ArgumentParser(prog="python -m oricf.bench.train_camera_policy",
                                     description=__doc__.split("\n\n")[0])
    for name in ("demos", "chunk", "seed", "epochs"):
        parser.add_argument(f"--{name}", type=int, default=getattr(defaults, name))
    parser.add_argument("--noise", type=float, default=defaults.noise,
                        help="std of the noise added to the executed actions (0: none)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    result = train_or_find(Settings(demos=args.demos, chunk=args.chunk, seed=args.seed,
                                    epochs=args.epochs, noise=args.noise))
    print(f"{result.declaration} ({'trained' if result.trained else 'cached'})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
