"""The simulators by name: pybullet's robots, the Reacher with a camera, and metaworld's v3
tasks."""

from __future__ import annotations

from oricf.bench.sims import metaworld, pybullet, reacher_camera
from oricf.bench.sims.base import Sim
from oricf.errors import ConfigError


def sim_names() -> list[str]:
    """Every name open_sim takes (the metaworld tasks when metaworld is installed)."""
    return [*pybullet.ROBOTS, reacher_camera.NAME, *metaworld.task_names()]


def open_sim(name: str) -> Sim:
    """The simulator `name`: a pybullet robot, reacher-camera, or a metaworld v3 task."""
    if name in pybullet.ROBOTS:
        return pybullet.PybulletSim(name)
    if name == reacher_camera.NAME:
        return reacher_camera.ReacherCameraSim()
    if name in metaworld.task_names():
        return metaworld.MetaworldSim(name)
    raise ConfigError(f"no simulator {name!r}: the pybullet robots are "
                      f"{', '.join(pybullet.ROBOTS)}, with a camera {reacher_camera.NAME}; "
                      f"the metaworld v3 tasks are "
                      f"{', '.join(metaworld.task_names()) or '(metaworld is not installed)'}")
