"""`oricf bench control --realtime`: the same policies in real time over ROS 2, milliseconds
through the delay relay instead of simulated steps. Per task and round trip: the policy
service (`oricf serve policy`) behind the delay relay (half the round trip each way; none at
0 ms, the onboard reference), the gateway's control loop in its own process (`oricf gateway`
with a `control:` input, on rclpy's EventsExecutor unless told otherwise), and each episode
the simulator as a ROS 2 robot (`python -m oricf.bench.sim_node`) in real time at its rate.
The figures are the episodes' (success or return, steps) and the gateway's own: its
/metrics (action age in steps, empty ticks, chunks switched) and the robot side's CPU time
per step while an episode steps: the gateway's process (observation, call, merging,
publishing, with ROS), and the policy service's too when it runs onboard (0 ms). Unlike
simulated time, these move with the machine's load: quote medians of repeated runs.
"""

from __future__ import annotations

import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from oricf.bench.common import stop
from oricf.bench.control_report import Row
from oricf.bench.control_run import delay_steps, setting
from oricf.bench.cpusets import process_cpu_seconds
from oricf.bench.link import oricf
from oricf.bench.relay import DelayRelay
from oricf.launch.health import free_port, wait_serving
from oricf.models.declaration import load_declaration
from oricf.models.policy_task import PolicyTask


def control_input(rate_hz: float, state_size: int, action_dim: int, chunk: int,
                  cameras: tuple[str, ...] = (), mode: str = "edge-latest") -> dict[str, Any]:
    """The loop's settings as `oricf bench control` runs them delay-aware, ticked by the
    robot's state (each state a step, its action out as soon as it is known), set for `mode`
    as the simulated loop is (control_run.setting: when the next chunk is asked for, how
    late actions and chunks are merged, whether the actions committed go with a request).
    A policy's cameras: the simulator's views (bench/sim_node.py)."""
    loop = setting(mode, 0, chunk)
    return {"rate_hz": rate_hz, "tick": "state", "action_dim": action_dim, "max_age_ms": 200,
            "state": [{"topic": "/sim/state", "type": "std_msgs/Float64MultiArray",
                       "size": state_size}],
            "images": [{"name": name, "topic": f"/sim/{name}/image"} for name in cameras],
            "late": loop.late, "merge": loop.merge, "send_committed": loop.send_committed,
            # The last action held while an answer is on its way, as in simulated time,
            # for half a second at most (then the safe action, zeros).
            "request_at": loop.request_at, "hold_steps": max(2, int(rate_hz / 2)),
            "deadline_steps": max(8, 2 * chunk),
            "target": {"topic": "/sim/action", "bounds": [[-1, 1]] * action_dim,
                       "deadman_ms": 250}}


def scrape(port: int) -> dict[str, float]:
    """The gateway's control metrics for its one route (samples by name and bucket)."""
    import urllib.request

    from prometheus_client.parser import text_string_to_metric_families

    text = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10).read()
    samples: dict[str, float] = {}
    for family in text_string_to_metric_families(text.decode()):
        for sample in family.samples:
            if sample.name.startswith("oricf_gateway_control_"):
                label = sample.labels.get("le") or sample.labels.get("work")
                samples[sample.name + (f"[{label}]" if label else "")] = sample.value
    return samples


def loop_cpu_us(samples: dict[str, float], work: str, per: str = "ticks") -> float | None:
    """The CPU of the loop's own `work` (tick or request) as the gateway measured it on the
    loop's threads, in microseconds per tick (or per request)."""
    count = samples.get(f"oricf_gateway_control_{per}_total", 0.0)
    cpu_s = samples.get(f"oricf_gateway_control_cpu_seconds_total[{work}]")
    return None if cpu_s is None or not count else cpu_s * 1e6 / count


def age_percentile(samples: dict[str, float], q: float) -> float | None:
    """The smallest bucket bound of the action-age histogram (steps) holding q% of ages."""
    name = "oricf_gateway_control_action_age_steps_bucket"
    buckets = sorted((float(key[len(name) + 1:-1]), value) for key, value in samples.items()
                     if key.startswith(name + "["))
    total = buckets[-1][1] if buckets else 0
    return next((bound for bound, count in buckets if count >= total * q / 100), None) \
        if total else None


def wait_ready(port: int, gateway: subprocess.Popen[bytes], timeout: float = 120) -> float:
    """Once the gateway serves its metrics (its loop made): its ticks so far."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if gateway.poll() is not None:
            raise RuntimeError(f"the gateway exited with {gateway.returncode}")
        try:
            samples = scrape(port)
        except OSError:
            samples = {}
        if "oricf_gateway_control_ticks_total" in samples:
            return samples["oricf_gateway_control_ticks_total"]
        time.sleep(0.2)
    raise RuntimeError("the gateway did not start")


def private_domain() -> dict[str, str]:
    """This environment on a DDS domain of its own, discovery on this machine only, so the
    bench's robot and gateway see no one else's /sim topics."""
    from oricf.gateway.ros.dds import dds_profile

    return {**os.environ, "ROS_DOMAIN_ID": str(random.randint(101, 200)),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile())}


@dataclass(frozen=True)
class Plan:
    """A policy run in real time in one mode (edge-latest, or a mode whose policy is
    trained for a round trip) at some round trips; edge-latest's also onboard (0 ms)."""

    mode: str
    declaration: Path
    delays_ms: tuple[float, ...]


class RealtimeTask:
    """One policy's service, run once for all its round trips."""

    def __init__(self, task: str, declaration: Path, folder: Path,
                 max_steps: int | None = None, mode: str = "edge-latest") -> None:
        self.task = task
        self.mode = mode
        self.max_steps = max_steps
        policy = load_declaration(declaration).task
        assert isinstance(policy, PolicyTask), declaration
        self.settings = (policy.rate_hz, policy.state.size, policy.action.dim, policy.chunk)
        self.cameras = tuple(camera.name for camera in policy.images)
        self.port = free_port()
        config = folder / f"policy-{self.port}.yaml"
        config.write_text(yaml.safe_dump({"server": {"listen": f"127.0.0.1:{self.port}"},
                                          "model": str(declaration)}))
        self.service = subprocess.Popen(oricf("serve", "policy", "--config", str(config)),
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wait_serving(f"127.0.0.1:{self.port}", timeout=120, process=self.service)
        self.folder = folder

    def close(self) -> None:
        stop(self.service)

    def row(self, delay_ms: float, seeds: list[int], metaworld: bool,
            executor: str = "events") -> Row:
        relay = DelayRelay(("127.0.0.1", self.port), delay_ms / 2000) if delay_ms else None
        address = relay.address if relay else f"127.0.0.1:{self.port}"
        metrics = free_port()
        pipeline = self.folder / f"control-{self.port}-{delay_ms:g}.yaml"
        pipeline.write_text(yaml.safe_dump({
            "metrics": {"listen": f"127.0.0.1:{metrics}"},
            "executor": executor,
            "endpoints": {"policy": {"address": address, "deadline_ms": 2000}},
            "routes": {"policy": {"input": {"control": control_input(
                *self.settings, self.cameras, self.mode if delay_ms else "onboard")},
                                  "call": {"method": "Act", "service": "policy"}}}}))
        env = private_domain()
        gateway = subprocess.Popen(oricf("gateway", "--config", str(pipeline)), env=env,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # The robot's CPU: the gateway's, and the policy service's where it is onboard.
        robot = [gateway.pid] if delay_ms else [gateway.pid, self.service.pid]
        try:
            wait_ready(metrics, gateway)
            episodes = [self._episode(seed, env, robot) for seed in seeds]
            samples = scrape(metrics)
        finally:
            stop(gateway)
            if relay is not None:
                relay.close()
        cpu = sum(cpu for _, cpu in episodes)
        ticks = sum(result["steps"] for result, _ in episodes)
        row = self._summary(delay_ms, [r for r, _ in episodes], samples, cpu, ticks, metaworld)
        row.executor = executor
        return row

    def _episode(self, seed: int, env: dict[str, str], robot: list[int]
                 ) -> tuple[dict[str, Any], float]:
        """One episode's result, and the robot's CPU seconds while it stepped."""
        argv = [sys.executable, "-m", "oricf.bench.sim_node", "--sim", self.task, "--seed",
                str(seed), "--wait-s", "60",
                *(["--max-steps", str(self.max_steps)] if self.max_steps else [])]
        with subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) as sim:
            assert sim.stdout is not None
            before = 0.0
            lines = []
            for line in sim.stdout:
                if line.startswith('{"started"'):
                    before = sum(process_cpu_seconds(pid) for pid in robot)
                lines.append(line)
            cpu = sum(process_cpu_seconds(pid) for pid in robot) - before
            errors = sim.stderr.read() if sim.stderr else ""
        if sim.returncode != 0 or not lines:
            raise RuntimeError(f"sim_node {self.task} seed {seed}: {errors[-2000:]}")
        result: dict[str, Any] = json.loads(lines[-1])
        return result, cpu

    def _summary(self, delay_ms: float, results: list[dict[str, Any]],
                 samples: dict[str, float], cpu_s: float, ticks: float,
                 metaworld: bool) -> Row:
        successes = [r for r in results if r["success"]]
        steps = [r["steps_to_success"] if metaworld else r["steps"]
                 for r in (successes if metaworld else results)]
        count = len(results)
        switches = samples.get("oricf_gateway_control_switch_jump_count", 0.0)
        jump_sum = samples.get("oricf_gateway_control_switch_jump_sum", 0.0)
        return Row(
            self.task, realtime_mode(self.mode, delay_ms), delay_ms,
            delay_steps(delay_ms, self.settings[0]), count,
            len(successes) / count if metaworld else None,
            statistics.fmean(r["return"] for r in results),
            statistics.fmean(steps) if steps else None,
            age_percentile(samples, 50), age_percentile(samples, 99),
            # Between episodes the robot publishes nothing: those ticks are not the loop's.
            max(0.0, samples.get("oricf_gateway_control_empty_ticks_total", 0.0)
                - samples.get("oricf_gateway_control_missing_state_total", 0.0)) / count,
            samples.get("oricf_gateway_control_late_actions_total", 0.0) / count,
            switches / count, jump_sum / switches if switches else None,
            cpu_s * 1e6 / ticks if ticks else 0.0,
            loop_cpu_us_per_tick=_sum(loop_cpu_us(samples, "tick"),
                                      loop_cpu_us(samples, "request")),
            loop_tick_cpu_us=loop_cpu_us(samples, "tick"),
            request_cpu_us=loop_cpu_us(samples, "request", per="requests"))


def _sum(*values: float | None) -> float | None:
    return None if None in values else sum(v or 0.0 for v in values)


def realtime_mode(mode: str, delay_ms: float) -> str:
    """A real-time row's mode: realtime-onboard at no delay, realtime-edge for edge-latest
    (the loop's defaults), else realtime-<mode>."""
    if delay_ms == 0:
        return "realtime-onboard"
    return "realtime-edge" if mode == "edge-latest" else f"realtime-{mode}"


def realtime_rows(task: str, plans: list[Plan], episodes: int, seed: int, metaworld: bool,
                  max_steps: int | None = None,
                  executors: tuple[str, ...] = ("events",)) -> list[Row]:
    """The task's rows in real time, each plan's policy served once: the onboard reference
    (0 ms, edge-latest's policy) and each round trip, with the gateway on each ROS executor
    (PipelineConfig.executor) in turn."""
    seeds = [seed + i for i in range(episodes)]
    rows = []
    with tempfile.TemporaryDirectory(prefix="oricf-bench-control-") as folder:
        for plan in plans:
            runner = RealtimeTask(task, plan.declaration, Path(folder), max_steps, plan.mode)
            delays = sorted({0.0, *plan.delays_ms} if plan.mode == "edge-latest"
                            else set(plan.delays_ms))
            try:
                rows += [runner.row(ms, seeds, metaworld, executor)
                         for ms in delays for executor in executors]
            finally:
                runner.close()
    return rows
