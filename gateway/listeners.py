"""The settings of the gateway's surfaces that listen, as a pipeline YAML writes them. They
are part of the pipeline's schema (oricf.gateway.config), so they live in the core; the
surfaces that serve them (oricf.gateway.api, oricf.gateway.live_view) import them from here.

    control:                                 # the control API (`oricf mcp --attach`)
      listen: unix:/run/oricf/control.sock   # or 127.0.0.1:7100 (loopback by default)
      auth: {file: control.tokens}           # bearer tokens; required on TCP
      tls: {cert: gw.pem, key: gw.key}       # required beyond this machine
      approvers: {file: approver.tokens}     # the MCP servers that relay a person's approval

    foxglove:                  # the live view
      listen: 127.0.0.1:8765     # loopback unless tls and auth are both set
      max_fps: 5                 # frames per camera route; the rest are dropped for the view
      jpeg_quality: 75           # raw frames are encoded for the view; JPEG/PNG pass as they are
      tls: {cert: server.pem, key: server.key}      # wss:// (client_ca: client certificates)
      auth: {env: ORICF_VIEW_TOKEN}                 # or {file: tokens.txt}: one per line

Every listener's exposure beyond loopback follows one rule, oricf.tls.check_exposure.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from pydantic import Field

from oricf.hosts import Address, ListenAddress, ListenTarget, UnixSocket
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


class LiveViewConfig(ListenerConfig):
    """The live view's listener and its limits; beyond loopback, tls and auth are both
    required (oricf.tls.check_exposure)."""

    listen: ListenAddress = Field(Address("127.0.0.1", 8765),
                                  description="host:port (port 0 picks a free one)")
    max_fps: float = Field(5.0, gt=0, le=60, description="frames sent per camera route per "
                                                         "second at most")
    jpeg_quality: int = Field(75, ge=10, le=100, description="raw frames encoded for the view")
    tls: ServerTls | None = Field(None, description="serve wss:// only")
    auth: TokenSource | None = Field(
        None, description="bearer tokens: `Authorization: Bearer TOKEN` or `?token=TOKEN`")
    max_clients: int = Field(8, ge=1, le=256, description="viewers connected at once")
    max_message_bytes: int = Field(
        65536, ge=1024, le=16 << 20, description="largest message a viewer may send")
    backlog: int = Field(
        64, ge=4, le=4096, description="messages queued per viewer; a slow viewer loses the "
                                       "oldest frames beyond it")
