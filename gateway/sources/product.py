"""product: {product: people_count} runs the route on every new value of a data product
that another route outputs; the pipeline feeds it (oricf.gateway.pipeline)."""

from __future__ import annotations

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import SourceKind


class ProductInput(Schema):
    product: str | None = Field(None, description="run on every new value of a data product")


COMPONENT = SourceKind("product", ProductInput, lambda config: "value", None, rank=1)
