"""YAML for user files: composed with bounds checked while composing, constructed with only the safe tags.

PyYAML's composer and constructor recurse once per nesting level, aliases let a small file stand for a huge
document (a "billion laughs"), a control character gives a two-line message without a position, and a bad tagged
value (``!!int xyz``) escapes as a bare ``ValueError``. This module turns each of those into one
``path:line:column: message`` error of the caller's :class:`~bt_meta.errors.UserInputError` class, before the
expensive work: depth and alias count are counted as the events arrive, so the composer never recurses past
:data:`MAX_YAML_DEPTH` and stops at the first alias past :data:`MAX_YAML_ALIASES`.

Offers:

* :data:`MAX_YAML_DEPTH`, :data:`MAX_YAML_ALIASES`, :data:`MAX_YAML_EXPANDED_NODES` -- the bounds
* :func:`compose_yaml` -- text to a node tree (positions kept), or ``None`` for an empty document
* :func:`construct_yaml` -- a node to JSON-like Python values (plain tags only), errors located
* :func:`load_yaml` -- both (for files whose positions are not needed after loading)
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import yaml

from bt_meta.errors import UserInputError

MAX_YAML_DEPTH = 64
MAX_YAML_ALIASES = 1000
MAX_YAML_EXPANDED_NODES = 200_000


class _BoundError(yaml.MarkedYAMLError):
    """A bound of this module was passed (a YAML error so it is reported like the others)."""


class _BoundedLoader(yaml.SafeLoader):
    """The pure-Python safe loader, counting nesting depth and aliases as the composer meets them."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self.depth = 0
        self.aliases = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            self.aliases += 1
            if self.aliases > MAX_YAML_ALIASES:
                raise _BoundError(problem=f"more than {MAX_YAML_ALIASES} aliases (*name) in one file",
                                  problem_mark=event.start_mark)
            return super().compose_node(parent, index)
        if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            if self.depth >= MAX_YAML_DEPTH:
                raise _BoundError(problem=f"nested deeper than {MAX_YAML_DEPTH} levels", problem_mark=event.start_mark)
            self.depth += 1
            try:
                return super().compose_node(parent, index)
            finally:
                self.depth -= 1
        return super().compose_node(parent, index)


_PLAIN_TAGS = frozenset(f"tag:yaml.org,2002:{name}" for name in ("null", "bool", "int", "float", "str", "seq", "map"))
_TIMESTAMP_TAG = "tag:yaml.org,2002:timestamp"


class _LocatingConstructor(yaml.constructor.SafeConstructor):
    """The safe constructor limited to JSON-like values, any error a tagged value raises turned into a located
    ``ConstructorError``. A date or time is kept as the text written (values must stay JSON-able for traces);
    ``!!set``, ``!!binary``, ``!!omap``, ``!!pairs`` and every other tag are refused."""

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        if node.tag == _TIMESTAMP_TAG and isinstance(node, yaml.ScalarNode):
            return node.value
        if node.tag not in _PLAIN_TAGS:
            raise yaml.constructor.ConstructorError(
                None, None,
                f"the tag {_shown_tag(node.tag)} is not allowed here (only plain values, lists and mappings)",
                node.start_mark)
        try:
            return super().construct_object(node, deep=deep)
        except yaml.YAMLError:
            raise
        except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError) as exc:
            raise yaml.constructor.ConstructorError(
                None, None, f"cannot read the {_shown_tag(node.tag)} value {_short(node)}: {type(exc).__name__}",
                node.start_mark) from None


def _shown_tag(tag: str) -> str:
    """``tag:yaml.org,2002:int`` as the ``!!int`` a user wrote."""
    prefix = "tag:yaml.org,2002:"
    return "!!" + tag[len(prefix):] if tag.startswith(prefix) else tag


def _short(node: yaml.Node) -> str:
    if isinstance(node, yaml.ScalarNode):
        text = node.value if len(node.value) <= 40 else node.value[:40] + "..."
        return repr(text)
    return "here"


def _located(exc: yaml.YAMLError, path: str, error: type[UserInputError], text: str = "",
             syntax: str = "YAML syntax error") -> UserInputError:
    if isinstance(exc, yaml.reader.ReaderError):
        code = ord(exc.character) if isinstance(exc.character, str) else int(exc.character)
        before = text[: exc.position]
        line, column = before.count("\n") + 1, exc.position - (before.rfind("\n") + 1) + 1
        return error(f"control character #x{code:04x} is not allowed in YAML", path, line, column)
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or exc.context or "not valid YAML"
        if isinstance(exc, _BoundError):
            message = f"YAML error: {problem}"
        elif isinstance(exc, yaml.constructor.ConstructorError):
            message = f"YAML tag error: {problem}"
        else:
            message = f"{syntax}: {problem}"
            if exc.context and exc.problem:
                message += f" ({exc.context})"
        if mark is None:
            return error(message, path)
        return error(message, path, mark.line + 1, mark.column + 1)
    return error(f"YAML error: {type(exc).__name__}", path)


def compose_yaml(text: str, path: str, error: type[UserInputError] = UserInputError, *,
                 syntax: str = "YAML syntax error") -> yaml.Node | None:
    """The node tree of ``text`` (one document), every bound checked; ``None`` for an empty document.

    ``syntax`` starts the message of a syntax error (each file format keeps the wording its docs show).
    The same text composed again in the same process is the tree composed the first time (see
    :func:`_remembered`): a campaign worker reads the same task file and scene for episode after episode.
    """
    key = (text, path, error, syntax)
    root = _remembered(key)
    if root is not _MISSING:
        return root
    root = _compose(text, path, error, syntax)
    _remember(key, text, root)
    return root


_MISSING: Any = object()
_COMPOSED: OrderedDict[tuple[Any, ...], yaml.Node | None] = OrderedDict()
_COMPOSED_KEPT = 32
_COMPOSED_LARGEST = 256 * 1024  # characters: task files and scenes are a few KiB; a huge file is not kept


def _remembered(key: tuple[Any, ...]) -> Any:
    """A tree composed before from the same text, path and wording, or ``_MISSING``. Callers only read the
    trees; the one thing that mutates one is the constructor's merge-key flattening (``<<``), so texts that may
    hold a merge key are never remembered. ``BT_META_MODEL_CACHE=0`` turns this off (:mod:`bt_meta.model_cache`).
    """
    from bt_meta.model_cache import enabled

    if not enabled() or key not in _COMPOSED:
        return _MISSING
    _COMPOSED.move_to_end(key)
    return _COMPOSED[key]


def _remember(key: tuple[Any, ...], text: str, root: yaml.Node | None) -> None:
    from bt_meta.model_cache import enabled

    if not enabled() or len(text) > _COMPOSED_LARGEST or "<<" in text or "merge" in text:
        return
    _COMPOSED[key] = root
    while len(_COMPOSED) > _COMPOSED_KEPT:  # the least recently used go: a worker meets many variant scenes
        _COMPOSED.popitem(last=False)


def _compose(text: str, path: str, error: type[UserInputError], syntax: str) -> yaml.Node | None:
    loader = None
    try:
        loader = _BoundedLoader(text)  # the reader checks for control characters here
        root = loader.get_single_node()
    except yaml.YAMLError as exc:
        raise _located(exc, path, error, text, syntax) from None
    except RecursionError:  # pragma: no cover - the depth bound keeps the composer far from the limit
        raise error(f"YAML error: nested deeper than {MAX_YAML_DEPTH} levels", path) from None
    finally:
        if loader is not None:
            loader.dispose()
    if root is not None:
        _check_expanded_size(root, path, error)
    return root


def _check_expanded_size(root: yaml.Node, path: str, error: type[UserInputError]) -> None:
    """Refuse a document whose aliases expand to more than :data:`MAX_YAML_EXPANDED_NODES` nodes, or that holds
    itself (an alias inside its own anchor). Sizes are counted once per distinct node, bottom up, so the check is
    linear in the file however much the aliases multiply."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        if id(node) in sizes:
            continue
        children = _children(node)
        if children_done or not children:
            open_nodes.discard(id(node))
            total = 1 + sum(sizes[id(child)] for child in children)
            sizes[id(node)] = total
            if total > MAX_YAML_EXPANDED_NODES:
                raise error(f"YAML error: the aliases expand to more than {MAX_YAML_EXPANDED_NODES} values", path,
                            node.start_mark.line + 1, node.start_mark.column + 1)
            continue
        if id(node) in open_nodes:
            raise error("YAML error: an alias refers to a collection that contains it (a recursive structure)", path,
                        node.start_mark.line + 1, node.start_mark.column + 1)
        open_nodes.add(id(node))
        stack.append((node, True))
        for child in children:
            if id(child) in open_nodes:
                raise error("YAML error: an alias refers to a collection that contains it (a recursive structure)",
                            path, child.start_mark.line + 1, child.start_mark.column + 1)
            if id(child) not in sizes:
                stack.append((child, False))


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def construct_yaml(node: yaml.Node, path: str, error: type[UserInputError] = UserInputError) -> Any:
    """Plain Python values (dict, list, str, int, float, bool, None, dates) of ``node``; any other tag, a bad
    tagged value or a bad merge key is a located ``error``."""
    constructor = _LocatingConstructor()
    try:
        return constructor.construct_document(node)
    except yaml.YAMLError as exc:
        raise _located(exc, path, error) from None
    except RecursionError:  # pragma: no cover - compose_yaml bounds the depth
        raise error(f"YAML error: nested deeper than {MAX_YAML_DEPTH} levels", path) from None


def load_yaml(text: str, path: str, error: type[UserInputError] = UserInputError, *,
              syntax: str = "YAML syntax error") -> Any:
    """``compose_yaml`` then ``construct_yaml``: the document's values, ``None`` when it is empty."""
    root = compose_yaml(text, path, error, syntax=syntax)
    return None if root is None else construct_yaml(root, path, error)
