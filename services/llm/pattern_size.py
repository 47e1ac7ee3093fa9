"""How large a JSON Schema `pattern` becomes once llama.cpp's schema converter unrolls it.

The converter (llama_cpp.llama_grammar) writes `x{m,n}` out as m copies of x followed by
n - m nested optional copies, so `a{0,2000}` is a grammar 2000 groups deep and
`(a{0,50}){0,50}` has 2500 places where the answer can be; a counted repetition inside
another multiplies. expanded_size() counts those places (every character, class or `.`
times the counts of the repetitions around it) without building anything, so a pattern
is refused before the converter spends memory on it or llama.cpp's parser recurses into it.
The scan follows the converter's reading of a pattern: escapes, classes, groups and
`{m}`, `{m,}`, `{m,n}`; it needs no recursion however deeply groups nest.
"""

from __future__ import annotations

from dataclasses import dataclass

from oricf.errors import InvalidInput


@dataclass
class _Group:
    done: int = 0     # places in the finished items of this group
    last: int = 0     # places in the item a quantifier would apply to

    def add(self, places: int) -> None:
        self.done += self.last
        self.last = places

    @property
    def size(self) -> int:
        return self.done + self.last


def _class_end(pattern: str, i: int) -> int:
    """The index after the `]` closing the class that starts at `i` (the converter's rule:
    a backslash escapes the next character)."""
    i += 1
    while i < len(pattern) and pattern[i] != "]":
        i += 2 if pattern[i] == "\\" else 1
    return i + 1


def _repeat_factor(body: str, path: str, max_repeat: int) -> int:
    """How many copies `{body}` makes of the item before it (`{m,}`: m, then a loop)."""
    parts = [part.strip() for part in body.split(",")]
    if len(parts) > 2 or not all(part.isdigit() for part in parts if part) or not parts[0]:
        raise InvalidInput(f"{path}: {{{body[:40]}}} is not a repetition count such as "
                           f"{{3}}, {{1,}} or {{0,8}}")
    counts = [int(part) for part in parts if part]
    if max(counts) > max_repeat:
        raise InvalidInput(f"{path}: the repetition {{{body[:40]}}} is over the limit of "
                           f"{max_repeat} repeats")
    if len(parts) == 1:
        return counts[0]
    return counts[0] + 1 if len(counts) == 1 else max(counts)


def expanded_size(pattern: str, path: str, max_repeat: int) -> int:
    """The places in `pattern` once every counted repetition is written out.

    Raises InvalidInput (naming `path`) for a count over max_repeat or a malformed count."""
    groups = [_Group()]
    i = 0
    while i < len(pattern):
        c = pattern[i]
        if c == "(":
            groups.append(_Group())
            i += 1
        elif c == ")" and len(groups) > 1:
            inner = groups.pop()
            groups[-1].add(inner.size)
            i += 1
        elif c == "{":
            end = pattern.find("}", i)
            if end < 0:
                raise InvalidInput(f"{path}: a '{{' is never closed")
            groups[-1].last *= _repeat_factor(pattern[i + 1:end], path, max_repeat)
            i = end + 1
        elif c in "*+?|^$":
            i += 1            # a loop, an option or an end: no copies
        elif c == "[":
            groups[-1].add(1)
            i = _class_end(pattern, i)
        else:
            groups[-1].add(1)
            i += 2 if c == "\\" else 1
    return sum(group.size for group in groups)
