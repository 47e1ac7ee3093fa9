"""The pipeline's `foxglove:` key: where the live view listens and what it sends.

    foxglove:
      listen: 127.0.0.1:8765     # loopback unless tls and auth are both set
      max_fps: 5                 # frames per camera route; the rest are dropped for the view
      jpeg_quality: 75           # raw frames are encoded for the view; JPEG/PNG pass as they are
      tls: {cert: server.pem, key: server.key}      # wss:// (client_ca: client certificates)
      auth: {env: ORICF_VIEW_TOKEN}                 # or {file: tokens.txt}: one per line
"""

from __future__ import annotations

from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.hosts import is_loopback
from oricf.metrics import split_listen
from oricf.tls import ServerTls, TokenSource


class LiveViewConfig(Schema):
    """The live view's listener and its limits."""

    listen: str = Field("127.0.0.1:8765", description="host:port (port 0 picks a free one)")
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

    @field_validator("listen")
    @classmethod
    def _host_port(cls, value: str) -> str:
        split_listen(value)
        return value

    @model_validator(mode="after")
    def _secure_beyond_loopback(self) -> LiveViewConfig:
        host, _ = split_listen(self.listen)
        if not is_loopback(host) and (self.tls is None or self.auth is None):
            raise ValueError(f"listen: {self.listen} is reachable from other machines: set "
                             f"both tls and auth, or listen on 127.0.0.1")
        return self
