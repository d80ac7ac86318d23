"""Decomposition trees: the planner's record of which method decomposed which task, with bindings and states.

Offers:

* :class:`DecompositionNode` -- one task occurrence: id, ground task, kind, method, bindings, children, parent,
  the state before it, and (primitives) its index in the plan
* :class:`DecompositionTree` -- nodes by id and roots; :meth:`~DecompositionTree.walk` (pre-order,
  iterative), :meth:`~DecompositionTree.primitives` (plan order), :meth:`~DecompositionTree.to_dict`
  (JSON-able) and :meth:`~DecompositionTree.pretty` (indented text)
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from bt_meta.htn.state import State, atom_text

MAX_INDENT = 40  # deeper levels print their depth instead of ever more indentation


@dataclass(slots=True)
class DecompositionNode:
    id: str
    task: tuple[str, ...]
    kind: str  # "compound" or "primitive"
    method: str | None
    bindings: dict[str, str]
    parent: str | None
    state_before: State
    step: int | None = None
    children: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.task[0]

    @property
    def args(self) -> tuple[str, ...]:
        return tuple(self.task[1:])

    def label(self) -> str:
        return atom_text(self.task)

    def to_dict(self, states: bool = False) -> dict[str, Any]:
        data: dict[str, Any] = {
            "id": self.id,
            "task": list(self.task),
            "kind": self.kind,
            "method": self.method,
            "bindings": dict(self.bindings),
            "parent": self.parent,
            "children": list(self.children),
            "step": self.step,
        }
        if states:
            data["state_before"] = self.state_before.to_list()
        return data


class DecompositionTree:
    def __init__(self, nodes: dict[str, DecompositionNode], roots: list[str]) -> None:
        self.nodes = nodes
        self.roots = roots

    def __len__(self) -> int:
        return len(self.nodes)

    def __getitem__(self, node_id: str) -> DecompositionNode:
        return self.nodes[node_id]

    def walk(self, start: str | None = None) -> Iterator[DecompositionNode]:
        """Pre-order, left to right, without recursion (trees can be 10,000+ levels deep)."""
        stack = [start] if start is not None else list(reversed(self.roots))
        while stack:
            node = self.nodes[stack.pop()]
            yield node
            stack.extend(reversed(node.children))

    def depth(self, node_id: str) -> int:
        depth = 0
        parent = self.nodes[node_id].parent
        while parent is not None:
            depth += 1
            parent = self.nodes[parent].parent
        return depth

    def ancestors(self, node_id: str) -> list[DecompositionNode]:
        """Parent first, root last."""
        result = []
        parent = self.nodes[node_id].parent
        while parent is not None:
            node = self.nodes[parent]
            result.append(node)
            parent = node.parent
        return result

    def primitives(self, start: str | None = None) -> list[DecompositionNode]:
        """Primitive nodes in plan order (of the whole tree, or under ``start``)."""
        found = [n for n in self.walk(start) if n.kind == "primitive"]
        found.sort(key=lambda n: n.step if n.step is not None else -1)
        return found

    def to_dict(self, states: bool = False) -> dict[str, Any]:
        """``{"roots": [...], "nodes": [node, ...]}`` with nodes in pre-order; states only when asked."""
        return {"roots": list(self.roots), "nodes": [node.to_dict(states) for node in self.walk()]}

    def pretty(self, indent: str = "  ") -> str:
        """Indented text, one node a line; below depth ``MAX_INDENT`` the depth is written instead of indented."""
        lines: list[str] = []
        stack: list[tuple[str, int]] = [(root, 0) for root in reversed(self.roots)]
        while stack:
            node_id, level = stack.pop()
            node = self.nodes[node_id]
            if node.kind == "primitive":
                detail = f"  [step {node.step}]"
            else:
                shown = ", ".join(f"?{k}={v}" for k, v in node.bindings.items())
                detail = f"  [method {node.method}{'; ' + shown if shown else ''}]"
            shown_level = min(level, MAX_INDENT)
            deeper = f"[depth {level}] " if level > MAX_INDENT else ""
            lines.append(f"{indent * shown_level}{deeper}{node.id} {node.label()}{detail}")
            stack.extend((child, level + 1) for child in reversed(node.children))
        return "\n".join(lines)
