"""JSON answers enforced while decoding: a llama.cpp grammar for any JSON object, or one
made from a JSON Schema, so that even a small model can only produce text that parses and
validates.

Schemas come from callers, and llama.cpp's grammar code is native: a grammar it cannot
parse leaves llama-cpp-python a null sampler (the process dies at the first token), one
nested thousands deep overflows its parser's stack, and one with many readings of the same
text makes every token slow. So a schema goes through three gates, each a client error
(InvalidInput, naming the limit) when it fails:

1. the schema itself (check_schema): only local `$ref`s ("#/...", since the converter
   would fetch an https:// reference: a request forgery), its size and depth, length and
   count keywords, and what each `pattern` expands to (pattern_size);
2. the GBNF text made from it in Python (llama_cpp.llama_grammar.json_schema_to_gbnf,
   which raises on what it cannot convert): its bytes, nesting, rules and alternatives,
   and terminals that no token could match (gbnf);
3. llama.cpp's own parser (native_check): the grammar is built once and freed; a grammar
   it refuses is refused here, before any sampler holds it.

The limits are config keys (limits.json_schema); their ceilings were measured so that the
worst accepted grammar is parsed in milliseconds and decodes at a bounded cost per token.
"""

from __future__ import annotations

import json
import logging
from typing import Any

from oricf.errors import InvalidInput
from oricf.services.llm.config import JsonSchemaLimits
from oricf.services.llm.domain import JsonOutput
from oricf.services.llm.gbnf import measure
from oricf.services.llm.pattern_size import expanded_size

log = logging.getLogger(__name__)

REPEAT_KEYWORDS = ("minLength", "maxLength", "minItems", "maxItems", "minProperties",
                   "maxProperties")
ROOT = "root"


def _check_keywords(node: dict[str, Any], path: str, limits: JsonSchemaLimits) -> None:
    ref = node.get("$ref")
    if ref is not None and (not isinstance(ref, str) or not ref.startswith("#")):
        raise InvalidInput(f"{path}.$ref: only references inside the schema ('#/...') are "
                           f"allowed, got {str(ref)[:80]!r}")
    for keyword in REPEAT_KEYWORDS:
        value = node.get(keyword)
        if isinstance(value, int) and not isinstance(value, bool) and value > limits.max_repeat:
            raise InvalidInput(f"{path}.{keyword}: {value} is over the limit of "
                               f"{limits.max_repeat}")
    pattern = node.get("pattern")
    if isinstance(pattern, str):
        size = expanded_size(pattern, f"{path}.pattern", limits.max_repeat)
        if size > limits.max_pattern_expansion:
            raise InvalidInput(f"{path}.pattern: written out, its repetitions make {size:,} "
                               f"places; the limit is {limits.max_pattern_expansion}")


def _check_tree(schema: Any, path: str, limits: JsonSchemaLimits) -> None:
    """Every node of the schema, without recursion (depth is a limit, not a crash)."""
    todo = [(schema, path, 0)]
    while todo:
        node, where, depth = todo.pop()
        if depth > limits.max_depth:
            raise InvalidInput(f"{where}: the schema is nested deeper than "
                               f"{limits.max_depth} levels")
        if isinstance(node, list):
            todo.extend((item, f"{where}[{i}]", depth + 1) for i, item in enumerate(node))
        elif isinstance(node, dict):
            _check_keywords(node, where, limits)
            todo.extend((value, f"{where}.{key}", depth + 1) for key, value in node.items())


def _to_gbnf(text: str) -> str:
    from llama_cpp.llama_grammar import json_schema_to_gbnf

    try:
        grammar: str = json_schema_to_gbnf(text)
    except RecursionError:
        raise InvalidInput("the JSON Schema nests too deeply to be enforced") from None
    except Exception as exc:  # the converter raises whatever it meets: assert, key, type
        raise InvalidInput(f"the JSON Schema cannot be enforced: {type(exc).__name__}: "
                           f"{str(exc)[:200]}") from None
    return grammar


def _check_grammar(grammar: str, path: str, limits: JsonSchemaLimits) -> None:
    size = len(grammar.encode("utf-8", errors="replace"))
    if size > limits.max_grammar_bytes:
        raise InvalidInput(f"{path}: the grammar made from the schema has {size:,} bytes; the "
                           f"limit is {limits.max_grammar_bytes:,} (limits.json_schema."
                           f"max_grammar_bytes)")
    shape = measure(grammar, cap=limits.max_alternatives + 1)
    if shape.rules > limits.max_grammar_rules:
        raise InvalidInput(f"{path}: the grammar made from the schema has {shape.rules:,} rules; "
                           f"the limit is {limits.max_grammar_rules:,}")
    if shape.nesting > limits.max_repeat + 8:
        raise InvalidInput(f"{path}: the grammar made from the schema nests {shape.nesting} "
                           f"groups deep; the limit is {limits.max_repeat + 8}")
    if shape.alternatives > limits.max_alternatives:
        raise InvalidInput(f"{path}: the schema's alternatives (anyOf, oneOf, enum, type "
                           f"lists, | in patterns) can read one answer in over "
                           f"{limits.max_alternatives} ways at once; the limit is "
                           f"{limits.max_alternatives}")


def check_schema(schema: Any, path: str, limits: JsonSchemaLimits) -> str:
    """The GBNF grammar for `schema`, refused (InvalidInput naming `path`) if it is unsafe."""
    if not isinstance(schema, dict):
        raise InvalidInput(f"{path}: a JSON Schema must be an object")
    _check_tree(schema, path, limits)
    text = json.dumps(schema)
    if len(text) > limits.max_schema_chars:
        raise InvalidInput(f"{path}: the schema has {len(text):,} characters; the limit is "
                           f"{limits.max_schema_chars:,}")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise InvalidInput(f"{path}: the schema has a lone surrogate (\\ud800-\\udfff), "
                           f"which is not text") from None
    grammar = _to_gbnf(text)
    _check_grammar(grammar, path, limits)
    return grammar


def native_check(grammar: str, vocab: Any) -> None:
    """Builds the grammar once with llama.cpp and frees it: InvalidInput if it refuses."""
    import llama_cpp

    sampler = llama_cpp.llama_sampler_init_grammar(vocab, grammar.encode("utf-8"),
                                                   ROOT.encode())
    if not sampler:
        raise InvalidInput("llama.cpp refuses the grammar made from the JSON Schema (its "
                           "repetitions or rules go past what its parser accepts)")
    llama_cpp.llama_sampler_free(sampler)


def json_grammar(output: JsonOutput, vocab: Any) -> Any:
    """The llama.cpp grammar for a JSON answer (the model is loaded: llama_cpp is too)."""
    from llama_cpp import LlamaGrammar
    from llama_cpp.llama_grammar import JSON_GBNF

    if output.grammar is None:
        return LlamaGrammar.from_string(JSON_GBNF, verbose=False)
    native_check(output.grammar, vocab)
    return LlamaGrammar.from_string(output.grammar, verbose=False)
