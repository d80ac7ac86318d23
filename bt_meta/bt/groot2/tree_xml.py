"""The full-tree XML Groot2 receives, laid out as BehaviorTree.CPP's ``WriteTreeToXML(tree, true, true)`` prints it.

Groot2 draws the tree from this text and matches statuses to nodes by their ``_uid`` attribute, so it carries
BehaviorTree.CPP's metadata: one ``<BehaviorTree ID _fullpath>`` per subtree instance (the main tree's
``_fullpath`` is empty), every node as ``<RegistrationName name _uid ports...>`` (a SubTree as
``<SubTree ID _fullpath _uid ports...>``, its body in its own ``<BehaviorTree>``), then a ``<TreeNodesModel>`` with
one entry per node type, sorted by ID. Layout follows TinyXML2's printer (4-space indent, no XML declaration,
``&apos;``-style escaping in attributes) so a byte comparison with BehaviorTree.CPP only differs where
BehaviorTree.CPP's own order is a hash-map order (ports).

Offers:

* :func:`full_tree_xml` -- :class:`~bt_meta.bt.groot2.published_tree.PublishedTree` -> XML text
"""

from __future__ import annotations

from bt_meta.bt.groot2.published_tree import CONDITION_ATTRIBUTES, PublishedNode, PublishedTree
from bt_meta.bt.registry import PortSpec

_INDENT = "    "


def _attribute(text: str) -> str:
    return (text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")
            .replace("'", "&apos;"))


def _text(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _open(tag: str, attributes: list[tuple[str, str]]) -> str:
    return "<" + tag + "".join(f' {name}="{_attribute(value)}"' for name, value in attributes)


def _node_attributes(node: PublishedNode) -> list[tuple[str, str]]:
    subtree = node.subtree_id is not None
    head = [("ID", str(node.subtree_id)), ("_fullpath", node.path)] if subtree else [("name", node.name)]
    head.append(("_uid", str(node.uid)))
    ports = sorted((k, v) for k, v in node.attributes.items() if k not in CONDITION_ATTRIBUTES)
    conditions = [(k, node.attributes[k]) for k in CONDITION_ATTRIBUTES if k in node.attributes]
    return head + ports + conditions


def _write_node(node: PublishedNode, depth: int, lines: list[str]) -> None:
    pad = _INDENT * depth
    start = _open(node.registration_name, _node_attributes(node))
    children = [] if node.subtree_id is not None else node.children
    if not children:
        lines.append(pad + start + "/>")
        return
    lines.append(pad + start + ">")
    for child in children:
        _write_node(child, depth + 1, lines)
    lines.append(f"{pad}</{node.registration_name}>")


def _write_model(node_id: str, category: str, ports: list[PortSpec], lines: list[str]) -> None:
    pad = _INDENT * 2
    start = _open(category, [("ID", node_id)])
    if not ports:
        lines.append(pad + start + "/>")
        return
    lines.append(pad + start + ">")
    for port in ports:
        attributes = [("name", port.name)]
        if port.type_name:
            attributes.append(("type", port.type_name))
        if port.default not in (None, ""):
            attributes.append(("default", str(port.default)))
        element = _open(f"{port.direction}_port", attributes)
        if port.description:
            lines.append(f"{pad}{_INDENT}{element}>{_text(port.description)}</{port.direction}_port>")
        else:
            lines.append(f"{pad}{_INDENT}{element}/>")
    lines.append(f"{pad}</{category}>")


def full_tree_xml(tree: PublishedTree) -> str:
    """The FULLTREE reply body (and the XML a ``.btlog`` file starts with)."""
    lines = ['<root BTCPP_format="4">']
    for subtree in tree.subtrees:
        lines.append(_INDENT + _open("BehaviorTree", [("ID", subtree.tree_id), ("_fullpath", subtree.instance_name)])
                     + ">")
        _write_node(subtree.nodes[0], 2, lines)
        lines.append(_INDENT + "</BehaviorTree>")
    if not tree.models:
        lines.append(_INDENT + "<TreeNodesModel/>")
    else:
        lines.append(_INDENT + "<TreeNodesModel>")
        for node_id in sorted(tree.models):
            category, ports = tree.models[node_id]
            _write_model(node_id, category, ports, lines)
        lines.append(_INDENT + "</TreeNodesModel>")
    lines.append("</root>")
    return "\n".join(lines) + "\n"
