"""What a response_format JSON Schema may cost, checked in Python before llama.cpp sees its
grammar: pattern repetitions written out, grammar bytes, nesting, rules and alternatives,
terminals no token can match, recursion; then llama.cpp's own parser on the shipped model's
vocabulary. The service-level behaviour (400s, the process surviving) is in
test_llm_json_schema.py."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest

from oricf.errors import InvalidInput
from oricf.services.llm.config import JsonSchemaLimits
from oricf.services.llm.gbnf import measure
from oricf.services.llm.grammar import check_schema, native_check
from oricf.services.llm.pattern_size import expanded_size
from tests.services.schemas import look_alikes
from tests.support.data import data_file

LIMITS = JsonSchemaLimits()
PATH = "schema"


def string(pattern: str) -> dict[str, Any]:
    return {"type": "string", "pattern": pattern}


@pytest.mark.parametrize(("pattern", "size"), [
    ("^[0-9]{1,3}$", 3),
    ("^a{0,2000}$", 2000),
    ("^(a{0,50}){0,50}$", 2500),
    ("^((ab){2,}c)$", 7),
    ("^[}{]{4}\\{x$", 6),
    ("^" + "(" * 3000 + "a" + ")" * 3000 + "$", 1),
])
def test_a_pattern_is_sized_as_the_converter_writes_it_out(pattern: str, size: int) -> None:
    assert expanded_size(pattern, PATH, max_repeat=10_000) == size


@pytest.mark.parametrize(("schema", "says"), [
    (string("^a{0,2000}$"), "is over the limit of 256 repeats"),
    (string("^a{99999999999999999999}$"), "is over the limit of 256 repeats"),
    (string("^(a{0,50}){0,50}$"), "2,500 places; the limit is 256"),
    (string("^((a{0,8}){0,8}){0,8}$"), "512 places"),
    (string("^a{x}$"), "is not a repetition count"),
    (string("^a{1$"), "is never closed"),
    (string("^(?=a)$"), "cannot be enforced"),
    (string("^[\\x00]$"), "no character matches"),
    (string("^\\x00$"), "needs the character NUL"),
    (string("^[b-a]$"), "no character matches"),
    (string("^[^\\x01-\\U0010FFFF]$"), "no character matches"),
    (string("^" + "(" * 3000 + "a" + ")" * 3000 + "$"), "nests too deeply"),
    ({"$defs": {"n": {"type": "array", "items": {"$ref": "#/$defs/n"}}}, "type": "object",
      "properties": {"x": {"$ref": "#/$defs/n"}}}, "recursive schemas are not supported"),
    ({"type": "string", "enum": [f"v{i}" for i in range(100)]}, "in over 32 ways"),
    (string("^(a?){0,64}$"), "in over 32 ways"),
    ({"type": "object", "properties": {f"p{i}": {"type": "string", "maxLength": 256}
                                       for i in range(40)}}, "bytes; the limit is 65,536"),
    ({"type": "string", "maxLength": 257}, "257 is over the limit of 256"),
])
def test_costly_schemas_are_refused_naming_the_limit(schema: dict[str, Any], says: str) -> None:
    with pytest.raises(InvalidInput) as error:
        check_schema(schema, PATH, LIMITS)
    assert says in str(error.value)


def test_alternatives_nested_in_alternatives_multiply() -> None:
    limits = JsonSchemaLimits(max_alternatives=256)
    counts = [measure(check_schema(look_alikes(levels), PATH, limits), cap=10**9)
              .alternatives for levels in (3, 4, 5)]
    assert counts[1] == 2 * counts[0] and counts[2] == 2 * counts[1]
    with pytest.raises(InvalidInput, match="in over 32 ways"):
        check_schema(look_alikes(20), PATH, LIMITS)


def test_optional_items_in_a_row_add_up() -> None:
    """`a?` repeated: after some a's the reader may be at any of the later places."""
    def stacks(pattern: str) -> int:
        return measure(check_schema(string(pattern), PATH, LIMITS), cap=10**9).alternatives

    assert stacks("^(a?){0,20}$") > 20 > stacks("^a{0,20}$")


WORKING = [
    string("^[0-9]{1,3}$"),
    string("^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$"),
    {"type": "object", "properties": {"people": {"type": "integer"},
                                      "names": {"type": "array", "items": {"type": "string"},
                                                "maxItems": 8}},
     "required": ["people"]},
    {"type": "object"},                    # any JSON object: the recursive value rules
    {"type": "string", "maxLength": 256},
    {"type": "string", "format": "date-time"},
]


@pytest.mark.parametrize("schema", WORKING, ids=lambda schema: json.dumps(schema)[:40])
def test_reasonable_schemas_pass(schema: dict[str, Any]) -> None:
    assert "root ::=" in check_schema(schema, PATH, LIMITS)


@pytest.fixture(scope="module")
def vocab() -> Iterator[Any]:
    import llama_cpp

    params = llama_cpp.llama_model_default_params()
    params.vocab_only = True
    path = data_file("gemma3-270m", "model.gguf")
    model = llama_cpp.llama_model_load_from_file(str(path).encode(), params)
    assert model
    yield llama_cpp.llama_model_get_vocab(model)
    llama_cpp.llama_model_free(model)


@pytest.mark.parametrize("schema", WORKING, ids=lambda schema: json.dumps(schema)[:40])
def test_llama_cpp_builds_the_grammars_that_pass(vocab: Any, schema: dict[str, Any]) -> None:
    native_check(check_schema(schema, PATH, LIMITS), vocab)


@pytest.mark.parametrize("grammar", [
    'root ::= ("a" ("a" ' * 1001 + ")?" * 2002,     # past llama.cpp's repetition limit
    "root ::= root-1\nroot-1 ::= root-1 \"a\" | \"a\"",  # left recursion
    "root ::= undefined",
    'root ::= "a" {5000}',
])
def test_a_grammar_llama_cpp_refuses_is_invalid_input(vocab: Any, grammar: str) -> None:
    with pytest.raises(InvalidInput, match=r"llama\.cpp refuses"):
        native_check(grammar, vocab)
