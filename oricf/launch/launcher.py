"""Runs a deployment as local processes: services first, each waited for until SERVING
(grpc.health.v1), remote services checked, then the gateway, pointed at the services started
here (oricf.launch.wiring); supervises them (a crash is reported and restarted if the
deployment says so); stops them all, gateway first."""

from __future__ import annotations

import logging
import socket
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import yaml

from oricf.errors import ConfigError
from oricf.hosts import Address
from oricf.launch import health
from oricf.launch.deployment import Deployment, ProcessPlan, gateway_plan, service_plan
from oricf.launch.process import LineSink, ManagedProcess, describe_exit, restart, wants_restart
from oricf.launch.wiring import wire_gateway
from oricf.tls import ClientTls
from oricf.yamlfile import read_limited

log = logging.getLogger(__name__)

# (message, final) for progress while models load: passing states about once a second
# (final False), lasting events such as "detector SERVING" (final True)
Progress = Callable[[str, bool], None]
POLL_S = 0.25
LOG_WAITING_EVERY_S = 10.0


class LaunchFailed(Exception):
    """A process could not be started, ended for good, or never became SERVING."""


class Stopped(Exception):
    """The stop event was set while starting."""


class Launcher:
    def __init__(self, deployment: Deployment, sink: LineSink,
                 progress: Progress | None = None) -> None:
        self.deployment = deployment
        self.sink = sink
        self.progress = progress or self._log_progress
        self._last_waiting_log = 0.0
        self.services: list[ManagedProcess] = []
        self.gateway: ManagedProcess | None = None
        # name -> (address, TLS) of every remote endpoint to find SERVING first
        self.remote: dict[str, tuple[str, ClientTls | None]] = {}
        self._scratch = tempfile.TemporaryDirectory(prefix="oricf-up-")

    @property
    def processes(self) -> list[ManagedProcess]:
        return [*self.services, *([self.gateway] if self.gateway else [])]

    def plan(self) -> tuple[list[ProcessPlan], ProcessPlan | None]:
        """Every command, with every config validated, before anything starts."""
        plans = [service_plan(name, entry, self.deployment)
                 for name, entry in self.deployment.services.items()]
        if self.deployment.gateway is None:
            return plans, None
        wiring = wire_gateway(self.deployment, {p.name: p.health for p in plans if p.health})
        self.remote = {name: (e.address, e.tls) for name, e in wiring.remote.items()}
        overlay = None
        if wiring.endpoints:
            overlay = Path(self._scratch.name) / "wiring.yaml"
            overlay.write_text(yaml.safe_dump({"endpoints": wiring.endpoints}))
        return plans, gateway_plan(self.deployment, overlay)

    def start(self, stop: threading.Event) -> None:
        """Starts everything; returns once services are SERVING and the gateway runs."""
        service_plans, gateway = self.plan()
        targets = {p.name: (p.health, self.deployment.tls) for p in service_plans if p.health}
        targets.update(self.remote)
        _refuse_unreadable(service_plans, targets)
        _refuse_ports_in_use(service_plans)
        self.services = [ManagedProcess(plan, self.sink) for plan in service_plans]
        for process in self.services:
            process.start()
        self._wait_serving(targets, stop)
        if gateway is not None:
            self.gateway = ManagedProcess(gateway, self.sink)
            self.gateway.start()

    def _wait_serving(self, targets: dict[str, tuple[str, ClientTls | None]],
                      stop: threading.Event) -> None:
        """Polls every target until all say SERVING; reports progress about once a second."""
        start = time.monotonic()
        pending = dict(targets)
        states: dict[str, str] = {}
        last_report = 0.0
        while pending:
            if stop.is_set():
                raise Stopped()
            for name, (address, tls) in list(pending.items()):
                self._check_alive(name)
                states[name] = health.status(address, timeout=1.0, tls=tls)
                if states[name] == "SERVING":
                    del pending[name]
                    self.progress(f"{name} SERVING at {address} "
                                  f"({time.monotonic() - start:.1f} s)", True)
            elapsed = time.monotonic() - start
            if pending and elapsed > self.deployment.startup_timeout_s:
                waiting = ", ".join(f"{n} ({states.get(n, '?')})" for n in pending)
                raise LaunchFailed(f"not SERVING after {elapsed:.0f} s: {waiting}")
            if pending and elapsed - last_report >= 1.0:
                last_report = elapsed
                waiting = ", ".join(f"{n} {states.get(n, '')}".strip() for n in pending)
                self.progress(f"loading models: waiting for {waiting} ({elapsed:.0f} s)", False)
            stop.wait(POLL_S)

    def _log_progress(self, message: str, final: bool) -> None:
        if final or time.monotonic() - self._last_waiting_log >= LOG_WAITING_EVERY_S:
            self._last_waiting_log = time.monotonic()
            log.info("%s", message)

    def _check_alive(self, name: str) -> None:
        """A service that died while loading is restarted if its policy allows, else fatal."""
        process = next((p for p in self.services if p.name == name), None)
        if process is None:
            return
        code = process.poll()
        if code is None:
            return
        if not wants_restart(process, code):
            tail = "\n".join(process.tail)
            raise LaunchFailed(f"{name} ended while starting ({describe_exit(code)}):\n{tail}")
        log.error("%s ended while starting (%s); restarting", name, describe_exit(code))
        restart(process)

    def supervise(self, stop: threading.Event) -> int:
        """Watches the processes until stop is set (returns 0) or one ends for good (1)."""
        while not stop.wait(POLL_S):
            for process in self.processes:
                code = process.poll()
                if code is None:
                    continue
                if not wants_restart(process, code):
                    log.error("%s ended (%s); not restarted: stopping the deployment",
                              process.name, describe_exit(code))
                    return 1
                limit = process.plan.restart.max_restarts
                log.error("%s ended (%s); restart %d of %d", process.name, describe_exit(code),
                          process.restarts + 1, limit)
                restart(process)
        return 0

    def stop(self) -> None:
        """Gateway first (it stops calling the services), then every service in parallel."""
        grace = self.deployment.stop_grace_s
        if self.gateway is not None:
            self._report_stop(self.gateway, self.gateway.stop(grace))
        for process in self.services:
            process.terminate()
        for process in self.services:
            self._report_stop(process, process.stop(grace))
        self._scratch.cleanup()

    @staticmethod
    def _report_stop(process: ManagedProcess, code: int | None) -> None:
        if code is not None:
            log.info("%s stopped (%s)", process.name, describe_exit(code))


def _refuse_unreadable(plans: list[ProcessPlan],
                       targets: dict[str, tuple[str, ClientTls | None]]) -> None:
    """Fails before starting when a certificate, key or token file cannot be read: by a
    service (it would stop at start, again at every restart) or by a health check."""
    files = [(plan.name, path) for plan in plans for path in plan.reads]
    files += [(f"health check of {name}", path) for name, (_, tls) in targets.items() if tls
              for path in (tls.ca, tls.cert, tls.key) if path]
    for user, path in files:
        try:  # read as its user will read it: a FIFO there would hold the launcher for ever
            read_limited(path, "a certificate, key or token file")
        except ConfigError as exc:
            raise LaunchFailed(f"{user}: {exc} (make the certificates and token first: "
                               "docs/security.md)") from None


def _refuse_ports_in_use(plans: list[ProcessPlan]) -> None:
    """Fails before starting when a service's port already answers.

    Otherwise the health check would find the other process SERVING and the deployment
    would run against services it did not start (and cannot stop).
    """
    for plan in plans:
        if not plan.health:
            continue
        address = Address.parse(plan.health)
        try:
            with socket.create_connection((address.host, address.port), timeout=0.5):
                pass
        except OSError:
            continue
        raise LaunchFailed(f"{plan.name}: {plan.health} is already in use by another process "
                           "(another deployment running?); stop it or change the address")
