"""Inline SVG pictures of behaviour trees for the run and demo reports, drawn by hand (no graphviz binary needed).

The report's plots are matplotlib's (:mod:`bt_meta.plotting`); the tree stays hand-drawn: neither matplotlib nor
a package already installed lays out a tree with per-node status colours without a graphviz binary.

Offers:

* :class:`TreeNode` -- one behaviour of a py_trees tree as the picture needs it (name, kind, status, children)
* :func:`tree_from_behaviour` -- a py_trees tree to :class:`TreeNode` s, statuses from a node-id -> status map
* :func:`tree_svg` -- the tree as a left-to-right indented diagram, boxes coloured by status
* :data:`STATUS_COLOURS` -- the colour of each node status
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["STATUS_COLOURS", "TreeNode", "tree_from_behaviour", "tree_svg"]

STATUS_COLOURS = {
    "SUCCESS": "#4caf50",
    "FAILURE": "#e53935",
    "RUNNING": "#fbc02d",
    "INVALID": "#cfd8dc",
}



@dataclass
class TreeNode:
    """One behaviour: ``kind`` is the py_trees class name (Sequence, Monitor, CheckCondition, ...)."""

    name: str
    kind: str
    status: str = "INVALID"
    node_id: str | None = None
    children: list[TreeNode] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "status": self.status, "node_id": self.node_id,
                "children": [c.to_dict() for c in self.children]}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TreeNode:
        return cls(data["name"], data["kind"], data.get("status", "INVALID"), data.get("node_id"),
                   [cls.from_dict(c) for c in data.get("children", ())])


def _node_id(behaviour: Any) -> str | None:
    node_id = getattr(behaviour, "node_id", None)
    if node_id is None:
        decorated = getattr(behaviour, "decorated", None)
        node_id = getattr(decorated, "node_id", None)
    if node_id is None:
        first = str(behaviour.name).split(" ", 1)[0]
        if first.startswith("n") and first[1:].isdigit():
            node_id = first
    return node_id


def tree_from_behaviour(root: Any, statuses: Mapping[str, str], guards: Mapping[str, str] | None = None) -> TreeNode:
    """The tree under ``root``; leaves take their status from ``statuses`` (node id -> status, as the step events
    reported it), guards from ``guards`` (node id -> status), composites the status a Sequence derives from them."""
    guards = guards or {}

    def build(behaviour: Any) -> TreeNode:
        kind = type(behaviour).__name__
        node_id = _node_id(behaviour)
        children = list(getattr(behaviour, "children", []) or [])
        decorated = getattr(behaviour, "decorated", None)
        if decorated is not None:
            children = [decorated]
        node = TreeNode(str(behaviour.name), kind, node_id=node_id, children=[build(c) for c in children])
        for position, child in enumerate(node.children):
            if child.kind == "CheckCondition":  # a guard: failed when a failure names it, passed when work followed
                ran = any(c.status != "INVALID" for c in node.children[position + 1:])
                child.status = guards.get(child.node_id or "", "SUCCESS" if ran else "INVALID")
        if kind == "CheckCondition":
            pass  # set by the parent
        elif not node.children:
            node.status = statuses.get(node_id or "", "INVALID")
        elif decorated is not None:
            node.status = node.children[0].status
        else:
            node.status = _sequence_status([c.status for c in node.children])
        return node

    return build(root)


def _sequence_status(children: Sequence[str]) -> str:
    """A Sequence's status after its children finished their part: the first child that did not succeed decides."""
    for status in children:
        if status != "SUCCESS":
            return status if status in ("FAILURE", "RUNNING") else ("RUNNING" if any(
                s == "SUCCESS" for s in children) else "INVALID")
    return "SUCCESS" if children else "INVALID"


def _esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


def tree_svg(root: TreeNode, *, title: str = "") -> str:
    """The tree as an indented diagram (one row per behaviour, elbow edges), coloured by status."""
    rows: list[tuple[int, TreeNode, int | None]] = []

    def walk(node: TreeNode, depth: int, parent_row: int | None) -> None:
        row = len(rows)
        rows.append((depth, node, parent_row))
        for child in node.children:
            walk(child, depth + 1, row)

    walk(root, 0, None)
    indent, row_h, box_h, char_w = 22, 22, 17, 6.6
    width = max(max(int(d * indent + 30 + len(_label(n)) * char_w) for d, n, _ in rows) + 20,
                len(STATUS_COLOURS) * 90 + 10, int(len(title) * 7.5) + 10)
    top = 24 if title else 6
    height = top + row_h * len(rows) + 26
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="monospace" font-size="11">']
    if title:
        out.append(f'<text x="4" y="15" font-weight="bold">{_esc(title)}</text>')
    for row, (depth, node, parent_row) in enumerate(rows):
        x, y = 8 + depth * indent, top + row * row_h
        if parent_row is not None:
            px, py = 8 + (depth - 1) * indent + 6, top + parent_row * row_h + box_h
            out.append(f'<path d="M{px},{py} V{y + box_h / 2} H{x}" fill="none" stroke="#90a4ae"/>')
        label = _label(node)
        w = len(label) * char_w + 10
        colour = STATUS_COLOURS.get(node.status, STATUS_COLOURS["INVALID"])
        rx = 8 if node.kind in ("Monitor",) else 2
        out.append(f'<g><title>{_esc(node.kind)} {_esc(node.name)}: {_esc(node.status)}</title>'
                   f'<rect x="{x}" y="{y}" width="{w:.0f}" height="{box_h}" rx="{rx}" fill="{colour}" '
                   f'fill-opacity="0.85" stroke="#37474f" stroke-width="0.6"/>'
                   f'<text x="{x + 5}" y="{y + 12}">{_esc(label)}</text></g>')
    legend_y = top + row_h * len(rows) + 12
    lx = 8
    for status, colour in STATUS_COLOURS.items():
        out.append(f'<rect x="{lx}" y="{legend_y - 9}" width="10" height="10" fill="{colour}"/>'
                   f'<text x="{lx + 14}" y="{legend_y}">{status}</text>')
        lx += 90
    out.append("</svg>")
    return "".join(out)


def _label(node: TreeNode) -> str:
    prefix = {"Sequence": "→ ", "Monitor": "◉ ", "CheckCondition": "? "}.get(node.kind, "")
    if node.kind == "Monitor":
        return f"{prefix}Monitor"
    return f"{prefix}{node.name}"
