"""Simulators that `oricf bench control` runs policies in, one module per family.

`open_sim(name)` opens one by name: a pybullet robot (`hopper`, `ant`,
`inverted-double-pendulum`), `reacher-camera` (pybullet's Reacher whose target only its
camera shows), or a metaworld v3 task (`pick-place-v3`, ...). Each is headless, seeded at
`reset(seed)`, and stepped one action at a time (`Step`); a sim's `cameras` name the views
`images()` gives after each step (none but reacher-camera's). The simulators come with the
dev extra (pybullet, metaworld); nothing is imported until one is opened.
"""

from oricf.bench.sims.base import Sim, Step
from oricf.bench.sims.names import open_sim, sim_names

__all__ = ["Sim", "Step", "open_sim", "sim_names"]
