"""`reacher-camera`: pybullet's two-joint Reacher whose target only a camera shows.

ReacherBulletEnv (`pybullet==3.2.7`, the dev extra) with a state of the arm's own joints
only (cos and sin of the shoulder's and the elbow's angle, then their velocities, scaled
as the env scales them): the target's position, and the fingertip-to-target vector that
gives it away, are left out, so a policy has to find the target in `images()["top"]`, a
top-down view rendered with pybullet's software renderer (no display, no GPU) at
CAMERA_SIZE pixels a side. The camera sees a red disc (the target, drawn above the arm so
the arm never hides it), a dark arm with a green fingertip, on a plain grey floor.

`reset(seed)` draws the arm's start from the env's generator and the target anywhere the
fingertip reaches (TARGET_RADII from the base, at least START_DISTANCE_M from the
fingertip's start), both from `seed`. An episode succeeds, and ends, when the fingertip has
stayed within SUCCESS_DISTANCE_M of the target for HOLD_STEPS steps in a row (it stopped
there: a sweeping arm that crosses the target does not count), else it ends after
MAX_STEPS; the reward is the env's (progress towards the target, less the effort).
`expert(sim)` knows the target and reaches it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from oricf.bench.entry import need
from oricf.bench.sims.base import Step, checked_action
from oricf.bench.sims.pybullet import RATE_HZ, gym_stand_in

log = logging.getLogger(__name__)

NAME = "reacher-camera"
CAMERA = "top"
CAMERA_SIZE = 32                  # pixels a side
VIEW_HALF_M = 0.23                # the camera sees [-0.23, 0.23] m each way at the floor
STATE_SIZE = 6                    # cos, sin of both joint angles; both velocities
VELOCITY_SCALE = 0.1              # rad/s in the state, as the env scales them
SUCCESS_DISTANCE_M = 0.03         # fingertip to target: the fingertip (0.01) touches the disc
HOLD_STEPS = 5                    # ... for this many steps in a row: it stopped there
TARGET_RADII = (0.09, 0.19)       # metres from the base; the fingertip reaches 0.21
START_DISTANCE_M = 0.08           # the target at least this far from the fingertip's start
MAX_STEPS = 150                   # 2.5 s at 60.6 Hz
MARKER_RADIUS_M = 0.02            # the target's disc as the camera sees it
MARKER_HEIGHT_M = 0.03            # above the arm (0.02 at most): never hidden by it
UPPER_M, FOREARM_M = 0.1, 0.11   # shoulder to elbow, elbow to fingertip (reacher.xml)
EXPERT_GAIN, EXPERT_DAMPING = 2.0, 0.3  # per rad, per rad/s
FLOOR, ARM, FINGERTIP, TARGET = ((0.85, 0.85, 0.85, 1), (0.1, 0.2, 0.5, 1),
                                 (0.1, 0.6, 0.1, 1), (0.95, 0.05, 0.05, 1))


def _environment() -> Any:
    need("pybullet", "dev", f"the simulator {NAME}")
    gym_stand_in()
    from pybullet_envs.gym_manipulator_envs import ReacherBulletEnv

    return ReacherBulletEnv()


class Camera:
    """A fixed top-down camera over the arm, rendered on the CPU."""

    def __init__(self, client: Any, size: int = CAMERA_SIZE) -> None:
        self._client, self.size = client, size
        height = 1.0
        self._view = client.computeViewMatrix([0, 0, height], [0, 0, 0], [0, 1, 0])
        fov = 2 * math.degrees(math.atan(VIEW_HALF_M / height))
        self._projection = client.computeProjectionMatrixFOV(fov, 1.0, 0.5, 1.5)

    def bgr(self) -> np.ndarray:
        """The view now: BGR uint8, size x size x 3, +x to the right and +y up."""
        _, _, rgba, _, _ = self._client.getCameraImage(
            self.size, self.size, self._view, self._projection,
            renderer=self._client.ER_TINY_RENDERER)
        pixels = np.asarray(rgba, np.uint8).reshape(self.size, self.size, 4)
        return np.ascontiguousarray(pixels[:, :, 2::-1])


class ReacherCameraSim:
    """The Reacher as a Sim with one camera: success within SUCCESS_DISTANCE_M."""

    name = NAME
    rate_hz = RATE_HZ
    state_size = STATE_SIZE
    action_dim = 2
    max_steps = MAX_STEPS
    cameras: tuple[str, ...] = (CAMERA,)

    def __init__(self) -> None:
        self._env = _environment()
        self.action_low, self.action_high = -np.ones(2), np.ones(2)
        self._camera: Camera | None = None
        self._marker = -1
        self._steps = 0
        self._held = 0                  # steps in a row within SUCCESS_DISTANCE_M
        self._over = True

    @property
    def env(self) -> Any:
        """The pybullet_envs environment (its robot knows where the target is)."""
        return self._env

    def reset(self, seed: int) -> np.ndarray:
        self._env.seed(seed)
        self._env.reset()
        if self._camera is None:  # the scene is loaded by the first reset
            self._camera = Camera(self._env._p)
            self._marker = paint(self._env._p, self._env.robot)
        place_target(self._env, np.random.default_rng(seed))
        self._env._p.resetBasePositionAndOrientation(
            self._marker, [*self.target(), MARKER_HEIGHT_M], [0, 0, 0, 1])
        self._steps, self._held, self._over = 0, 0, False
        return self._state()

    def step(self, action: np.ndarray) -> Step:
        values = checked_action(self, action, self._over)
        _, reward, _, _ = self._env.step(values)
        self._steps += 1
        self._held = self._held + 1 if self.distance() <= SUCCESS_DISTANCE_M else 0
        success = self._held >= HOLD_STEPS
        self._over = success or self._steps >= self.max_steps
        return Step(self._state(), float(reward), self._over, success)

    def images(self) -> dict[str, np.ndarray]:
        """The camera's view after the last reset or step, by camera name."""
        if self._camera is None:
            raise RuntimeError(f"{NAME}: reset() before asking for images")
        return {CAMERA: self._camera.bgr()}

    def target(self) -> np.ndarray:
        """The target's x, y in metres (the simulator's truth: not in the state)."""
        return np.asarray(self._env.robot.target.pose().xyz()[:2], np.float64)

    def fingertip(self) -> np.ndarray:
        return np.asarray(self._env.robot.fingertip.pose().xyz()[:2], np.float64)

    def distance(self) -> float:
        return float(np.linalg.norm(self.fingertip() - self.target()))

    def close(self) -> None:
        self._env.close()

    def joints(self) -> tuple[float, float, float, float]:
        """The shoulder's and the elbow's angle (rad) and velocity (rad/s)."""
        robot = self._env.robot
        theta, theta_dot = robot.central_joint.get_state()
        gamma, gamma_dot = robot.elbow_joint.get_state()
        return float(theta), float(gamma), float(theta_dot), float(gamma_dot)

    def _state(self) -> np.ndarray:
        theta, gamma, theta_dot, gamma_dot = self.joints()
        return np.array([math.cos(theta), math.sin(theta), math.cos(gamma), math.sin(gamma),
                         VELOCITY_SCALE * theta_dot, VELOCITY_SCALE * gamma_dot])


def place_target(env: Any, rng: np.random.Generator) -> None:
    """The target somewhere the fingertip reaches, uniform over that ring's area (the env
    draws it in a square, mostly out of reach), and at least START_DISTANCE_M from where
    the fingertip starts, so no episode is won before it begins."""
    robot = env.robot
    tip = np.asarray(robot.fingertip.pose().xyz()[:2])
    low, high = TARGET_RADII
    while True:
        radius = math.sqrt(rng.uniform(low * low, high * high))
        angle = rng.uniform(-math.pi, math.pi)
        target = radius * np.array([math.cos(angle), math.sin(angle)])
        if np.linalg.norm(target - tip) >= START_DISTANCE_M:
            break
    robot.jdict["target_x"].reset_current_position(float(target[0]), 0)
    robot.jdict["target_y"].reset_current_position(float(target[1]), 0)
    robot.calc_state()  # the env's to_target_vec, for its reward


def paint(client: Any, robot: Any) -> int:
    """Plain colours the camera tells apart (pybullet's loader gives every part the same
    green, and the floor a checker), and a disc larger than the target's own small sphere,
    which moves with it: its body id."""
    client.changeVisualShape(0, -1, rgbaColor=FLOOR, textureUniqueId=-1)
    for body in range(1, client.getNumBodies()):
        for shape in client.getVisualShapeData(body):
            client.changeVisualShape(body, shape[1], rgbaColor=FLOOR)
    arm = robot.parts["fingertip"].bodies[robot.parts["fingertip"].bodyIndex]
    for link in (robot.parts["body0"].bodyPartIndex, robot.parts["body1"].bodyPartIndex):
        client.changeVisualShape(arm, link, rgbaColor=ARM)
    client.changeVisualShape(arm, robot.parts["fingertip"].bodyPartIndex, rgbaColor=FINGERTIP)
    target = robot.parts["target"]
    client.changeVisualShape(target.bodies[target.bodyIndex], target.bodyPartIndex,
                             rgbaColor=TARGET)
    disc = client.createVisualShape(client.GEOM_CYLINDER, radius=MARKER_RADIUS_M,
                                    length=0.002, rgbaColor=TARGET)
    return int(client.createMultiBody(baseMass=0, baseVisualShapeIndex=disc))


def expert(sim: ReacherCameraSim, gain: float = EXPERT_GAIN,
           damping: float = EXPERT_DAMPING) -> Callable[[np.ndarray], np.ndarray]:
    """A scripted policy that knows where the target is (the simulator's truth, not the
    state): each step, the joint angles that put the fingertip on the target (of the two
    elbow solutions, the nearer), and a PD torque towards them. Observation -> action."""
    def act(observation: np.ndarray) -> np.ndarray:
        theta, gamma, theta_dot, gamma_dot = sim.joints()
        to_theta, to_gamma = joint_errors(sim.target(), theta, gamma)
        return np.clip([gain * to_theta - damping * theta_dot,
                        gain * to_gamma - damping * gamma_dot], -1.0, 1.0)
    return act


def joint_errors(target: np.ndarray, theta: float, gamma: float) -> tuple[float, float]:
    """How far each joint is from the nearer inverse-kinematics solution for `target`
    (shoulder wrapped to [-pi, pi); the elbow, limited to +-3 rad, is not)."""
    x, y = float(target[0]), float(target[1])
    cos_gamma = (x * x + y * y - UPPER_M ** 2 - FOREARM_M ** 2) / (2 * UPPER_M * FOREARM_M)
    best: tuple[float, float, float] | None = None
    for sign in (1.0, -1.0):
        goal_gamma = sign * math.acos(min(1.0, max(-1.0, cos_gamma)))
        goal_theta = math.atan2(y, x) - math.atan2(FOREARM_M * math.sin(goal_gamma),
                                                   UPPER_M + FOREARM_M * math.cos(goal_gamma))
        d_theta = (goal_theta - theta + math.pi) % (2 * math.pi) - math.pi
        d_gamma = goal_gamma - gamma
        if best is None or abs(d_theta) + abs(d_gamma) < best[0]:
            best = (abs(d_theta) + abs(d_gamma), d_theta, d_gamma)
    assert best is not None
    return best[1], best[2]
