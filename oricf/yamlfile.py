"""Reading YAML with limits: every YAML text ORICF reads (pipelines, overlays, service
configs, deployments, model declarations, the catalog, prompts, --set values) goes through
`read_yaml` or `parse_yaml`.

A config file may come from someone else (an overlay handed over, a model declaration
downloaded with its weights), so reading one must not cost more than a config can need:
the bytes read are capped (a link to /dev/zero reads no further than the cap), the text
must be UTF-8, nesting is limited (deep nesting would end in a RecursionError), the nodes
are counted with every alias counted as the nodes it stands for (an alias bomb is a few
hundred bytes that expand to gigabytes once merged node by node), and integers are
limited in digits. Every failure is a ConfigError naming the file and the line, never a
parser's own exception.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
import yaml.reader
from yaml.composer import ComposerError
from yaml.constructor import ConstructorError
from yaml.events import AliasEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from oricf.errors import ConfigError

MAX_BYTES = 1 << 20  # a config is a page or two; the largest shipped is far below this
MAX_DEPTH = 64  # nesting of collections; configs go a handful of levels deep
MAX_NODES = 100_000  # scalars and collections, every alias counted as what it expands to
MAX_INT_DIGITS = 40  # above any 128-bit value; Python's own limit would raise ValueError


class LimitedLoader(yaml.SafeLoader):
    """PyYAML's safe loader, counting depth and (expanded) nodes as it composes."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0
        self._expanded: dict[int, int] = {}  # id(node) -> nodes it stands for, itself in
        self._keys: list[str] = []  # where the node being composed is, for errors

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        # PyYAML passes a mapping value its key node, a list item its index.
        self._keys.append(f"[{index}]" if isinstance(index, int) else
                          f".{str(index.value)[:40]}" if isinstance(index, ScalarNode) else "")
        try:
            return self._compose(parent, index)
        finally:
            self._keys.pop()

    def _compose(self, parent: Node | None, index: Any) -> Node:
        if self.check_event(AliasEvent):
            mark = self.peek_event().start_mark
            node = super().compose_node(parent, index)
            if id(node) not in self._expanded:  # the alias is inside the node it names
                raise ComposerError(None, None, f"an alias inside the value it names (a "
                                    f"structure that contains itself) at {self._where()}", mark)
            self._count(self._expanded[id(node)], mark)
            return node
        mark = self.peek_event().start_mark
        self._depth += 1
        if self._depth > MAX_DEPTH:
            raise ComposerError(None, None, f"nested more than {MAX_DEPTH} levels deep", mark)
        node = super().compose_node(parent, index)
        self._depth -= 1
        self._expanded[id(node)] = 1 + sum(self._expanded.get(id(child), 1)
                                           for child in _children(node))
        self._count(1, mark)
        return node

    def _count(self, nodes: int, mark: Any) -> None:
        self._nodes += nodes
        if self._nodes > MAX_NODES:
            raise ComposerError(None, None, f"more than {MAX_NODES:,} values (aliases "
                                f"counted as what they repeat), reached at {self._where()}", mark)

    def _where(self) -> str:
        """The key path of the node being composed, escaped: a file's keys may be anything."""
        path = "".join(self._keys).lstrip(".") or "(top level)"
        return repr(path[-120:])[1:-1]

    def construct_yaml_int(self, node: Node) -> int:
        digits = sum(c.isalnum() for c in str(node.value))
        if digits > MAX_INT_DIGITS:
            raise ConstructorError(None, None, f"an integer of more than {MAX_INT_DIGITS} "
                                   "digits", node.start_mark)
        return int(super().construct_yaml_int(node))


LimitedLoader.add_constructor("tag:yaml.org,2002:int", LimitedLoader.construct_yaml_int)


def _children(node: Node) -> list[Node]:
    if isinstance(node, SequenceNode):
        return list(node.value)
    if isinstance(node, MappingNode):
        return [child for pair in node.value for child in pair]
    return []


def read_yaml(path: Path) -> Any:
    """The parsed content of a YAML file; ConfigError naming the file if it cannot be read
    or goes beyond a limit."""
    return parse_yaml(_text(path), str(path))


def _text(path: Path) -> str:
    try:
        with open(path, "rb") as file:
            # One byte more than the cap tells a file at the cap from one beyond it, and a
            # device or a pipe is never read further.
            data = file.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: a folder, not a YAML file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    if len(data) > MAX_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_BYTES:,} bytes, more than a config "
                          f"can need")
    try:
        return data.decode("utf-8-sig")  # a UTF-8 byte-order mark is harmless
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start:,}); save it as "
                          f"UTF-8") from None


def parse_yaml(text: str, source: str) -> Any:
    """Parsed YAML text; ConfigError naming source (and the line) when the text is not
    YAML or goes beyond a limit."""
    if len(text) > MAX_BYTES:
        raise ConfigError(f"{source}: larger than {MAX_BYTES:,} characters, more than a "
                          f"config can need")
    loader = None
    try:
        loader = LimitedLoader(text)  # checks the characters at once
        return loader.get_single_data()
    except yaml.reader.ReaderError as exc:
        raise ConfigError(f"{source}: invalid YAML (character {exc.position:,}): character "
                          f"#x{exc.character:04x} is not allowed in YAML") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{source}: invalid YAML{where}: {problem}") from None
    except (ValueError, OverflowError, RecursionError) as exc:  # a constructor's own
        raise ConfigError(f"{source}: invalid YAML: {exc}") from None
    finally:
        if loader is not None:
            loader.dispose()
