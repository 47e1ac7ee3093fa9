"""What every source that is not a ROS topic provides (oricf.gateway.components.Source): it
runs on a thread of its own, hands each item to its route as a loader (`submit`), and says
when it has ended for good (`on_end`, e.g. a file that reached its end)."""

from __future__ import annotations

from oricf.gateway.components import OnEnd, Source, SourceKind, Submit

__all__ = ["OnEnd", "Source", "SourceKind", "Submit"]
