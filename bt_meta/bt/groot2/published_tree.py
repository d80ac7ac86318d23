"""A py_trees tree seen as BehaviorTree.CPP's ``BT::Tree``: node uids, subtrees, blackboards, full-tree XML.

Groot2 knows a tree only through what BehaviorTree.CPP's publisher tells it, so we number and describe our
behaviours exactly as BehaviorTree.CPP would have built them from the same XML:

* **uids** count from 1 in depth-first pre-order over the expanded tree (a ``SubTree`` node, then its subtree's
  nodes, then its next sibling), as ``Tree::getUID()`` is called while ``XMLParser`` creates nodes;
* **subtrees** (``Tree::subtrees``) are listed root first, then in the order their SubTree nodes were created; each
  has an instance name -- the main tree's is empty (published under its ID), a SubTree's is its parent's name,
  ``/``, then its ``name`` attribute or ``ID::uid``. The STATUS reply lists nodes subtree by subtree;
* a bt-meta **Monitor** is not a BehaviorTree.CPP node: it is folded into the action it wraps, and the status shown
  for that action is the monitor's (what the parent sees);
* **blackboards**: py_trees has one; the XML reader gives every SubTree instance a private key prefix
  (``SubTree.scope``). A subtree's blackboard is its private entries, plus -- as BehaviorTree.CPP creates an entry
  for every ``{key}`` port at load time -- the keys its nodes use that land in its own scope, shown as ``null``
  until written.

Offers:

* :class:`PublishedNode`, :class:`PublishedSubtree`, :class:`PublishedTree` (:meth:`PublishedTree.build`)
* :func:`json_value` -- a blackboard value as BehaviorTree.CPP's JSON exporter would write it (``None`` = unknown)
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import Any

import py_trees

from bt_meta.bt.nodes.conditions import POST_CONDITIONS, PRE_CONDITIONS
from bt_meta.bt.nodes.subtree import SubTree
from bt_meta.bt.registry import NodeInstance, NodeRegistry, NodeType, PortSpec, blackboard_key
from bt_meta.bt.xml.writer import describe
from bt_meta.errors import BtMetaError

Behaviour = py_trees.behaviour.Behaviour

# BehaviorTree.CPP's pre- and post-condition attributes, written after the ports in its enum order (PreCond, then
# PostCond), as ``WriteTreeToXML`` does.
CONDITION_ATTRIBUTES = (*PRE_CONDITIONS, *POST_CONDITIONS)
_INTERNAL_PREFIX = "/bt_meta/"
# Port types whose blackboard entries BehaviorTree.CPP stores converted: a string written there becomes a number.
_TYPED = {"int", "unsigned int", "int32_t", "int64_t", "uint32_t", "uint64_t", "long", "unsigned", "size_t",
          "double", "float", "bool"}
_SUBTREE_MODEL = ("SubTree", [PortSpec("_autoremap", "input", "bool", "false",
                                       "If true, all the ports with the same name will be remapped")])


class PublishError(BtMetaError):
    """A tree that cannot be published to Groot2 (too many nodes for 16-bit uids, a node with no XML form)."""


@dataclass
class PublishedNode:
    """One BehaviorTree.CPP node: ``behaviour`` carries the status shown, ``node`` is the node itself."""

    uid: int
    behaviour: Behaviour
    node: Behaviour
    registration_name: str
    name: str
    category: str
    path: str
    attributes: dict[str, str]
    subtree_id: str | None = None
    children: list[PublishedNode] = field(default_factory=list)


@dataclass
class PublishedSubtree:
    """One ``Tree::Subtree``: its tree ID, instance name, private blackboard prefix and nodes in uid order."""

    tree_id: str
    instance_name: str
    scope: str
    nodes: list[PublishedNode] = field(default_factory=list)
    # Entries BehaviorTree.CPP creates at load for {key} ports, with the port that typed them (None: untyped).
    declared_keys: dict[str, PortSpec | None] = field(default_factory=dict)
    initial_values: dict[str, str] = field(default_factory=dict)
    remap: dict[str, str] = field(default_factory=dict)
    autoremap: bool = False
    parent: PublishedSubtree | None = None

    @property
    def published_name(self) -> str:
        """The name Groot2 asks for in a BLACKBOARD request."""
        return self.instance_name or self.tree_id

    def resolve(self, key: str) -> tuple[PublishedSubtree, str]:
        """The subtree whose blackboard holds ``key`` written in this subtree, and its name there."""
        if key.startswith("@"):
            root: PublishedSubtree = self
            while root.parent is not None:
                root = root.parent
            return root, key[1:]
        if self.parent is None:
            return self, key
        if key in self.remap:
            target = blackboard_key(self.remap[key])
            if target is not None:
                return self.parent.resolve(key if target == "=" else target)
            return self, key  # a literal remapping is a local entry
        if self.autoremap:
            return self.parent.resolve(key)
        return self, key


def json_value(value: Any) -> Any:
    """BehaviorTree.CPP's ``JsonExporter``: strings, integers (bools become 0/1), doubles and vectors of those."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, (list, tuple)) and value:
        kinds = {str if isinstance(v, str) else bool if isinstance(v, bool) else type(v) for v in value}
        if len(kinds) == 1 and kinds <= {str, bool, int, float}:
            return list(value)
    return None


def _monitor_chain(behaviour: Behaviour) -> Behaviour:
    while getattr(behaviour, "is_monitor", False) and len(behaviour.children) == 1:
        behaviour = behaviour.children[0]
    return behaviour


def _conditions(instance: NodeInstance) -> dict[str, str]:
    return {k: instance.attributes[k] for k in CONDITION_ATTRIBUTES if k in instance.attributes}


def _allowed_port_name(name: str) -> bool:
    return bool(name) and name[0].isalpha() and name not in ("name", "ID")


class _Builder:
    def __init__(self, registry: NodeRegistry | None) -> None:
        self.registry = registry
        self.nodes: list[PublishedNode] = []
        self.subtrees: list[PublishedSubtree] = []
        self.used: dict[str, tuple[str, list[PortSpec]]] = {}

    def node_type(self, node_id: str) -> NodeType | None:
        if self.registry is not None and node_id in self.registry:
            return self.registry.get(node_id)
        return None

    def subtree(self, tree_id: str, instance_name: str, scope: str, body: Behaviour,
                parent: PublishedSubtree | None, remap: dict[str, str], autoremap: bool,
                initial: dict[str, str]) -> tuple[PublishedSubtree, PublishedNode]:
        subtree = PublishedSubtree(tree_id, instance_name, scope, remap=remap, autoremap=autoremap, parent=parent,
                                   initial_values=initial)
        # BehaviorTree.CPP writes literal remappings as strings before creating the subtree's nodes: untyped.
        subtree.declared_keys.update(dict.fromkeys(initial))
        self.subtrees.append(subtree)
        prefix = f"{instance_name}/" if instance_name else ""
        return subtree, self.step(body, subtree, prefix)

    def attributes(self, instance: NodeInstance, node_type: NodeType | None) -> dict[str, str]:
        """Ports as BehaviorTree.CPP keeps them: as written, plus declared defaults (inputs; outputs if ``{key}``),
        and the pre/post-condition scripts as written."""
        written = {k: v for k, v in instance.ports.items() if _allowed_port_name(k)}
        if node_type is not None:
            for spec in node_type.ports:
                if spec.name in written or spec.default in (None, ""):
                    continue
                if spec.direction != "output" or blackboard_key(spec.default) is not None:
                    written[spec.name] = spec.default
        return written | _conditions(instance)

    def note_model(self, instance: NodeInstance, node_type: NodeType | None) -> None:
        if node_type is not None:
            self.used.setdefault(instance.id, (node_type.category, list(node_type.ports)))
            return
        ports = [PortSpec(name) for name in instance.ports if _allowed_port_name(name)]
        self.used.setdefault(instance.id, (instance.category, ports))

    def step(self, behaviour: Behaviour, subtree: PublishedSubtree, prefix: str) -> PublishedNode:
        node = _monitor_chain(behaviour)
        try:
            instance = describe(node)
        except BtMetaError as error:
            raise PublishError(str(error)) from None
        uid = len(self.nodes) + 1
        if uid > 0xFFFF:
            raise PublishError("Groot2 numbers nodes with 16 bits: this tree has more than 65535 nodes")
        if instance.category == "SubTree":
            return self.subtree_node(behaviour, node, instance, subtree, prefix, uid)
        node_type = self.node_type(instance.id)
        path = prefix + node.name + (f"::{uid}" if node.name == instance.id else "")
        published = PublishedNode(uid, behaviour, node, instance.id, node.name, instance.category, path,
                                  self.attributes(instance, node_type))
        self.nodes.append(published)
        subtree.nodes.append(published)
        self.note_model(instance, node_type)
        for port, value in instance.ports.items():  # written ports create entries at load; defaults do not
            key = blackboard_key(value) if _allowed_port_name(port) else None
            if key is not None:
                holder, name = subtree.resolve(port if key == "=" else key)
                spec = node_type.port(port) if node_type is not None else None
                if name not in holder.declared_keys:  # the first port to create an entry types it
                    holder.declared_keys[name] = spec if spec is not None and spec.type_name in _TYPED else None
        for child in node.children:
            published.children.append(self.step(child, subtree, prefix))
        return published

    def subtree_node(self, behaviour: Behaviour, node: Behaviour, instance: NodeInstance,
                     subtree: PublishedSubtree, prefix: str, uid: int) -> PublishedNode:
        tree_id = instance.id
        named = node.name != tree_id
        path = prefix + node.name + ("" if named else f"::{uid}")
        ports = {k: v for k, v in instance.ports.items() if _allowed_port_name(k)}
        published = PublishedNode(uid, behaviour, node, "SubTree", node.name, "SubTree", path,
                                  ports | _conditions(instance), tree_id)
        self.nodes.append(published)
        subtree.nodes.append(published)
        self.used.setdefault("SubTree", _SUBTREE_MODEL)
        if len(node.children) != 1:
            raise PublishError(f"SubTree {node.name!r} must have exactly one child (its tree's root)")
        parent_name = subtree.instance_name
        own = node.name if named else f"{tree_id}::{uid}"
        instance_name = f"{parent_name}/{own}" if parent_name else own
        autoremap = str(instance.ports.get("_autoremap", "false")).strip().lower() in ("true", "1")
        scope = getattr(node, "scope", "") if isinstance(node, SubTree) else ""
        initial = {k: v for k, v in ports.items() if blackboard_key(v) is None}
        _child_tree, root = self.subtree(tree_id, instance_name, scope, node.children[0], subtree,
                                         {k: v for k, v in ports.items() if blackboard_key(v) is not None},
                                         autoremap, initial)
        published.children.append(root)
        return published


class PublishedTree:
    """A py_trees tree numbered and described as BehaviorTree.CPP would build it (see the module docstring)."""

    def __init__(self, root: PublishedNode, tree_id: str, nodes: list[PublishedNode],
                 subtrees: list[PublishedSubtree], models: dict[str, tuple[str, list[PortSpec]]]) -> None:
        self.root = root
        self.tree_id = tree_id
        self.nodes = nodes
        self.subtrees = subtrees
        self.models = models

    @classmethod
    def build(cls, root: Behaviour, *, registry: NodeRegistry | None = None,
              tree_id: str | None = None) -> PublishedTree:
        """Number ``root``'s nodes; ``registry`` supplies declared ports, defaults and the TreeNodesModel."""
        main_id = tree_id or getattr(root, "bt_tree_id", None) or "MainTree"
        builder = _Builder(registry)
        _subtree, top = builder.subtree(main_id, "", "", root, None, {}, False, {})
        models = dict(builder.used)
        if registry is not None:
            for node_type in registry:
                if node_type.id == "SubTree" and node_type.builtin:
                    models.setdefault("SubTree", _SUBTREE_MODEL)
                    continue
                models.setdefault(node_type.id, (node_type.category, list(node_type.ports)))
        return cls(top, main_id, builder.nodes, builder.subtrees, models)

    def status_order(self) -> list[PublishedNode]:
        """Nodes in the order of BehaviorTree.CPP's status buffer: subtree by subtree, pre-order within each."""
        return [node for subtree in self.subtrees for node in subtree.nodes]

    def subtree_named(self, name: str) -> PublishedSubtree | None:
        for subtree in self.subtrees:
            if subtree.published_name == name:
                return subtree
        return None

    def blackboard(self, subtree: PublishedSubtree) -> dict[str, Any]:
        """The entries of one subtree's blackboard as BehaviorTree.CPP's JSON export (``None`` = not exportable)."""
        storage = py_trees.blackboard.Blackboard.storage
        private = [s.scope + "/" for s in self.subtrees if s.scope]
        values: dict[str, Any] = {key: None for key in subtree.declared_keys}
        for key, value in subtree.initial_values.items():
            values[key] = self._typed(subtree, key, value)
        for key, value in list(storage.items()):
            if subtree.scope:
                if not key.startswith(subtree.scope + "/"):
                    continue
                name = key[len(subtree.scope) + 1 :]
            else:
                if key.startswith(_INTERNAL_PREFIX) or any(key.startswith(p) for p in private):
                    continue
                name = key[1:] if key.startswith("/") else key
            values[name] = self._typed(subtree, name, value)
        return values

    @staticmethod
    def _typed(subtree: PublishedSubtree, name: str, value: Any) -> Any:
        spec = subtree.declared_keys.get(name)
        if spec is not None and isinstance(value, str):
            with contextlib.suppress(ValueError):  # BT.CPP would have refused the write; show the text
                value = spec.convert(value)
        return json_value(value)
