"""product: {product: people_count, from: count, max_age_s: 5} keeps the newest value as a
data product, which the pipeline itself holds (oricf.gateway.products.ProductStore): routes
that read it as input or context, and the control API, read it there."""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import SinkKind


class ProductOutput(Schema):
    product: str | None = None
    max_age_s: float = Field(5.0, gt=0, description="product: older values count as stale")


COMPONENT = SinkKind("product", ProductOutput, None, rank=1)
