"""A simulator as a ROS 2 robot: `python -m oricf.bench.sim_node --sim NAME`. It steps in
real time at the simulator's rate, publishes each observation (`std_msgs/Float64MultiArray`
on `--state-topic`) and acts on the newest action received (`std_msgs/Float64MultiArray` on
`--action-topic`), as a robot's driver does: an action that has not come by a step's time is
the one before it held (or zeros before any). A simulator with cameras (reacher-camera)
publishes each camera's view of the step too, as `sensor_msgs/Image` (bgr8) on
`--camera-topic` (`{camera}` is the camera's name), just before the state. At the episode's
end it prints one JSON line: the steps, the return, whether and when the task succeeded,
and how many steps had no new action (and a line `{"started": NAME}` when the episode
starts stepping). Used by the control loop's end-to-end test and `oricf bench control
--realtime`.
"""

from __future__ import annotations

import argparse
import json
import logging
import threading
import time
from typing import Any

import numpy as np

from oricf.bench.sims import Sim, open_sim

log = logging.getLogger(__name__)


class SimRobot:
    """The simulator on a ROS node: a thread that steps it on an absolute schedule."""

    def __init__(self, node: Any, sim: Sim, state_topic: str, action_topic: str,
                 camera_topic: str = "/sim/{camera}/image") -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Image
        from std_msgs.msg import Float64MultiArray

        self.sim = sim
        self._message = Float64MultiArray
        self._image = Image
        self._publisher = node.create_publisher(Float64MultiArray, state_topic,
                                                QoSProfile(depth=1))
        self._cameras = {name: node.create_publisher(Image, camera_topic.format(camera=name),
                                                     QoSProfile(depth=1))
                         for name in sim.cameras}
        node.create_subscription(Float64MultiArray, action_topic, self._take,
                                 QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        self._lock = threading.Lock()
        self._action = np.zeros(sim.action_dim)
        self._fresh = False
        self.received = 0

    def _take(self, msg: Any) -> None:
        values = np.asarray(msg.data, np.float64)
        if values.shape != (self.sim.action_dim,) or not np.isfinite(values).all():
            log.warning("action refused: %d values, finite %s", values.size,
                        bool(np.isfinite(values).all()))
            return
        with self._lock:
            self._action, self._fresh = values, True
            self.received += 1

    def _publish(self, observation: np.ndarray) -> None:
        if self._cameras:  # the views first: the state makes the loop's step
            for name, view in self.sim.images().items():
                height, width = view.shape[:2]
                self._cameras[name].publish(self._image(
                    height=height, width=width, encoding="bgr8", step=width * 3,
                    data=np.ascontiguousarray(view).tobytes()))
        self._publisher.publish(self._message(data=observation.astype(float).tolist()))

    def episode(self, seed: int, max_steps: int, wait_s: float,
                stop: threading.Event) -> dict[str, Any]:
        """Runs one episode in real time; its result. Waits up to `wait_s` for the first
        action, publishing the first observation meanwhile."""
        observation = self.sim.reset(seed)
        period = 1.0 / self.sim.rate_hz
        deadline = time.monotonic() + wait_s
        while not self._fresh and time.monotonic() < deadline and not stop.is_set():
            self._publish(observation)
            time.sleep(period)
        steps, total, success_at, stale = 0, 0.0, None, 0
        print(json.dumps({"started": self.sim.name}), flush=True)  # for CPU read around it
        started = time.monotonic()
        while steps < max_steps and not stop.is_set():
            with self._lock:
                action, fresh, self._fresh = self._action, self._fresh, False
            stale += 0 if fresh else 1
            result = self.sim.step(action)
            steps += 1
            total += result.reward
            if result.success and success_at is None:
                success_at = steps
            self._publish(result.observation)
            if result.done:
                break
            stop.wait(max(0.0, started + steps * period - time.monotonic()))
        return {"sim": self.sim.name, "seed": seed, "steps": steps, "return": round(total, 3),
                "success": success_at is not None, "steps_to_success": success_at,
                "steps_without_new_action": stale, "actions_received": self.received}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oricf.bench.sim_node",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--sim", required=True, help="a pybullet robot or metaworld v3 task")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=None)
    parser.add_argument("--state-topic", default="/sim/state")
    parser.add_argument("--action-topic", default="/sim/action")
    parser.add_argument("--camera-topic", default="/sim/{camera}/image",
                        help="where each camera's view goes ({camera}: its name)")
    parser.add_argument("--wait-s", type=float, default=30.0,
                        help="how long to wait for the first action")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from oricf.gateway.ros.dds import use_dds_profile

    use_dds_profile()
    rclpy.init()
    node = Node("oricf_sim")
    sim = open_sim(args.sim)
    robot = SimRobot(node, sim, args.state_topic, args.action_topic, args.camera_topic)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    stop = threading.Event()
    try:
        result = robot.episode(args.seed, args.max_steps or sim.max_steps, args.wait_s, stop)
        print(json.dumps(result), flush=True)
    except KeyboardInterrupt:
        return 130
    finally:
        stop.set()
        executor.shutdown()
        spinner.join(5)
        node.destroy_node()
        rclpy.try_shutdown()
        sim.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
