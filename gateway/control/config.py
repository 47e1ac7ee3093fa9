"""The `control:` key of a pipeline YAML: where the gateway's control API listens.

    control:
      listen: unix:/run/oricf/control.sock   # or 127.0.0.1:7100 (loopback by default)
      auth: {file: control.tokens}           # bearer tokens; required on TCP
      tls: {cert: gw.pem, key: gw.key}       # required beyond this machine
      approvers: {file: approver.tokens}     # the MCP servers that relay a person's approval
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from pydantic import Field

from oricf.hosts import Address, ListenTarget, UnixSocket
from oricf.tls import Exposure, ListenerConfig, ServerTls, TokenSource


class ControlConfig(ListenerConfig):
    """Bearer tokens on every TCP address, TLS beyond loopback too (oricf.tls.check_exposure);
    a Unix socket is this user's only (mode 0600)."""

    listen: ListenTarget = Field(Address("127.0.0.1", 7100),
                                 description="host:port, or unix:PATH")
    auth: TokenSource | None = Field(None, description="bearer tokens (required on TCP)")
    tls: ServerTls | None = None
    approvers: TokenSource | None = Field(
        None, description="bearer tokens of the MCP servers (oricf mcp --attach) that relay "
                          "a person's approval of `approval: elicit` targets; a publish "
                          "says `approved` to no effect without one of them")
    max_body_bytes: int = Field(12 * 1024 * 1024, ge=1024, le=256 * 1024 * 1024)
    max_connections: int = Field(
        64, ge=2, le=4096, description="connections at once; a new one closes the "
                                       "connection idle the longest when all are open")
    header_timeout_s: float = Field(
        10.0, gt=0, le=600, description="a connection whose request headers are not complete "
                                        "this long after it opened (or after its last "
                                        "answer) is closed")
    body_timeout_s: float = Field(
        30.0, gt=0, le=3600, description="a request body not complete this long after its "
                                         "headers is answered 408")
    exposure: ClassVar[Exposure] = Exposure.TOKENS_ON_TCP

    @property
    def socket_path(self) -> Path | None:
        return self.listen.path if isinstance(self.listen, UnixSocket) else None
