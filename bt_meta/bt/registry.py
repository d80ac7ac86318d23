"""Node types and the registry the XML loader and the compiler instantiate behaviours from.

BehaviorTree.CPP identifies every node by an ID and declares its ports; the XML only names IDs and fills ports
with literals or ``{key}`` blackboard references. This module is that vocabulary for bt-meta.

Offers:

* :class:`PortSpec` -- one declared port: name, direction, BehaviorTree.CPP type name, default
* :class:`NodeType` -- an ID, its category, its ports and the factory that builds the py_trees behaviour
* :class:`NodeInstance` -- what one node of a tree says in XML (ID, category, ports as written); behaviours carry
  it as ``behaviour.bt_node`` so the writer can write them back
* :class:`NodeRegistry` -- IDs to node types; :meth:`NodeRegistry.create` validates ports and builds a behaviour
* :func:`default_registry` -- a registry holding every BehaviorTree.CPP built-in node bt-meta implements
* :func:`blackboard_key` -- ``"{key}"`` -> ``"key"`` (``None`` for a literal)
* :class:`UnknownNodeError`, :class:`PortError` -- raised by the registry (the XML reader adds file positions)

Factory contract: ``factory(name=str, ports={port: value}, children=[Behaviour, ...]) -> Behaviour``. ``ports``
holds every declared port that was given or has a default, as strings: a literal, or ``"{key}"`` where ``key`` is
already resolved to a blackboard key valid at the root of the tree (the loader applies SubTree remapping before
calling the factory). ``bt_node.ports`` keeps the values exactly as written in the XML instead.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Literal

import py_trees

from bt_meta.errors import BtMetaError

Direction = Literal["input", "output", "inout"]
Category = Literal["Action", "Condition", "Control", "Decorator", "SubTree"]
CATEGORIES: tuple[str, ...] = ("Action", "Condition", "Control", "Decorator", "SubTree")
DIRECTIONS: tuple[str, ...] = ("input", "output", "inout")

# BehaviorTree.CPP spells a blackboard reference "{key}"; "{=}" means "the key named like the port".
_KEY_RE = re.compile(r"^\{\s*([^{}\s]+)\s*\}$")

Factory = Callable[..., py_trees.behaviour.Behaviour]


class RegistryError(BtMetaError):
    """A node type or a port does not fit the registry (the XML reader turns it into a located TreeXMLError)."""


class UnknownNodeError(RegistryError, KeyError):
    """An ID nobody registered; the message lists the closest known IDs."""

    def __init__(self, node_id: str, known: list[str]) -> None:
        self.node_id = node_id
        self.known = known
        close = difflib.get_close_matches(node_id, known, n=3, cutoff=0.6)
        hint = f"did you mean {', '.join(close)}?" if close else f"known IDs: {', '.join(sorted(known))}"
        self.message = f"unknown node ID {node_id!r}; {hint}"
        RegistryError.__init__(self, self.message)

    def __str__(self) -> str:  # KeyError would quote the message
        return self.message


class PortError(RegistryError):
    """A missing required port, an undeclared port, or a literal that does not convert to the port's type."""

    def __init__(self, message: str, port: str | None = None) -> None:
        self.message = message
        self.port = port
        super().__init__(message)


def blackboard_key(value: str | None) -> str | None:
    """Return ``key`` for a ``"{key}"`` port value, ``None`` for a literal."""
    if value is None:
        return None
    match = _KEY_RE.match(value.strip())
    return match.group(1) if match else None


_TRUE = {"true", "1", "yes", "on"}
_FALSE = {"false", "0", "no", "off"}
_INT_TYPES = {"int", "int32_t", "int64_t", "long", "short", "std::int32_t", "std::int64_t"}
_UINT_TYPES = {"unsigned", "unsigned int", "uint32_t", "uint64_t", "size_t", "std::size_t", "unsigned long"}
_FLOAT_TYPES = {"double", "float"}


@dataclass(frozen=True)
class PortSpec:
    """One declared port. A port with no default whose direction reads a value is required."""

    name: str
    direction: Direction = "input"
    type_name: str = "std::string"
    default: str | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if self.direction not in DIRECTIONS:
            raise RegistryError(f"port {self.name!r}: direction must be one of {', '.join(DIRECTIONS)}")

    @property
    def required(self) -> bool:
        return self.default is None and self.direction != "output"

    def convert(self, text: str) -> Any:
        """Convert a literal to the port's Python value; ``ValueError`` names the port and expected type."""
        value = text.strip()
        type_name = self.type_name.strip()
        try:
            if type_name in _INT_TYPES:
                return int(value, 10)
            if type_name in _UINT_TYPES:
                number = int(value, 10)
                if number < 0:
                    raise ValueError
                return number
            if type_name in _FLOAT_TYPES:
                return float(value)
            if type_name in ("BT::NodeStatus", "NodeStatus"):
                if value not in ("SUCCESS", "FAILURE", "RUNNING", "SKIPPED"):
                    raise ValueError
                return value
            if type_name == "bool":
                lowered = value.lower()
                if lowered in _TRUE:
                    return True
                if lowered in _FALSE:
                    return False
                raise ValueError
        except ValueError:
            raise ValueError(f"port {self.name!r} expects {type_name}, got {text!r}") from None
        return text

    def validate(self, text: str) -> None:
        """Check a port value as written: a ``{key}`` is always fine, a literal must convert."""
        if blackboard_key(text) is None:
            self.convert(text)


@dataclass
class NodeType:
    """A node ID with its category, declared ports and the factory building its behaviour."""

    id: str
    category: Category
    ports: list[PortSpec]
    factory: Factory
    description: str = ""
    builtin: bool = False
    # How many children the XML must give: (minimum, maximum or None for unbounded).
    children: tuple[int, int | None] | None = None
    # Ports without a default may be left out (BT.CPP's rule for a <TreeNodesModel> declaration: a missing port is
    # an error only when the node reads it).
    ports_optional: bool = False

    def __post_init__(self) -> None:
        if self.category not in CATEGORIES:
            raise RegistryError(f"node type {self.id!r}: category must be one of {', '.join(CATEGORIES)}")
        if not self.id or not re.match(r"^[A-Za-z_][A-Za-z0-9_:.\-]*$", self.id):
            raise RegistryError(f"node type ID {self.id!r} is not a valid XML/BehaviorTree.CPP identifier")
        names = [p.name for p in self.ports]
        if len(names) != len(set(names)):
            raise RegistryError(f"node type {self.id!r} declares a port twice")
        if self.children is None:
            self.children = {
                "Action": (0, 0),
                "Condition": (0, 0),
                "Decorator": (1, 1),
                "Control": (1, None),
                "SubTree": (0, 0),
            }[self.category]

    def port(self, name: str) -> PortSpec | None:
        for spec in self.ports:
            if spec.name == name:
                return spec
        return None

    @property
    def port_names(self) -> list[str]:
        return [p.name for p in self.ports]

    def check_ports(self, given: dict[str, str]) -> dict[str, str]:
        """Validate ports as written and return them completed with defaults; raises :class:`PortError`."""
        for name, value in given.items():
            spec = self.port(name)
            if spec is None:
                known = ", ".join(self.port_names) or "none"
                raise PortError(f"node {self.id!r} has no port {name!r} (ports: {known})", name)
            try:
                spec.validate(value)
            except ValueError as error:
                raise PortError(f"node {self.id!r}: {error}", name) from None
        completed: dict[str, str] = {}
        for spec in self.ports:
            if spec.name in given:
                completed[spec.name] = given[spec.name]
            elif spec.default is not None:
                completed[spec.name] = spec.default
            elif spec.required and not self.ports_optional:
                raise PortError(f"node {self.id!r} is missing required port {spec.name!r}", spec.name)
        return completed


@dataclass
class NodeInstance:
    """What one node of a tree says in XML: its ID, category and ports exactly as written.

    ``monitor`` is ``False`` when the XML opted out with ``_monitor="false"``; ``line`` is the XML line the node
    came from (``None`` for compiled trees). For a SubTree, ``id`` is the subtree's ID and ``ports`` its remapping
    (``_autoremap`` included when given).
    """

    id: str
    category: Category
    ports: dict[str, str] = field(default_factory=dict)
    monitor: bool = True
    line: int | None = None
    path: str | None = None
    # Pre/post-condition attributes as written (``_skipIf`` ...): not ports, but written back with the node.
    attributes: dict[str, str] = field(default_factory=dict)


class NodeRegistry:
    """Node IDs to :class:`NodeType`. Registering an ID twice is an error unless ``replace=True``."""

    def __init__(self, types: list[NodeType] | None = None) -> None:
        self._types: dict[str, NodeType] = {}
        # Script enums (BT.CPP's registerScriptingEnum): a name scripts read as a number.
        self.enums: dict[str, int] = {}
        for node_type in types or []:
            self.register(node_type)

    def register_enum(self, name: str, value: int) -> None:
        """Let scripts use ``name`` for ``value`` (BT.CPP's ``registerScriptingEnum``)."""
        if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", name):
            raise RegistryError(f"enum name {name!r} is not an identifier")
        self.enums[name] = int(value)

    def register(self, node_type: NodeType, *, replace: bool = False) -> NodeType:
        if not replace and node_type.id in self._types:
            raise RegistryError(f"node ID {node_type.id!r} is already registered")
        self._types[node_type.id] = node_type
        return node_type

    def get(self, node_id: str) -> NodeType:
        try:
            return self._types[node_id]
        except KeyError:
            raise UnknownNodeError(node_id, list(self._types)) from None

    def __contains__(self, node_id: object) -> bool:
        return node_id in self._types

    def __iter__(self) -> Iterator[NodeType]:
        return iter(self._types.values())

    def __len__(self) -> int:
        return len(self._types)

    def ids(self) -> list[str]:
        return list(self._types)

    def custom_types(self) -> list[NodeType]:
        """Node types that are not BehaviorTree.CPP built-ins (they need a TreeNodesModel entry in XML)."""
        return [t for t in self._types.values() if not t.builtin]

    def copy(self) -> NodeRegistry:
        clone = NodeRegistry()
        clone._types = dict(self._types)
        return clone

    def create(
        self,
        node_id: str,
        *,
        name: str | None = None,
        ports: dict[str, str] | None = None,
        children: list[py_trees.behaviour.Behaviour] | None = None,
        instance: NodeInstance | None = None,
    ) -> py_trees.behaviour.Behaviour:
        """Validate ports and children, call the factory and attach ``bt_node``.

        ``ports`` are the values the factory receives (keys already resolved); ``instance`` is what the writer
        will write (defaults to the same ports).
        """
        node_type = self.get(node_id)
        given = dict(ports or {})
        completed = node_type.check_ports(given)
        kids = list(children or [])
        low, high = node_type.children or (0, None)
        if len(kids) < low or (high is not None and len(kids) > high):
            expected = str(low) if low == high else f"at least {low}" if high is None else f"{low} to {high}"
            raise RegistryError(f"node {node_id!r} ({node_type.category}) needs {expected} children, got {len(kids)}")
        behaviour = node_type.factory(name=name or node_id, ports=completed, children=kids)
        if getattr(behaviour, "bt_node", None) is None:
            behaviour.bt_node = instance or NodeInstance(node_id, node_type.category, given)
        return behaviour


def default_registry() -> NodeRegistry:
    """A fresh registry with every BehaviorTree.CPP built-in node bt-meta implements (see :mod:`bt_meta.bt.nodes`)."""
    from bt_meta.bt.nodes import builtin_node_types

    return NodeRegistry(builtin_node_types())
