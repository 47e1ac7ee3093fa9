"""JSON schemas whose grammars llama.cpp finds costly, for the language service's tests."""

from __future__ import annotations

from typing import Any


def look_alikes(levels: int) -> dict[str, Any]:
    """Each level an anyOf of two arrays that both start with `[` and the next level: the
    answer `[[[[...` is read both ways at every level, so the ways double per level."""
    defs: dict[str, Any] = {f"d{levels}": {"type": "integer"}}
    for k in range(levels):
        inner = {"$ref": f"#/$defs/d{k + 1}"}
        defs[f"d{k}"] = {"anyOf": [
            {"type": "array", "prefixItems": [inner], "minItems": 1, "maxItems": 1},
            {"type": "array", "prefixItems": [inner, {"type": "boolean"}], "minItems": 2,
             "maxItems": 2}]}
    return {"$defs": defs, "type": "object", "properties": {"x": {"$ref": "#/$defs/d0"}},
            "required": ["x"]}
