"""Tables of `oricf bench gateway`: latency, robot-side CPU and estimated energy per frame.

Power model (printed with the figures; both constants are flags):
    energy per frame = robot CPU-seconds x watts per busy core
                       + bytes over the radio x 8 x joules per bit (offloaded only)
The radio bytes are the Detect request (the image as the endpoint's transport sends it) and
the response, both at the same cost per bit; onboard calls never leave the robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from oricf.bench.common import print_table


@dataclass
class PowerModel:
    watts_per_core: float
    nj_per_bit: float

    def joules(self, cpu_s: float, radio_bytes: float = 0.0) -> float:
        return cpu_s * self.watts_per_core + radio_bytes * 8 * self.nj_per_bit * 1e-9

    def describe(self) -> str:
        return (f"energy = CPU-seconds x {self.watts_per_core:g} W per busy core + radio bytes "
                f"(request + response) x 8 x {self.nj_per_bit:g} nJ/bit when offloaded")


@dataclass
class InputResult:
    """Everything measured for one kind of camera input (raw bgr8 or JPEG)."""

    kind: str
    through_ms: float = 0.0
    direct_ms: float = 0.0
    lost: int = 0
    cpu: dict[str, float] = field(default_factory=dict)  # phase -> CPU s per frame
    request_bytes: dict[str, float] = field(default_factory=dict)  # transport -> median
    response_bytes: float = 0.0
    # The offloaded (edge) gateway's thread wake-ups per frame, by thread name, most first.
    edge_wakeups: dict[str, float] = field(default_factory=dict)
    post_us: dict[str, float] = field(default_factory=dict)  # post steps -> median us/frame
    view_images_per_s: float = 0.0  # images the live view's viewer received, its CPU phase


def latency_table(result: InputResult, frames: int) -> None:
    print_table(f"Latency per frame, {result.kind} input, median of {frames} (interleaved; "
                f"{result.lost} frames without a count)", ["path", "median ms"],
                [["publish -> /human_counter (gateway)", f"{result.through_ms:.1f}"],
                 [f"direct Detect call ({result.kind})", f"{result.direct_ms:.1f}"],
                 ["added by the gateway", f"{result.through_ms - result.direct_ms:.1f}"]])


def cost_table(result: InputResult, power: PowerModel, fps: float, frames: tuple[int, int],
               threads: tuple[int, int]) -> None:
    """frames: per phase, and the number of parts whose median is shown; threads: the
    shipped detector's thread count and the other one measured."""
    cpu = result.cpu
    shipped, other = threads
    onboard = {f"{shipped} thr (shipped)": cpu["gw raw 1"] + cpu["det shipped"],
               f"{other} thr": cpu["gw raw 2"] + cpu["det other"]}
    rows: list[list[str]] = []
    for name, value in onboard.items():
        rows.append([f"onboard, detector {name}", "gateway + detector",
                     f"{value * 1e3:.2f}", "-", "-", f"{power.joules(value) * 1e3:.1f}", "0",
                     "-", "-"])
    shared = cpu["gw shm"] + cpu["det shm"]
    rows.append([f"onboard, detector {shipped} thr, shared memory", "gateway + detector",
                 f"{shared * 1e3:.2f}",
                 *(f"{(1 - shared / on) * 100:.1f}%" for on in onboard.values()),
                 f"{power.joules(shared) * 1e3:.1f}", "0", "-", "-"])
    offloaded = {"raw": (cpu["gw raw 1"] + cpu["gw raw 2"]) / 2, "jpeg": cpu["gw jpeg"],
                 "jpeg, Infer decoded": cpu["gw infer decoded"]}
    for transport, value in offloaded.items():
        # Infer's request carries the same JPEG; its reply is about the size of Detect's.
        radio = result.request_bytes[transport.split(",")[0]] + result.response_bytes
        energy = power.joules(value, radio)
        cuts = [f"{(1 - value / on) * 100:.1f}%" for on in onboard.values()]
        energy_cuts = [f"{(1 - energy / power.joules(on)) * 100:.1f}%"
                       for on in onboard.values()]
        rows.append([f"offloaded, transport {transport}", "gateway", f"{value * 1e3:.2f}",
                     *cuts, f"{energy * 1e3:.1f}", f"{radio / 1e3:.1f}", *energy_cuts])
    print_table(f"Robot side per processed frame, {result.kind} input at {fps:g} fps, "
                f"{frames[0]} frames per phase, median of {frames[1]} parts (detector alone: "
                f"{cpu['det shipped'] * 1e3:.1f} ms CPU with "
                f"{shipped} thread(s), {cpu['det other'] * 1e3:.1f} ms with {other})",
                ["placement", "robot processes", "CPU ms", *(f"CPU cut vs {k}" for k in onboard),
                 "energy mJ", "radio kB", *(f"energy cut vs {k}" for k in onboard)], rows)


def wakeup_note(result: InputResult, wakeup_s: float) -> None:
    """How much of the offloaded gateway's CPU is the price of waking its threads."""
    total = sum(result.edge_wakeups.values())
    share = total * wakeup_s / result.cpu["gw jpeg"]
    threads = ", ".join(f"{name or '?'} {count:.1f}"
                        for name, count in result.edge_wakeups.items() if count >= 0.1)
    print(f"Offloaded gateway (transport jpeg): {total:.1f} thread wake-ups per frame "
          f"({threads}); one costs {wakeup_s * 1e6:.0f} us of CPU on this machine (a thread "
          f"blocked on a socket, woken at the camera rate), about {share:.0%} of its CPU per "
          f"frame.")
