"""The `control:` key of a pipeline YAML: where the gateway's control API listens.

    control:
      listen: unix:/run/oricf/control.sock   # or 127.0.0.1:7100 (loopback by default)
      auth: {file: control.tokens}           # bearer tokens; required on TCP
      tls: {cert: gw.pem, key: gw.key}       # for an address beyond this machine
      approvers: {file: approver.tokens}     # the MCP servers that relay a person's approval
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.metrics import split_listen
from oricf.tls import ServerTls, TokenSource

UNIX = "unix:"


class ControlConfig(Schema):
    listen: str = Field("127.0.0.1:7100", description="host:port, or unix:PATH")
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

    @field_validator("listen")
    @classmethod
    def _address(cls, value: str) -> str:
        if value.startswith(UNIX):
            if not value[len(UNIX):]:
                raise ValueError("unix: needs a path")
        else:
            split_listen(value)
        return value

    @model_validator(mode="after")
    def _token_on_tcp(self) -> ControlConfig:
        if self.socket_path is None and self.auth is None:
            raise ValueError("a TCP listen address needs auth (bearer tokens): any local "
                             "user could otherwise drive the robot's agent targets")
        return self

    @property
    def socket_path(self) -> Path | None:
        return Path(self.listen[len(UNIX):]) if self.listen.startswith(UNIX) else None
