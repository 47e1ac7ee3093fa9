"""The pipeline's `foxglove:` key: where the live view listens and what it sends.

    foxglove:
      listen: 127.0.0.1:8765     # loopback unless tls and auth are both set
      max_fps: 5                 # frames per camera route; the rest are dropped for the view
      jpeg_quality: 75           # raw frames are encoded for the view; JPEG/PNG pass as they are
      tls: {cert: server.pem, key: server.key}      # wss:// (client_ca: client certificates)
      auth: {env: ORICF_VIEW_TOKEN}                 # or {file: tokens.txt}: one per line
"""

from __future__ import annotations

from pydantic import Field

from oricf.hosts import Address, ListenAddress
from oricf.tls import ListenerConfig, ServerTls, TokenSource


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
