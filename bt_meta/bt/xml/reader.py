"""Loading BehaviorTree.CPP v4 XML into py_trees behaviours.

Offers:

* :func:`load_tree_file`, :func:`load_tree_text` -- XML -> root behaviour (BT.CPP semantics, monitors wrapped)
* :func:`resolve_document` -- XML -> :class:`ResolvedNode` tree (validated, SubTrees expanded, keys remapped),
  without building behaviours (``bt-meta show`` uses it)
* :class:`ResolvedNode` -- one validated node: type, name, ports as written and as resolved, children, position
* :func:`select_tree` -- which ``<BehaviorTree>`` to run: explicit ID, else ``main_tree_to_execute``, else the
  only one
* :func:`check_expansion` -- refuse SubTrees that expand beyond a size or depth bound, without expanding them

Syntax: compact (``<MoveTo goal="{g}"/>``) and explicit (``<Action ID="MoveTo" goal="{g}"/>``, ``<Condition ID>``,
``<Control ID>``, ``<Decorator ID>``); ``<SubTree ID="X" port="{key}" _autoremap="true"/>``; ``name`` sets the
behaviour's name; ``_monitor="false"`` keeps the loader from wrapping that Action in a monitor. The pre/post
conditions ``_skipIf`` ... ``_post`` are compiled here (syntax errors located) and attached to the behaviour (see
:mod:`bt_meta.bt.nodes.conditions`); every other attribute that does not start with a letter (Groot2's
``_collapsed``, ``_uid``) is ignored, as BT.CPP ignores it. Before resolving, SubTree expansion is bounded
(:func:`check_expansion`).

Blackboard scoping: every SubTree instance gets a private scope, as in BT.CPP. The reader rewrites each ``{key}``
inside a subtree to the key it denotes at the root: a remapped port ``p="{k}"`` maps ``{p}`` to the parent's ``k``
(``{=}`` = same name), ``_autoremap="true"`` maps every other key not starting with ``_`` to the same name in the
parent, ``{@k}`` is always the root's ``k``, a literal remapping ``p="3"`` initialises the private entry, and
anything else becomes a key private to that instance (``/_<TreeID>_<n>/key``, ``n`` unique in the process).

TreeNodesModel: an ID declared in ``<TreeNodesModel>`` but not registered is an error for :func:`load_tree_*`
(there is no implementation to instantiate) and names the model, unless ``stubs`` is given (``--stub-unknown``);
:func:`resolve_document` accepts it and checks the XML's ports against the declared ports (a port without a
default may be left out, as in BT.CPP), so a file can be inspected without the plugins that implement it. For
registered IDs the registry's ports are authoritative and the model is ignored. A ``<SubTree>`` model's port
defaults fill the ports a SubTree instance leaves out.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import py_trees

from bt_meta.bt.nodes import UNSUPPORTED_BUILTINS
from bt_meta.bt.nodes.conditions import POST_CONDITIONS, PRE_CONDITIONS, Conditions, attach_conditions
from bt_meta.bt.nodes.entries import BlackboardEnvironment
from bt_meta.bt.nodes.stubs import Stub, StubPolicy
from bt_meta.bt.nodes.subtree import SubTree
from bt_meta.bt.nodes.ticking import install_wake_up
from bt_meta.bt.registry import (
    CATEGORIES,
    NodeInstance,
    NodeRegistry,
    NodeType,
    PortError,
    PortSpec,
    RegistryError,
    UnknownNodeError,
    blackboard_key,
    default_registry,
)
from bt_meta.bt.script import CompiledScript, ScriptSyntaxError, compile_script
from bt_meta.bt.script.ast import Name
from bt_meta.bt.script.parser import walk
from bt_meta.bt.xml.document import ModelEntry, TreeDocument, TreeSources, XMLElement, parse_file, parse_text
from bt_meta.errors import BtMetaError, TreeXMLError

WrapAction = Callable[[py_trees.behaviour.Behaviour, NodeInstance], py_trees.behaviour.Behaviour]

_RESERVED = {"name", "ID"}
_CONDITION_ATTRIBUTES = (*PRE_CONDITIONS, *POST_CONDITIONS)
# Built-in ports whose literal value is a script, compiled at load so that a syntax error is located.
# Built-in ports that name a blackboard entry with a plain string (BT.CPP resolves it in the node's own scope).
_ENTRY_NAME_PORTS = {
    ("SetBlackboard", "output_key"),
    ("UnsetBlackboard", "key"),
    ("WasEntryUpdated", "entry"),
    ("SkipUnlessUpdated", "entry"),
    ("WaitValueUpdate", "entry"),
}
_SCRIPT_PORTS = {("Script", "code"), ("ScriptCondition", "code"), ("Precondition", "if")}
# Numbers SubTree instances across every load in this process: py_trees has one global blackboard, so two loaded
# trees must not share a private scope.
_INSTANCES = itertools.count(1)
_TRUE = {"true", "1"}
_FALSE = {"false", "0"}


def _model_factory(node_id: str) -> Callable[..., py_trees.behaviour.Behaviour]:
    def factory(**_kwargs: object) -> py_trees.behaviour.Behaviour:
        raise RegistryError(f"node {node_id!r} is only declared in <TreeNodesModel>; register an implementation")

    return factory


def _model_type(entry: ModelEntry) -> NodeType:
    return NodeType(
        entry.id, entry.category, list(entry.ports), _model_factory(entry.id), ports_optional=True  # type: ignore[arg-type]
    )


@dataclass
class ResolvedNode:
    """A validated node. ``ports`` are as written in the XML, ``resolved_ports`` have keys mapped to the root."""

    node_type: NodeType
    name: str
    ports: dict[str, str]
    resolved_ports: dict[str, str]
    line: int
    column: int
    children: list[ResolvedNode] = field(default_factory=list)
    monitor: bool = True
    subtree_id: str | None = None
    subtree_init: dict[str, str] = field(default_factory=dict)
    from_model: bool = False
    subtree_scope: str = ""
    # Pre/post-condition scripts (``_skipIf`` ...) and the root key of every name the node's scripts use.
    conditions: dict[str, CompiledScript] = field(default_factory=dict)
    script_keys: dict[str, str] = field(default_factory=dict)
    path: str | None = None  # the file the node was written in (trees can span several files)

    @property
    def id(self) -> str:
        return self.subtree_id or self.node_type.id

    @property
    def category(self) -> str:
        return self.node_type.category

    def instance(self, path: str) -> NodeInstance:
        attributes = {name: script.source for name, script in self.conditions.items()}
        return NodeInstance(
            self.id, self.category, dict(self.ports), self.monitor, self.line, path, attributes  # type: ignore[arg-type]
        )


class _Scope:
    """Maps keys written inside one SubTree instance to keys at the root."""

    def __init__(
        self,
        parent: _Scope | None = None,
        remap: dict[str, str] | None = None,
        autoremap: bool = False,
        prefix: str = "",
    ) -> None:
        self.parent = parent
        self.remap = remap or {}
        self.autoremap = autoremap
        self.prefix = prefix

    def resolve(self, key: str) -> str:
        if key.startswith("@"):
            return key[1:]
        if self.parent is None:
            return key
        if key in self.remap:
            target = self.remap[key]
            if target == "=":
                target = key
            return self.parent.resolve(target)
        if self.autoremap and not key.startswith("_"):
            # BT.CPP: _autoremap leaves keys that start with "_" private to the subtree
            return self.parent.resolve(key)
        return f"{self.prefix}/{key}"


def select_tree(document: TreeDocument, tree_id: str | None = None) -> str:
    if tree_id is not None:
        if tree_id not in document.trees:
            raise document.error(f"no <BehaviorTree ID={tree_id!r}>; trees: {', '.join(document.trees)}", document.root)
        return tree_id
    if document.main_tree is not None:
        return document.main_tree
    if len(document.trees) == 1:
        return next(iter(document.trees))
    raise document.error(
        f"several trees ({', '.join(document.trees)}) and no main_tree_to_execute; choose one by ID", document.root
    )


def _stub_type(node_id: str, category: str, ports: list[PortSpec], stubs: StubPolicy) -> NodeType:
    script = stubs.script(node_id)

    def factory(*, name: str, ports: dict[str, str], children: list[py_trees.behaviour.Behaviour]) -> Stub:
        return Stub(name, node_id, script)

    return NodeType(
        node_id, category, ports, factory, "stub (--stub-unknown)", children=(0, None), ports_optional=True  # type: ignore[arg-type]
    )


class _Resolver:
    def __init__(
        self, document: TreeDocument, registry: NodeRegistry, allow_models: bool, stubs: StubPolicy | None = None
    ) -> None:
        self.document = document
        self.registry = registry
        self.allow_models = allow_models
        self.stubs = stubs

    def error(self, message: str, element: XMLElement) -> TreeXMLError:
        return self.document.error(message, element)

    def node_type(self, element: XMLElement) -> tuple[NodeType, str | None, bool]:
        """The node type of an element, the explicit category if the explicit syntax was used, model flag."""
        explicit: str | None = None
        node_id = element.tag
        if element.tag in CATEGORIES and element.tag != "SubTree":
            explicit = element.tag
            node_id = element.attrib.get("ID", "")
            if not node_id:
                raise self.error(f"<{element.tag}> needs an ID attribute naming the node", element)
        if element.tag == "SubTree":
            return self.registry.get("SubTree"), None, False
        if node_id in self.registry:
            node_type = self.registry.get(node_id)
            from_model = False
        elif self.stubs is not None and (node_id in self.document.models or node_id not in UNSUPPORTED_BUILTINS):
            model = self.document.models.get(node_id)
            if model is not None:
                category, ports = model.category, list(model.ports)
            else:
                count = len(element.children)
                category = explicit or ("Action" if count == 0 else "Decorator" if count == 1 else "Control")
                ports = [PortSpec(attr) for attr in element.attrib if attr[:1].isalpha() and attr not in _RESERVED]
            node_type = _stub_type(node_id, category, ports, self.stubs)
            from_model = model is not None
        elif node_id in self.document.models:
            if not self.allow_models:
                model = self.document.models[node_id]
                raise self.error(
                    f"node {node_id!r} is declared in <TreeNodesModel> (line {model.line}) but not registered; "
                    "load the plugin that implements it",
                    element,
                )
            node_type = _model_type(self.document.models[node_id])
            from_model = True
        elif node_id in UNSUPPORTED_BUILTINS:
            raise self.error(f"BehaviorTree.CPP built-in {node_id!r} is not supported by bt-meta", element)
        else:
            try:
                self.registry.get(node_id)
            except UnknownNodeError as unknown:
                raise self.error(unknown.message, element) from None
            raise AssertionError("unreachable")
        if explicit is not None and node_type.category != explicit:
            raise self.error(f"node {node_id!r} is a {node_type.category}, not a {explicit}", element)
        return node_type, explicit, from_model

    def flags(self, element: XMLElement, name: str) -> bool | None:
        value = element.attrib.get(name)
        if value is None:
            return None
        lowered = value.strip().lower()
        if lowered in _TRUE:
            return True
        if lowered in _FALSE:
            return False
        raise self.error(f'{name}="{value}" must be "true" or "false"', element)

    def split_attributes(self, element: XMLElement, explicit: bool) -> dict[str, str]:
        """The ports an element writes. Attributes that do not start with a letter are not ports: BT.CPP reads
        the pre/post conditions among them and ignores the rest (editor metadata such as ``_collapsed``)."""
        ports: dict[str, str] = {}
        for attr, value in element.attrib.items():
            if attr in _RESERVED:
                continue
            if attr == "__shared_blackboard":
                raise self.error(
                    '__shared_blackboard is BehaviorTree.CPP v3 syntax; in v4 use _autoremap="true" or remap ports',
                    element,
                )
            if not attr[:1].isalpha():
                continue
            ports[attr] = value
        return ports

    def compile(self, text: str, what: str, element: XMLElement) -> CompiledScript:
        try:
            return compile_script(text)
        except ScriptSyntaxError as error:
            where = f"at character {error.offset + 1} of {text!r}"
            raise self.error(f"{what}: {error.message} ({where})", element) from None

    def scripts(
        self, element: XMLElement, node_type: NodeType, ports: dict[str, str], scope: _Scope
    ) -> tuple[dict[str, CompiledScript], dict[str, str]]:
        """Compile the element's condition attributes and script ports; map every name they use to a root key."""
        conditions = {
            attr: self.compile(element.attrib[attr], attr, element)
            for attr in _CONDITION_ATTRIBUTES
            if attr in element.attrib
        }
        compiled = list(conditions.values())
        if node_type.builtin:
            for port, text in ports.items():
                if (node_type.id, port) in _SCRIPT_PORTS and blackboard_key(text) is None and text != "":
                    compiled.append(self.compile(text, f"{node_type.id} {port}", element))
        keys: dict[str, str] = {}
        for script in compiled:
            for expr in script.exprs:
                for node in walk(expr):
                    if isinstance(node, Name) and node.name not in keys:
                        keys[node.name] = scope.resolve(node.name)
        return conditions, keys

    def resolve_ports(self, node_type: NodeType, ports: dict[str, str], scope: _Scope) -> dict[str, str]:
        resolved = {}
        for port, value in ports.items():
            key = blackboard_key(value)
            if key is None and node_type.builtin and (node_type.id, port) in _ENTRY_NAME_PORTS:
                # e.g. BT.CPP's SetBlackboard names its entry with a plain string, in the current (subtree) scope.
                resolved[port] = "{" + scope.resolve(value.strip()) + "}"
            elif key is None:
                resolved[port] = value
            else:
                resolved[port] = "{" + scope.resolve(port if key == "=" else key) + "}"
        return resolved

    def resolve_tree(self, tree_id: str, scope: _Scope, stack: tuple[str, ...]) -> ResolvedNode:
        element = self.document.trees[tree_id].children[0]
        return self.resolve(element, scope, (*stack, tree_id))

    def resolve(self, element: XMLElement, scope: _Scope, stack: tuple[str, ...]) -> ResolvedNode:
        node_type, explicit, from_model = self.node_type(element)
        monitor = self.flags(element, "_monitor")
        if element.tag == "SubTree":
            return self.resolve_subtree(element, node_type, scope, stack, monitor)
        if self.flags(element, "_autoremap") is not None:
            raise self.error("_autoremap is only valid on <SubTree>", element)
        ports = self.split_attributes(element, explicit is not None)
        try:
            completed = node_type.check_ports(ports)
        except PortError as error:
            raise self.error(error.message, element) from None
        low, high = node_type.children or (0, None)
        count = len(element.children)
        if count < low or (high is not None and count > high):
            if low == high:
                expected = f"exactly {low} child" + ("" if low == 1 else "ren")
            elif high is None:
                expected = f"at least {low} child" + ("" if low == 1 else "ren")
            else:
                expected = f"{low} to {high} children"
            raise self.error(
                f"{node_type.category} {node_type.id!r} needs {expected}, got {count}",
                element,
            )
        self.check_static(node_type, completed, count, element)
        conditions, script_keys = self.scripts(element, node_type, completed, scope)
        children = [self.resolve(child, scope, stack) for child in element.children]
        return ResolvedNode(
            node_type,
            element.attrib.get("name", node_type.id),
            ports,
            self.resolve_ports(node_type, completed, scope),
            element.line,
            element.column,
            children,
            monitor is not False,
            from_model=from_model,
            conditions=conditions,
            script_keys=script_keys,
            path=element.path,
        )

    def check_static(self, node_type: NodeType, ports: dict[str, str], count: int, element: XMLElement) -> None:
        """Errors BT.CPP only finds at tick time, reported at load time when the values are literals."""
        if node_type.id != "Parallel" or not node_type.builtin:
            return
        for port in ("success_count", "failure_count"):
            text = ports.get(port)
            if text is None or blackboard_key(text) is not None:
                continue
            value = int(text)
            needed = max(count + value + 1, 0) if value < 0 else value
            if needed > count:
                raise self.error(f"Parallel {port}={value} needs {needed} children, it has {count}", element)

    def resolve_subtree(
        self,
        element: XMLElement,
        node_type: NodeType,
        scope: _Scope,
        stack: tuple[str, ...],
        monitor: bool | None,
    ) -> ResolvedNode:
        tree_id = element.attrib.get("ID")
        if not tree_id:
            raise self.error("<SubTree> needs an ID attribute naming a <BehaviorTree>", element)
        if tree_id not in self.document.trees:
            known = ", ".join(self.document.trees)
            where = "these files" if len(self.document.files) > 1 else "this file"
            raise self.error(
                f"SubTree {tree_id!r} does not exist; trees in {where}: {known} (a tree in another file needs "
                '<include path="..."/> or the file on the command line)',
                element,
            )
        if tree_id in stack:
            cycle = " -> ".join((*stack[stack.index(tree_id) :], tree_id))
            raise self.error(f"recursive SubTree: {cycle}", element)
        if element.children:
            raise self.error("<SubTree> takes no child elements; its body is the <BehaviorTree> it names", element)
        autoremap = bool(self.flags(element, "_autoremap"))
        ports = self.split_attributes(element, True)
        model = self.document.models.get(tree_id)
        if model is not None and model.category == "SubTree":
            # BT.CPP 4: a SubTree's model gives defaults for the ports an instance leaves out.
            for spec in model.ports:
                if spec.name not in ports and spec.default is not None:
                    ports[spec.name] = spec.default
        remap: dict[str, str] = {}
        init: dict[str, str] = {}
        prefix = f"/_{tree_id}_{next(_INSTANCES)}"
        for port, value in ports.items():
            key = blackboard_key(value)
            if key is None:
                init[f"{prefix}/{port}"] = value
            else:
                remap[port] = key
        inner = _Scope(scope, remap, autoremap, prefix)
        conditions, script_keys = self.scripts(element, node_type, {}, scope)
        child = self.resolve_tree(tree_id, inner, stack)
        written = dict(ports)
        if element.attrib.get("_autoremap") is not None:
            written["_autoremap"] = element.attrib["_autoremap"]
        return ResolvedNode(
            node_type,
            element.attrib.get("name", tree_id),
            written,
            {"ID": tree_id},
            element.line,
            element.column,
            [child],
            monitor is not False,
            subtree_id=tree_id,
            subtree_init=init,
            subtree_scope=prefix,
            conditions=conditions,
            script_keys=script_keys,
            path=element.path,
        )


# Bounds on what SubTrees expand to, checked before anything is built: 22 trees each using the next one twice are
# 4 million nodes from 2 KB of XML.
MAX_EXPANDED_NODES = 100_000
MAX_EXPANDED_DEPTH = 256


def _own_shape(body: XMLElement) -> tuple[int, int, list[tuple[str, int]]]:
    """Elements in one tree body, its depth, and the SubTree IDs it uses with the depth they stand at."""
    count, depth, uses = 0, 0, []
    stack = [(body, 1)]
    while stack:
        element, level = stack.pop()
        count += 1
        depth = max(depth, level)
        if element.tag == "SubTree" and element.attrib.get("ID"):
            uses.append((element.attrib["ID"], level))
        stack.extend((child, level + 1) for child in element.children)
    return count, depth, uses


def check_expansion(document: TreeDocument, tree_id: str) -> None:
    """Refuse a tree whose SubTrees expand beyond :data:`MAX_EXPANDED_NODES` nodes or :data:`MAX_EXPANDED_DEPTH`
    levels (computed per tree, without expanding; cycles are left to the resolver, which names them)."""
    shapes = {tid: _own_shape(tree.children[0]) for tid, tree in document.trees.items()}
    sizes: dict[str, tuple[int, int]] = {}
    on_path: set[str] = set()
    stack: list[tuple[str, bool]] = [(tree_id, False)]
    while stack:
        current, expanded = stack.pop()
        if current in sizes or current not in shapes:
            continue
        count, depth, uses = shapes[current]
        if not expanded:
            on_path.add(current)
            stack.append((current, True))
            stack.extend((used, False) for used, _ in uses if used not in sizes and used not in on_path)
            continue
        on_path.discard(current)
        for used, level in uses:
            used_count, used_depth = sizes.get(used, (0, 0))
            count += used_count
            depth = max(depth, level + used_depth)
        sizes[current] = (count, depth)
    total, deepest = sizes.get(tree_id, (0, 0))
    element = document.trees[tree_id]
    if total > MAX_EXPANDED_NODES:
        raise document.error(
            f"tree {tree_id!r} expands to {total:,} nodes through its SubTrees (at most {MAX_EXPANDED_NODES:,})",
            element,
        )
    if deepest > MAX_EXPANDED_DEPTH:
        raise document.error(
            f"tree {tree_id!r} is {deepest} levels deep once its SubTrees are expanded (at most {MAX_EXPANDED_DEPTH})",
            element,
        )


def resolve_document(
    document: TreeDocument,
    registry: NodeRegistry | None = None,
    *,
    tree_id: str | None = None,
    allow_models: bool = True,
    stubs: StubPolicy | None = None,
) -> ResolvedNode:
    """Validate the selected tree (and the subtrees it uses) and return it as :class:`ResolvedNode` objects.

    With ``stubs``, a node nobody registered (declared in the model or not) becomes a :class:`Stub`."""
    registry = registry if registry is not None else default_registry()
    chosen = select_tree(document, tree_id)
    check_expansion(document, chosen)
    resolver = _Resolver(document, registry, allow_models, stubs)
    return resolver.resolve_tree(chosen, _Scope(), ())


def _build(
    node: ResolvedNode,
    registry: NodeRegistry,
    wrap_action: WrapAction | None,
    path: str,
) -> py_trees.behaviour.Behaviour:
    children = [_build(child, registry, wrap_action, path) for child in node.children]
    path = node.path or path
    instance = node.instance(path)
    try:
        if node.subtree_id is not None:
            behaviour: py_trees.behaviour.Behaviour = SubTree(
                node.name, children[0], node.subtree_id, node.subtree_init, node.subtree_scope
            )
            behaviour.bt_node = instance
        else:
            # A stub (--stub-unknown) is not in the registry: build it from its own node type.
            maker = registry if node.node_type.id in registry else NodeRegistry([node.node_type])
            behaviour = maker.create(
                node.node_type.id,
                name=node.name,
                ports={k: v for k, v in node.resolved_ports.items() if k in node.ports},
                children=children,
                instance=instance,
            )
    except TreeXMLError:
        raise
    except (BtMetaError, ValueError, TypeError) as error:
        # e.g. a CheckCondition whose condition does not parse: located here, at load, not at its first tick
        raise TreeXMLError(f"cannot build node {node.id!r}: {error}", path, node.line, node.column) from None
    monitored = node.category == "Action" and not node.node_type.builtin and node.monitor
    if wrap_action is not None and monitored and not isinstance(behaviour, Stub):  # a stub has nothing to monitor
        behaviour = wrap_action(behaviour, instance)
    env = BlackboardEnvironment(node.script_keys, registry.enums)
    bind = getattr(behaviour, "bind_environment", None)
    if bind is not None:
        bind(env)
    if node.conditions:
        attach_conditions(behaviour, Conditions(dict(node.conditions), env))
    return behaviour


def load_document(
    document: TreeDocument,
    registry: NodeRegistry | None = None,
    *,
    tree_id: str | None = None,
    wrap_action: WrapAction | None = None,
    wake_up: bool = True,
    stubs: StubPolicy | None = None,
) -> py_trees.behaviour.Behaviour:
    """Build the selected tree. ``wake_up`` installs BT.CPP's wake-up signal (see :mod:`bt_meta.bt.nodes.ticking`).

    ``wrap_action(behaviour, instance)`` is applied to every registered custom Action without
    ``_monitor="false"``; built-ins and Conditions are never wrapped. ``stubs``: see :func:`resolve_document`.
    """
    registry = registry if registry is not None else default_registry()
    resolved = resolve_document(document, registry, tree_id=tree_id, allow_models=False, stubs=stubs)
    root = _build(resolved, registry, wrap_action, document.path)
    if wake_up:
        install_wake_up(root)
    root.bt_root = True
    root.bt_tree_id = select_tree(document, tree_id)
    root.bt_document = document
    return root


def load_tree_text(
    text: str | bytes,
    registry: NodeRegistry | None = None,
    *,
    path: str = "<string>",
    tree_id: str | None = None,
    wrap_action: WrapAction | None = None,
    wake_up: bool = True,
) -> py_trees.behaviour.Behaviour:
    return load_document(parse_text(text, path), registry, tree_id=tree_id, wrap_action=wrap_action, wake_up=wake_up)


def load_tree_file(
    path: str | Path,
    registry: NodeRegistry | None = None,
    *,
    tree_id: str | None = None,
    wrap_action: WrapAction | None = None,
    wake_up: bool = True,
    sources: TreeSources | None = None,
    stubs: StubPolicy | None = None,
) -> py_trees.behaviour.Behaviour:
    """Load a tree file; ``sources`` adds an include search path and files whose trees the tree may use."""
    document = parse_file(path, sources)
    return load_document(document, registry, tree_id=tree_id, wrap_action=wrap_action, wake_up=wake_up, stubs=stubs)
