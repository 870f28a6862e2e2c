"""YAML read with limits: a config (or a `--set` value) that is too large, too deep, expands its aliases into too
many nodes (a "billion laughs" bomb), refers to itself, repeats a key or holds a number no config key can take is
refused with an InputError naming the file, the line and the limit, before anything is built from it.

PyYAML's own SafeLoader is used (never the C composer: it recurses without a limit on the C stack), with the
composer counting depth and nodes as it goes, and the node graph walked once (aliases counted as expanded,
cycles found) before it is constructed. Every limit is far above what a config needs (the largest shipped
config has a few hundred nodes, 6 levels) and low enough that reading any file takes well under a second.
"""

from __future__ import annotations

import yaml
from yaml.constructor import ConstructorError
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from ..core.errors import InputError, clip

MAX_BYTES = 256 << 10  # a config file (256 KiB: fifty times the largest shipped one)
MAX_DEPTH = 64  # nested mappings and lists
MAX_NODES = 20_000  # values, keys, mappings and lists, with every alias counted as the node it expands to
MAX_DIGITS = 400  # characters of an integer (1e308 is the largest float)


class _Refused(Exception):
    """A limit was exceeded at a node (its mark gives the line)."""

    def __init__(self, message: str, mark=None):
        super().__init__(message)
        self.mark = mark


class _LimitedLoader(yaml.SafeLoader):
    """SafeLoader whose composer stops at MAX_DEPTH levels and MAX_NODES nodes, and whose integers are bounded."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0

    def compose_node(self, parent, index):
        self._depth += 1
        self._nodes += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(f"nested more than {MAX_DEPTH} levels deep", self.peek_event().start_mark)
            if self._nodes > MAX_NODES:
                raise _Refused(
                    f"more than {MAX_NODES} values (a config holds a few hundred)", self.peek_event().start_mark
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_yaml_int(self, node):
        text = str(node.value)
        if len(text) > MAX_DIGITS:
            raise ConstructorError(
                None, None, f"an integer of {len(text)} characters (at most {MAX_DIGITS})", node.start_mark
            )
        return super().construct_yaml_int(node)


_LimitedLoader.add_constructor("tag:yaml.org,2002:int", _LimitedLoader.construct_yaml_int)


def _line(mark) -> str:
    return f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""


def _walk(root: Node) -> None:
    """Raise _Refused for a cycle (an alias inside its own anchor), more than MAX_NODES nodes with aliases
    expanded, or a key given twice in one mapping (YAML keeps the last one silently)."""
    sizes: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        ident = id(node)
        if done:
            on_path.discard(ident)
            children = _children(node)
            sizes[ident] = 1 + sum(sizes[id(c)] for c in children)
            if sizes[ident] > MAX_NODES:
                raise _Refused(f"its aliases expand to more than {MAX_NODES} values (an alias bomb?)", node.start_mark)
            continue
        if ident in sizes:
            continue
        if ident in on_path:
            raise _Refused(
                "an alias refers to the mapping or list that holds it (a circular reference)", node.start_mark
            )
        on_path.add(ident)
        stack.append((node, True))
        if isinstance(node, MappingNode):
            _check_keys(node)
        for child in _children(node):
            if id(child) in on_path:
                raise _Refused(
                    "an alias refers to the mapping or list that holds it (a circular reference)", child.start_mark
                )
            if id(child) not in sizes:
                stack.append((child, False))


def _children(node: Node) -> list[Node]:
    if isinstance(node, SequenceNode):
        return list(node.value)
    if isinstance(node, MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _check_keys(node: MappingNode) -> None:
    seen: set[tuple[str, str]] = set()
    for key, _ in node.value:
        if isinstance(key, ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
            ident = (key.tag, key.value)
            if ident in seen:
                raise _Refused(f"key {clip(repr(key.value))} is given twice in one mapping", key.start_mark)
            seen.add(ident)


def load_yaml(text: str, source: str, what: str = "not valid YAML") -> object:
    """The YAML document in `text` as plain data, or an InputError naming `source`, the line and the problem
    (`what` starts the message: "not valid YAML")."""
    if len(text) > MAX_BYTES:
        raise InputError(f"{len(text)} characters of YAML, more than a config may hold ({MAX_BYTES})", source=source)
    loader = None
    try:
        loader = _LimitedLoader(text)  # its reader refuses control characters at once
        node = loader.get_single_node()
        if node is None:
            return None
        _walk(node)
        return loader.construct_document(node)
    except _Refused as exc:
        raise InputError(f"refused{_line(exc.mark)}: {exc}", source=source) from None
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow (a NUL, a control character)
        where = text[: exc.position]
        line, column = where.count("\n") + 1, exc.position - (where.rfind("\n") + 1) + 1
        raise InputError(
            f"{what} at line {line}, column {column}: character #x{exc.character:04x} is not allowed in YAML",
            source=source,
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        problem = " ".join(str(problem).split())  # one line
        raise InputError(f"{what}{_line(mark)}: {clip(problem)}", source=source) from None
    except RecursionError:  # a guard: MAX_DEPTH keeps the composer and the constructor far from the limit
        raise InputError(f"refused: nested too deeply (at most {MAX_DEPTH} levels)", source=source) from None
    finally:
        if loader is not None:
            loader.dispose()
