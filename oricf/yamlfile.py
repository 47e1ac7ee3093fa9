"""Reading YAML with limits: every YAML text ORICF reads (pipelines, overlays, service
configs, deployments, model declarations, the catalog, prompts, --set values) goes through
`read_yaml` or `parse_yaml`. Its reading of bytes, `read_limited`, is also the one reader of
the other small files a config names (tokens, keys and certificates: oricf.tls).

A config file may come from someone else (an overlay handed over, a model declaration
downloaded with its weights), so reading one must not cost more than a config can need:
only a regular file is read (a device such as /dev/zero, a FIFO that would wait for a
writer forever, a socket or a folder is refused without reading), the bytes read are capped,
the text must be UTF-8, nesting is limited (deep nesting would end in a RecursionError), the
nodes are counted with every alias counted as the nodes it stands for (an alias bomb is a
few hundred bytes that expand to gigabytes once merged node by node), integers are limited
in digits, and a key given twice in one mapping is refused (the last one would otherwise
win without a word). Every failure is a ConfigError naming the file and the line, never a
parser's own exception.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
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
MERGE_TAG = "tag:yaml.org,2002:merge"


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
        if isinstance(node, MappingNode):
            self._refuse_repeated_keys(node)
        self._expanded[id(node)] = 1 + sum(self._expanded.get(id(child), 1)
                                           for child in _children(node))
        self._count(1, mark)
        return node

    def _count(self, nodes: int, mark: Any) -> None:
        self._nodes += nodes
        if self._nodes > MAX_NODES:
            raise ComposerError(None, None, f"more than {MAX_NODES:,} values (aliases "
                                f"counted as what they repeat), reached at {self._where()}", mark)

    def _refuse_repeated_keys(self, node: MappingNode) -> None:
        """A key given twice in one mapping: PyYAML would keep the last without a word. The
        keys a merge (`<<: *base`) brings are not this mapping's own, so they may be given
        again: that is what a merge is for."""
        seen: set[object] = set()
        for key, _ in node.value:
            if not isinstance(key, ScalarNode) or key.tag == MERGE_TAG:
                continue
            value = self._key_value(key)
            if value in seen:
                self._keys.append(f".{str(key.value)[:40]}")
                where = self._where()
                self._keys.pop()
                raise ComposerError(None, None, f"the key {where} is given twice (the second "
                                    f"would replace the first)", key.start_mark)
            seen.add(value)

    def _key_value(self, key: ScalarNode) -> object:
        """A scalar key as the mapping will hold it: `1` and `0x1`, or `on` and `true`, are
        one key, as in the dict they become."""
        construct = self.yaml_constructors.get(key.tag)
        if construct is None:
            return (key.tag, key.value)
        try:
            value = construct(self, key)
            hash(value)
        except (TypeError, ValueError, OverflowError, yaml.YAMLError):
            return (key.tag, key.value)  # left for the constructor to refuse, as it would
        return value

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
    data = read_limited(path, "a YAML file")
    try:
        return data.decode("utf-8-sig")  # a UTF-8 byte-order mark is harmless
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start:,}); save it as "
                          f"UTF-8") from None


def read_limited(path: Path, kind: str, limit: int = MAX_BYTES,
                 check: Callable[[os.stat_result], None] | None = None) -> bytes:
    """The bytes of `path`, a regular file of at most `limit` bytes; ConfigError naming the
    file otherwise (`kind` says what it should have been: "a YAML file", "a token file").
    `check`, given the file's status once it is open, may refuse it too (a secret's mode)."""
    try:
        # O_NONBLOCK: opening a FIFO would otherwise wait for a writer, for ever. A device
        # or a FIFO is refused below, before any read; a regular file ignores the flag.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        info = os.fstat(fd)  # of what was opened: the name may have changed since
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(f"{path}: {_file_type(info.st_mode)}, not {kind}")
        if check is not None:
            check(info)
        with open(fd, "rb", closefd=False) as file:
            # One byte more than the cap tells a file at the cap from one beyond it (or one
            # that grew since its size was taken).
            data = b"" if info.st_size > limit else file.read(limit + 1)
    finally:
        os.close(fd)
    if info.st_size > limit or len(data) > limit:
        raise ConfigError(f"{path}: larger than {limit:,} bytes, more than {kind} can need")
    return data


def _file_type(mode: int) -> str:
    kinds = [(stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
             (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"),
             (stat.S_ISSOCK, "a socket")]
    return next((name for test, name in kinds if test(mode)), "not a regular file")


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
