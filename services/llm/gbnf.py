"""The shape of a GBNF grammar, read in Python before llama.cpp parses it.

llama.cpp's grammar parser recurses once per nested group, and while decoding it keeps one
parse stack per way the answer so far can be read: a grammar nested thousands deep can
overflow the native stack, and one whose alternatives can all match the same text (an
`anyOf` of look-alike schemas nested inside each other) doubles its stacks at every level
and stalls each token. measure() reads the grammar text once, without recursion, and
returns what bounds those costs:

- nesting: the deepest nest of parentheses (llama.cpp's recursion);
- rules: the rules llama.cpp will make (each named rule, group and `?`/`*`/`+` item);
- alternatives: how many parse stacks one position of the answer can have at most: the
  alternatives of a rule add up, items one after another in a sequence do not (only one
  of them is being read), and a reference counts what its rule counts.

It refuses (InvalidInput) a grammar with a terminal that no text can match (the character
NUL, an empty class): llama.cpp would then reject every token, pick one anyway and abort
the process when it accepts it. A rule that refers back to itself is refused too, except
the converter's own JSON value rules, whose alternatives start with distinct characters.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from oricf.errors import InvalidInput

MAX_CODE_POINT = 0x10FFFF
# The converter's fixed rules for any JSON value; they refer to each other, unambiguously.
RECURSIVE_BUILTINS = frozenset({"value", "object", "array"})
NAME = re.compile(r"[A-Za-z0-9-]+")
SIMPLE_ESCAPES = {"t": 9, "r": 13, "n": 10, "\\": 92, '"': 34, "[": 91, "]": 93}
HEX_ESCAPES = {"x": 2, "u": 4, "U": 8}


# One item of a sequence: 1 for a terminal or the name of the rule it refers to, and
# whether it may match nothing (`x?`, `x*`).
Item = tuple[int | str, bool]
Alternatives = list[list[Item]]


@dataclass(frozen=True)
class GrammarShape:
    nesting: int
    rules: int
    alternatives: int


class _Reader:
    def __init__(self, text: str) -> None:
        self.text = text
        self.i = 0
        # A rule (named, or a group under a made-up name) -> its alternatives, each a list
        # of items: 1 for a terminal, or the name of the rule it refers to.
        self.rules: dict[str, Alternatives] = {}
        self.made_rules = 0
        self.nesting = 0

    def fail(self, what: str) -> InvalidInput:
        return InvalidInput(f"the grammar made from the schema {what} (at character {self.i})")

    def char(self) -> int:
        """One character of a literal or class (as llama.cpp's parse_char reads it)."""
        text, i = self.text, self.i
        if text[i] != "\\":
            self.i += 1
            return ord(text[i])
        kind = text[i + 1: i + 2]
        if kind in SIMPLE_ESCAPES:
            self.i += 2
            return SIMPLE_ESCAPES[kind]
        digits = HEX_ESCAPES.get(kind)
        value = text[i + 2: i + 2 + digits] if digits else ""
        if not digits or len(value) != digits or not all(c in "0123456789abcdefABCDEF"
                                                         for c in value):
            raise self.fail(f"has an escape llama.cpp does not read: {text[i:i + 4]!r}")
        self.i += 2 + digits
        return int(value, 16)

    def literal(self) -> None:
        self.i += 1
        while self.i < len(self.text) and self.text[self.i] != '"':
            if self.char() == 0:
                raise self.fail("needs the character NUL, which no token can give")
        self.i += 1

    def char_class(self) -> None:
        self.i += 1
        negated = self.text.startswith("^", self.i)
        self.i += negated
        ranges: list[tuple[int, int]] = []
        while self.i < len(self.text) and self.text[self.i] != "]":
            low = high = self.char()
            if self.text[self.i: self.i + 1] == "-" and self.text[self.i + 1:][:1] not in "]":
                self.i += 1
                high = self.char()
            ranges.append((low, high))
        self.i += 1
        if not _matches_something(ranges, negated):
            raise self.fail("has a character class that no character matches")

    def rule(self) -> None:
        """`name ::= body`, up to the newline that ends it outside any group."""
        name = NAME.match(self.text, self.i)
        if name is None or not self.text.startswith("::=", self.skip_blanks(name.end())):
            raise self.fail("has a line that is not `name ::= ...`")
        if name.group() in self.rules:
            raise self.fail(f"defines {name.group()!r} twice")
        self.i = self.skip_blanks(name.end()) + 3
        self.body(name.group())

    def body(self, name: str) -> None:
        open_groups: list[tuple[str, Alternatives]] = [(name, [[]])]
        while self.i < len(self.text):
            c = self.text[self.i]
            if c == "\n" and len(open_groups) == 1:
                break
            if c in " \t\r\n":
                self.i += 1
            elif c == "#":
                end = self.text.find("\n", self.i)
                self.i = len(self.text) if end < 0 else end
            else:
                self.item(c, open_groups)
        if len(open_groups) > 1:
            raise self.fail("has a '(' that is never closed")
        self.rules[name] = open_groups[0][1]

    def item(self, c: str, open_groups: list[tuple[str, Alternatives]]) -> None:
        alternatives = open_groups[-1][1]
        if c == '"':
            self.literal()
            alternatives[-1].append((1, False))
        elif c == "[":
            self.char_class()
            alternatives[-1].append((1, False))
        elif c == ".":
            self.i += 1
            alternatives[-1].append((1, False))
        elif c == "|":
            self.i += 1
            alternatives.append([])
        elif c in "*+?" and alternatives[-1]:
            self.i += 1
            self.made_rules += 1
            if c != "+":
                alternatives[-1][-1] = (alternatives[-1][-1][0], True)
        elif c == "(":
            self.i += 1
            self.made_rules += 1
            open_groups.append((f"({self.made_rules})", [[]]))
            self.nesting = max(self.nesting, len(open_groups) - 1)
        elif c == ")" and len(open_groups) > 1:
            self.i += 1
            group, body = open_groups.pop()
            self.rules[group] = body
            open_groups[-1][1][-1].append((group, False))
        elif (name := NAME.match(self.text, self.i)) is not None:
            self.i = name.end()
            alternatives[-1].append((name.group(), False))
        else:
            raise self.fail(f"has {c!r} where llama.cpp's grammars have no such item")

    def skip_blanks(self, i: int) -> int:
        while i < len(self.text) and self.text[i] in " \t":
            i += 1
        return i


def measure(text: str, cap: int) -> GrammarShape:
    """The grammar's nesting, rules and alternatives (counted up to `cap`).

    Raises InvalidInput for a grammar llama.cpp could not parse or could not decode with."""
    reader = _Reader(text)
    while True:
        while reader.i < len(text) and text[reader.i] in " \t\r\n":
            reader.i += 1
        if reader.i >= len(text):
            break
        reader.rule()
    if "root" not in reader.rules:
        raise reader.fail("has no root rule")
    named = sum(1 for name in reader.rules if not name.startswith("("))
    return GrammarShape(nesting=reader.nesting, rules=named + reader.made_rules,
                        alternatives=_alternatives(reader.rules, cap))


def _alternatives(rules: dict[str, Alternatives], cap: int) -> int:
    """Parse stacks at one position, at most: a depth-first walk of the rules from root,
    with an explicit stack (the rules may nest thousands deep)."""
    counts: dict[str, tuple[int, bool]] = {}    # a rule -> (its stacks, whether it may be empty)
    started: set[str] = set()
    todo = ["root"]
    while todo:
        name = todo[-1]
        if name in counts:
            todo.pop()
            continue
        if name not in rules:
            raise InvalidInput(f"the grammar made from the schema refers to {name!r}, "
                               f"which it does not define")
        if name not in started:
            started.add(name)
            todo.extend(_refs_to_visit(rules[name], started, counts))
            continue
        # Every reference is counted now, or leads back into a JSON value rule: one stack,
        # never empty.
        seqs = [[_value(item, counts) for item in seq] for seq in rules[name]]
        counts[name] = (min(cap, sum(_sequence_stacks(seq) for seq in seqs)),
                        any(all(empty for _, empty in seq) for seq in seqs))
        todo.pop()
    return counts["root"][0]


def _value(item: Item, counts: dict[str, tuple[int, bool]]) -> tuple[int, bool]:
    value, optional = item
    if isinstance(value, int):
        return value, optional
    stacks, empty = counts.get(value, (1, False))
    return stacks, optional or empty


def _sequence_stacks(seq: list[tuple[int, bool]]) -> int:
    """Items one after another are read one at a time, except that the reader can be in
    an item and past it at once when the item may match nothing: a run of such items and
    the one after it add up (`a? a? a? b` has four places to be)."""
    best = run = 0
    for stacks, empty in seq:
        run += stacks
        best = max(best, run)
        if not empty:
            run = 0
    return best


def _refs_to_visit(body: Alternatives, started: set[str],
                   counts: dict[str, tuple[int, bool]]) -> list[str]:
    refs = []
    for item in {value for seq in body for value, _ in seq if isinstance(value, str)}:
        if item in counts:
            continue
        if item in started:   # an unfinished rule: this reference leads back into it
            if item not in RECURSIVE_BUILTINS:
                raise InvalidInput(f"the schema refers to itself (rule {item!r} of its "
                                   f"grammar); recursive schemas are not supported")
            continue
        refs.append(item)
    return refs


def _matches_something(ranges: list[tuple[int, int]], negated: bool) -> bool:
    """Whether a class admits a character from 1 to U+10FFFF (NUL no token can give)."""
    spans = sorted((max(low, 1), min(high, MAX_CODE_POINT)) for low, high in ranges)
    spans = [(low, high) for low, high in spans if low <= high]
    if not negated:
        return bool(spans)
    covered_to = 0
    for low, high in spans:
        if low > covered_to + 1:
            return True
        covered_to = max(covered_to, high)
    return covered_to < MAX_CODE_POINT
