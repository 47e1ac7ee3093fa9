"""Commands from an agent, through the policy: target listed, content within its type and
bounds (clamped or refused), rate, approval, then sent; a deadman sends the zero command
when a motion target is not renewed in time. Every outcome goes to the audit log.

Approval by MCP elicitation happens in the MCP server, which asks its user before it calls
`send(..., approved=True)`; a target that needs it is refused without. Over the control API
only a request carrying a token of `control.approvers` (the attached MCP server) can say
so; any other client's `approved` is dropped before it reaches here. Approval on a text
channel happens here, so no client of the control API can skip it.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from oricf.gateway.actuation.approval import ChannelApprover
from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.actuation.messages import nested, zero
from oricf.gateway.actuation.policy import AgentPolicy, Checked, Refused, TargetPolicy
from oricf.gateway.actuation.senders import Sender
from oricf.gateway.channels.server import Channels

log = logging.getLogger(__name__)


class Actuation:
    def __init__(self, policy: AgentPolicy, sender: Sender, audit: AuditLog,
                 channels: Channels | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.policy = policy
        self.audit = audit
        self._sender = sender
        self._clock = clock
        self._locks = {name: threading.Lock() for name in policy.targets}
        self._last_sent: dict[str, float] = {}
        self._approvers = {name: ChannelApprover(channels.get(t.approval_channel))
                           for name, t in policy.targets.items()
                           if t.approval_channel and channels is not None}
        self._deadman = Deadman(self._expire)

    def check(self, target: str, message: Any) -> Checked:
        """What would be sent (for a person to approve), or Refused (audited); nothing is
        sent."""
        try:
            return self.policy.target(target).check(target, message)
        except Refused as exc:
            self.audit.record("publish", "refused", target=target, message=message,
                              reason=str(exc))
            raise

    def send(self, target: str, message: Any, approved: bool = False) -> dict[str, Any]:
        """Sends within the policy; returns what was sent, or raises Refused (audited)."""
        try:
            return self._send(target, message, approved)
        except Refused as exc:
            self.audit.record("publish", "refused", target=target, message=message,
                              reason=str(exc))
            raise

    def _send(self, name: str, message: Any, approved: bool) -> dict[str, Any]:
        target = self.policy.target(name)
        checked = target.check(name, message)
        with self._locks[name]:
            self._check_rate(name, target)  # before asking anyone
        if target.approval == "elicit" and not approved:
            raise Refused(f"{name}: needs a person's approval, asked through the agent's "
                          f"client (MCP elicitation), and it was not given")
        if target.approval == "channel":  # without the lock: the deadman must not wait
            question = f"{name}: {json.dumps(nested(checked.fields))}"
            if not self._approvers[name].ask(question, target.approval_timeout_s):
                raise Refused(f"{name}: not approved on channel {target.approval_channel}")
        with self._locks[name]:
            self._check_rate(name, target)
            self._sender.send(name, checked.fields)
            self._last_sent[name] = self._clock()
            if target.deadman_ms is not None:
                self._deadman.renew(name, target.deadman_ms / 1000)
        outcome = "clamped" if checked.clamped else "sent"
        self.audit.record("publish", outcome, target=name, message=message,
                          sent=nested(checked.fields), clamped=checked.clamped)
        return {"target": name, "where": target.where, "sent": nested(checked.fields),
                "clamped": checked.clamped, "deadman_ms": target.deadman_ms}

    def _check_rate(self, name: str, target: TargetPolicy) -> None:
        last = self._last_sent.get(name)
        interval = 1.0 / target.max_rate_hz
        if last is not None and self._clock() - last < interval:
            wait_ms = (interval - (self._clock() - last)) * 1000
            raise Refused(f"{name}: over the rate limit of {target.max_rate_hz:g} commands "
                          f"a second; the next is allowed in {wait_ms:.0f} ms")

    def _expire(self, name: str) -> None:
        target = self.policy.targets[name]
        with self._locks[name]:
            if self._deadman.armed(name):  # a command came while this expiry waited
                return
            self._sender.send(name, zero(target.type))
        log.info("agent target %s: not renewed within %d ms, zero command sent", name,
                 target.deadman_ms)
        self.audit.record("deadman", "sent", target=name, sent=nested(zero(target.type)))

    def close(self) -> None:
        """Stops the deadman, sending the zero command of every target still armed."""
        for name in self._deadman.close():
            self._expire(name)
        self._sender.close()


class Deadman:
    """Per target, a deadline; `expire(target)` is called once when one passes unrenewed."""

    def __init__(self, expire: Callable[[str], None]) -> None:
        self._expire = expire
        self._deadlines: dict[str, float] = {}
        self._wake = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="agent-deadman", daemon=True)
        self._thread.start()

    def renew(self, target: str, seconds: float) -> None:
        with self._wake:
            deadline = time.monotonic() + seconds
            earlier = deadline < self._deadlines.get(target, float("inf"))
            self._deadlines[target] = deadline
            # A later deadline needs no wake-up: the thread, woken at the earlier one, waits
            # again (a control loop renews at every tick; a wake-up each costs CPU).
            if earlier:
                self._wake.notify()

    def armed(self, target: str) -> bool:
        with self._wake:
            return target in self._deadlines

    def _run(self) -> None:
        while True:
            with self._wake:
                if self._closed:
                    return
                now = time.monotonic()
                due = [t for t, at in self._deadlines.items() if at <= now]
                for target in due:
                    del self._deadlines[target]
                if not due:
                    nearest = min(self._deadlines.values(), default=now + 1.0)
                    self._wake.wait(max(0.0, nearest - now))
                    continue
            for target in due:
                try:
                    self._expire(target)
                except Exception:
                    log.exception("deadman of %s: the zero command failed", target)

    def close(self) -> list[str]:
        """Stops; returns the targets still armed."""
        with self._wake:
            self._closed = True
            armed = list(self._deadlines)
            self._deadlines.clear()
            self._wake.notify()
        self._thread.join(2)
        return armed
