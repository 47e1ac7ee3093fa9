"""Names a caller passes to the control operations, checked by one rule on both sides of the
control API: in this process (view.PipelineView) and before a request leaves for a running
gateway (client.ControlClient), so an attached MCP server refuses what the gateway would."""

from __future__ import annotations

from collections.abc import Iterable

from oricf.errors import InvalidInput
from oricf.logs import quoted


def known_product(name: str, products: Iterable[str]) -> str:
    """`name` if the pipeline writes a data product of that name, else InvalidInput."""
    known = sorted(products)
    if name not in known:
        raise InvalidInput(f"no data product {quoted(name, 100)} (products: "
                           f"{', '.join(known) or 'none'})")
    return name
