"""JSON answers enforced while decoding: a llama.cpp grammar for any JSON object, or one
made from a JSON Schema (llama_cpp.LlamaGrammar.from_json_schema), so that even a small
model can only produce text that parses and validates.

Schemas come from callers, so they are checked before they become a grammar: only local
`$ref`s ("#/..."), since llama-cpp-python would fetch an https:// reference over the
network (a request forgery); bounded size; and no length or count keyword so large that the
grammar it unrolls into would be huge (no answer can be longer than max_tokens anyway).
"""

from __future__ import annotations

import json
from typing import Any

from oricf.errors import InvalidInput
from oricf.services.llm.domain import JsonOutput

MAX_SCHEMA_CHARS = 16_384
MAX_REPEAT = 256
MAX_DEPTH = 32
REPEAT_KEYWORDS = ("minLength", "maxLength", "minItems", "maxItems", "minProperties",
                   "maxProperties")


def _check(node: Any, path: str, depth: int = 0) -> None:
    if depth > MAX_DEPTH:
        raise InvalidInput(f"{path}: the schema is nested deeper than {MAX_DEPTH} levels")
    if isinstance(node, list):
        for i, item in enumerate(node):
            _check(item, f"{path}[{i}]", depth + 1)
        return
    if not isinstance(node, dict):
        return
    ref = node.get("$ref")
    if ref is not None and (not isinstance(ref, str) or not ref.startswith("#")):
        raise InvalidInput(f"{path}.$ref: only references inside the schema ('#/...') are "
                           f"allowed, got {str(ref)[:80]!r}")
    for keyword in REPEAT_KEYWORDS:
        value = node.get(keyword)
        if isinstance(value, int) and not isinstance(value, bool) and value > MAX_REPEAT:
            raise InvalidInput(f"{path}.{keyword}: {value} is over the limit of {MAX_REPEAT}")
    for key, value in node.items():
        _check(value, f"{path}.{key}", depth + 1)


def check_schema(schema: Any, path: str) -> str:
    """The schema as JSON text, refused (InvalidInput naming `path`) if it is not safe."""
    if not isinstance(schema, dict):
        raise InvalidInput(f"{path}: a JSON Schema must be an object")
    text = json.dumps(schema)
    if len(text) > MAX_SCHEMA_CHARS:
        raise InvalidInput(f"{path}: the schema has {len(text):,} characters; the limit is "
                           f"{MAX_SCHEMA_CHARS:,}")
    _check(schema, path)
    return text


def json_grammar(output: JsonOutput) -> Any:
    """The llama.cpp grammar for a JSON answer (the model is loaded: llama_cpp is too)."""
    from llama_cpp import LlamaGrammar
    from llama_cpp.llama_grammar import JSON_GBNF

    if output.schema is None:
        return LlamaGrammar.from_string(JSON_GBNF, verbose=False)
    try:
        return LlamaGrammar.from_json_schema(output.schema, verbose=False)
    except Exception as exc:  # the converter raises whatever it meets: assert, key, type
        raise InvalidInput(f"the JSON Schema cannot be enforced: {type(exc).__name__}: "
                           f"{str(exc)[:200]}") from None
