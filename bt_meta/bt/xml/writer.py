"""Writing py_trees behaviour trees as BehaviorTree.CPP v4 XML that Groot2 and BehaviorTree.CPP open.

Offers:

* :func:`tree_to_xml` -- root behaviour -> XML text (``<root BTCPP_format="4">``, one ``<BehaviorTree>`` per tree
  and SubTree, a ``<TreeNodesModel>`` entry with ports for every custom node)
* :func:`write_tree` -- the same into a file
* :class:`TreeWriteError` -- a behaviour that has no XML form

What is written for each behaviour:

* a behaviour carrying ``bt_node`` (:class:`~bt_meta.bt.registry.NodeInstance`): its ID, ports as written,
  ``name`` when it differs from the ID, ``_monitor="false"`` when it opted out; SubTree bodies become their own
  ``<BehaviorTree>``
* a monitor (``is_monitor = True``): its child only -- monitors are implicit in XML, the loader adds them back
* bt-meta's BT.CPP node classes built by hand (no ``bt_node``): their BT.CPP ID
* py_trees built-ins, mapped to the BT.CPP node with the same tick semantics:
  ``Sequence(memory=True)`` -> ``Sequence`` (both resume at the RUNNING child and restart at 0 after a failure;
  *not* ``SequenceWithMemory``, which retries the failed child), ``Sequence(memory=False)`` ->
  ``ReactiveSequence``, ``Selector(memory=True)`` -> ``Fallback``, ``Selector(memory=False)`` ->
  ``ReactiveFallback``, ``Parallel(SuccessOnAll)`` -> ``Parallel success_count=-1 failure_count=1``,
  ``Parallel(SuccessOnOne)`` -> ``success_count=1 failure_count=1``, ``Inverter``, ``FailureIsSuccess`` ->
  ``ForceSuccess``, ``SuccessIsFailure`` -> ``ForceFailure``, ``Repeat(num_success)`` -> ``Repeat num_cycles``,
  ``Retry(num_failures)`` -> ``RetryUntilSuccessful num_attempts``, ``Timeout(duration)`` -> ``Timeout msec``,
  ``behaviours.Success``/``Failure`` -> ``AlwaysSuccess``/``AlwaysFailure``. py_trees' versions differ from BT.CPP in
  details (re-entry resets, one loop iteration per tick), so a round trip through XML yields BT.CPP semantics.
  Anything else raises :class:`TreeWriteError` naming the behaviour.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import py_trees

from bt_meta.bt import nodes as bt_nodes
from bt_meta.bt.registry import NodeInstance, NodeRegistry, PortSpec, default_registry
from bt_meta.errors import BtMetaError

Behaviour = py_trees.behaviour.Behaviour


class TreeWriteError(BtMetaError):
    """A behaviour that cannot be written as BehaviorTree.CPP XML."""


_OWN_CLASSES: dict[type, tuple[str, str]] = {
    bt_nodes.Sequence: ("Sequence", "Control"),
    bt_nodes.SequenceWithMemory: ("SequenceWithMemory", "Control"),
    bt_nodes.ReactiveSequence: ("ReactiveSequence", "Control"),
    bt_nodes.Fallback: ("Fallback", "Control"),
    bt_nodes.ReactiveFallback: ("ReactiveFallback", "Control"),
    bt_nodes.Parallel: ("Parallel", "Control"),
    bt_nodes.Inverter: ("Inverter", "Decorator"),
    bt_nodes.ForceSuccess: ("ForceSuccess", "Decorator"),
    bt_nodes.ForceFailure: ("ForceFailure", "Decorator"),
    bt_nodes.KeepRunningUntilFailure: ("KeepRunningUntilFailure", "Decorator"),
    bt_nodes.Repeat: ("Repeat", "Decorator"),
    bt_nodes.RetryUntilSuccessful: ("RetryUntilSuccessful", "Decorator"),
    bt_nodes.Timeout: ("Timeout", "Decorator"),
    bt_nodes.AlwaysSuccess: ("AlwaysSuccess", "Action"),
    bt_nodes.AlwaysFailure: ("AlwaysFailure", "Action"),
}


def _port_text(value: object) -> str:
    text = getattr(value, "text", None)
    return str(text) if text is not None else str(value)


def _own_ports(behaviour: Behaviour) -> dict[str, str]:
    if isinstance(behaviour, bt_nodes.Parallel):
        return {
            "success_count": _port_text(behaviour.success_count),
            "failure_count": _port_text(behaviour.failure_count),
        }
    if isinstance(behaviour, bt_nodes.Repeat):
        return {"num_cycles": _port_text(behaviour.num_cycles)}
    if isinstance(behaviour, bt_nodes.RetryUntilSuccessful):
        return {"num_attempts": _port_text(behaviour.num_attempts)}
    if isinstance(behaviour, bt_nodes.Timeout):
        return {"msec": _port_text(behaviour.msec)}
    return {}


def _pytrees_builtin(behaviour: Behaviour) -> NodeInstance | None:
    composites = py_trees.composites
    decorators = py_trees.decorators
    behaviours = py_trees.behaviours
    if type(behaviour) is composites.Sequence:
        return NodeInstance("Sequence" if behaviour.memory else "ReactiveSequence", "Control")
    if type(behaviour) is composites.Selector:
        return NodeInstance("Fallback" if behaviour.memory else "ReactiveFallback", "Control")
    if type(behaviour) is composites.Parallel:
        policy = behaviour.policy
        if isinstance(policy, py_trees.common.ParallelPolicy.SuccessOnAll):
            return NodeInstance("Parallel", "Control", {"success_count": "-1", "failure_count": "1"})
        if isinstance(policy, py_trees.common.ParallelPolicy.SuccessOnOne):
            return NodeInstance("Parallel", "Control", {"success_count": "1", "failure_count": "1"})
        return None
    simple = {
        decorators.Inverter: "Inverter",
        decorators.FailureIsSuccess: "ForceSuccess",
        decorators.SuccessIsFailure: "ForceFailure",
    }
    if type(behaviour) in simple:
        return NodeInstance(simple[type(behaviour)], "Decorator")
    if type(behaviour) is decorators.Repeat:
        return NodeInstance("Repeat", "Decorator", {"num_cycles": str(behaviour.num_success)})
    if type(behaviour) is decorators.Retry:
        return NodeInstance("RetryUntilSuccessful", "Decorator", {"num_attempts": str(behaviour.num_failures)})
    if type(behaviour) is decorators.Timeout:
        return NodeInstance("Timeout", "Decorator", {"msec": str(round(behaviour.duration * 1000))})
    if type(behaviour) is behaviours.Success:
        return NodeInstance("AlwaysSuccess", "Action")
    if type(behaviour) is behaviours.Failure:
        return NodeInstance("AlwaysFailure", "Action")
    return None


def describe(behaviour: Behaviour) -> NodeInstance:
    """The :class:`NodeInstance` the writer uses for ``behaviour`` (raises :class:`TreeWriteError`)."""
    instance = getattr(behaviour, "bt_node", None)
    if isinstance(instance, NodeInstance):
        if instance.category == "SubTree" and instance.id == "SubTree" and "ID" in instance.ports:
            # Built with registry.create("SubTree", ports={"ID": ...}): the ID port names the tree.
            ports = {k: v for k, v in instance.ports.items() if k != "ID"}
            return NodeInstance(instance.ports["ID"], "SubTree", ports, instance.monitor, instance.line, instance.path)
        return instance
    for cls, (node_id, category) in _OWN_CLASSES.items():
        if type(behaviour) is cls:
            return NodeInstance(node_id, category, _own_ports(behaviour))  # type: ignore[arg-type]
    if isinstance(behaviour, bt_nodes.SubTree):
        return NodeInstance(behaviour.tree_id, "SubTree", {})
    mapped = _pytrees_builtin(behaviour)
    if mapped is not None:
        return mapped
    raise TreeWriteError(
        f"cannot write behaviour {behaviour.name!r} ({type(behaviour).__module__}.{type(behaviour).__qualname__}) "
        "as BehaviorTree.CPP XML: give it a bt_node (NodeInstance) or build it from the node registry"
    )


def _unwrap(behaviour: Behaviour) -> Behaviour:
    while getattr(behaviour, "is_monitor", False):
        if len(behaviour.children) != 1:
            raise TreeWriteError(f"monitor {behaviour.name!r} must have exactly one child to be written")
        behaviour = behaviour.children[0]
    return behaviour


class _Writer:
    def __init__(self, registry: NodeRegistry) -> None:
        self.registry = registry
        self.trees: dict[str, ET.Element] = {}
        self.pending: list[tuple[str, Behaviour]] = []
        self.custom: dict[str, tuple[str, list[PortSpec]]] = {}

    def element(self, behaviour: Behaviour) -> ET.Element:
        behaviour = _unwrap(behaviour)
        instance = describe(behaviour)
        if instance.category == "SubTree":
            return self.subtree(behaviour, instance)
        attrib: dict[str, str] = {}
        if behaviour.name != instance.id:
            attrib["name"] = behaviour.name
        attrib.update(instance.ports)
        attrib.update(instance.attributes)
        if not instance.monitor:
            attrib["_monitor"] = "false"
        element = ET.Element(instance.id, attrib)
        self.note_custom(instance)
        if instance.category in ("Control", "Decorator"):
            if not behaviour.children:
                raise TreeWriteError(f"{instance.category} {behaviour.name!r} ({instance.id}) has no children")
            for child in behaviour.children:
                element.append(self.element(child))
        return element

    def subtree(self, behaviour: Behaviour, instance: NodeInstance) -> ET.Element:
        attrib = {"ID": instance.id}
        if behaviour.name != instance.id:
            attrib["name"] = behaviour.name
        attrib.update(instance.ports)
        attrib.update(instance.attributes)
        if not instance.monitor:
            attrib["_monitor"] = "false"
        if len(behaviour.children) != 1:
            raise TreeWriteError(f"SubTree {behaviour.name!r} must have exactly one child (the subtree's root)")
        if instance.id not in self.trees and all(tree_id != instance.id for tree_id, _ in self.pending):
            self.pending.append((instance.id, behaviour.children[0]))
        return ET.Element("SubTree", attrib)

    def note_custom(self, instance: NodeInstance) -> None:
        if instance.id in self.registry:
            node_type = self.registry.get(instance.id)
            if node_type.builtin:
                return
            self.custom.setdefault(instance.id, (node_type.category, list(node_type.ports)))
            return
        ports = [PortSpec(name) for name in instance.ports]
        _category, known = self.custom.setdefault(instance.id, (instance.category, ports))
        names = {p.name for p in known}
        known.extend(p for p in ports if p.name not in names)

    def tree(self, tree_id: str, behaviour: Behaviour) -> None:
        body = ET.Element("BehaviorTree", {"ID": tree_id})
        self.trees[tree_id] = body
        body.append(self.element(behaviour))

    def model(self) -> ET.Element:
        model = ET.Element("TreeNodesModel")
        for node_id in sorted(self.custom):
            category, ports = self.custom[node_id]
            entry = ET.SubElement(model, category, {"ID": node_id})
            for port in ports:
                attrib = {"name": port.name, "type": port.type_name}
                if port.default is not None:
                    attrib["default"] = port.default
                port_element = ET.SubElement(entry, f"{port.direction}_port", attrib)
                if port.description:
                    port_element.text = port.description
        return model


def tree_to_xml(
    root: Behaviour,
    *,
    tree_id: str | None = None,
    registry: NodeRegistry | None = None,
) -> str:
    """Return ``root`` as BehaviorTree.CPP v4 XML; ``tree_id`` defaults to the loaded tree's ID or ``MainTree``."""
    registry = registry if registry is not None else default_registry()
    main_id = tree_id or getattr(root, "bt_tree_id", None) or "MainTree"
    writer = _Writer(registry)
    writer.tree(main_id, root)
    while writer.pending:
        sub_id, body = writer.pending.pop(0)
        if sub_id not in writer.trees:
            writer.tree(sub_id, body)
    document = ET.Element("root", {"BTCPP_format": "4", "main_tree_to_execute": main_id})
    for body in writer.trees.values():
        document.append(body)
    document.append(writer.model())
    ET.indent(document, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(document, encoding="unicode") + "\n"


def write_tree(
    root: Behaviour,
    path: str | Path,
    *,
    tree_id: str | None = None,
    registry: NodeRegistry | None = None,
) -> Path:
    path = Path(path)
    path.write_text(tree_to_xml(root, tree_id=tree_id, registry=registry), encoding="utf-8")
    return path
