"""Replanning from a failed decomposition node, keeping the executed prefix (in the spirit of IPyHOP).

Offers:

* :func:`replan` -- re-decompose from a failed node of a :class:`~bt_meta.htn.tree.DecompositionTree`

What it does, precisely:

1. The *failed step* ``s`` is the failed node's plan index (a primitive), or, for a compound node, the number
   of primitives before it in pre-order. The *executed prefix* is every primitive with a step below ``s``;
   those primitives and all their ancestors are kept with their ids, methods and bindings.
2. Candidates are tried from the bottom up: the failed node's parent (or the failed node itself when it is
   compound), then each ancestor up to the root.
3. For a candidate ``X`` the planner runs, from the given current ``state``, on the agenda
   ``[X.task] + continuation(X)``. ``X.task`` may use every method and binding *except* the
   (method, bindings) pair ``X`` used before -- "the remaining methods and bindings", enumerated again in
   the current state. ``continuation(X)`` is the tasks that came after ``X`` in the old tree: ``X``'s later
   siblings, then its parent's later siblings, and so on up to the later root tasks; they are planned afresh
   because the state has changed.
4. The first candidate with a plan wins. The new tree keeps the executed nodes and the ancestors of ``X``;
   the new decomposition of ``X.task`` takes ``X``'s place under its parent when ``X`` had nothing executed,
   or becomes ``X``'s last child when part of ``X`` had been executed (that part stays visible). The planned
   continuation tasks become children of their old parents. New nodes get fresh ids after the largest old
   one; new primitives are numbered after the executed prefix.
5. If the failed node is a primitive at the root of the task network, the only candidate is the remaining
   task network itself (the failed primitive and the later root tasks), planned afresh.
6. When no candidate has a plan the result is ``no_plan``; the node and time budgets cover the whole climb.
"""

from __future__ import annotations

import time
from typing import Any

from bt_meta.errors import PlanningError
from bt_meta.htn.conditions import ExternalFn
from bt_meta.htn.model import Domain
from bt_meta.htn.planner import TASK, GroundAction, PlanResult, Search
from bt_meta.htn.state import Atom, State
from bt_meta.htn.tree import DecompositionNode, DecompositionTree


def _failed_step(tree: DecompositionTree, node_id: str) -> int:
    node = tree.nodes[node_id]
    if node.kind == "primitive" and node.step is not None:
        return node.step
    count = 0
    for visited in tree.walk():
        if visited.id == node_id:
            return count
        if visited.kind == "primitive":
            count += 1
    return count


def _later_siblings(tree: DecompositionTree, node: DecompositionNode) -> list[DecompositionNode]:
    siblings = tree.nodes[node.parent].children if node.parent is not None else tree.roots
    position = siblings.index(node.id)
    return [tree.nodes[s] for s in siblings[position + 1:]]


def _continuation(tree: DecompositionTree, node: DecompositionNode) -> list[tuple]:
    items: list[tuple] = []
    cursor: DecompositionNode | None = node
    while cursor is not None:
        for sibling in _later_siblings(tree, cursor):
            items.append((TASK, sibling.task, cursor.parent, None))
        cursor = tree.nodes[cursor.parent] if cursor.parent is not None else None
    return items


def _numeric_id(node_id: str) -> int:
    digits = node_id.lstrip("n")
    return int(digits) if digits.isdigit() else -1


def replan(domain: Domain, tree: DecompositionTree, failed_node_id: str, state: State, *,
           max_nodes: int | None = None, max_seconds: float | None = None, external: ExternalFn | None = None,
           goal: list[Atom] | None = None) -> PlanResult:
    """Re-decompose from ``failed_node_id`` in the current ``state``; see the module docstring."""
    if failed_node_id not in tree.nodes:
        raise PlanningError(f"no node {failed_node_id!r} in the decomposition tree")
    started = time.perf_counter()
    failed = tree.nodes[failed_node_id]
    step = _failed_step(tree, failed_node_id)
    executed = [p for p in tree.primitives() if p.step is not None and p.step < step]
    touched: set[str] = set()
    for prim in executed:
        touched.add(prim.id)
        touched.update(a.id for a in tree.ancestors(prim.id))

    candidates: list[DecompositionNode | None] = []
    first = failed if failed.kind == "compound" else (tree.nodes[failed.parent] if failed.parent else None)
    if first is None:
        candidates.append(None)  # a failed root primitive: replan the rest of the task network
    else:
        candidates.append(first)
        candidates.extend(tree.ancestors(first.id))
    next_id = max((_numeric_id(i) for i in tree.nodes), default=-1) + 1
    tried: list[str] = []
    expansions = 0
    last: PlanResult | None = None
    for candidate in candidates:
        remaining_nodes = None if max_nodes is None else max(max_nodes - expansions, 0)
        remaining_seconds = None if max_seconds is None else max(max_seconds - (time.perf_counter() - started), 0.0)
        search = Search(domain, external=external, max_nodes=remaining_nodes, max_seconds=remaining_seconds,
                        id_offset=next_id, step_offset=len(executed), goal=goal)
        if candidate is None:
            items = [(TASK, failed.task, None, None), *_continuation(tree, failed)]
            tried.append("task network")
        else:
            is_touched = candidate.id in touched
            exclude = (candidate.method, frozenset(candidate.bindings.items()))
            parent_key = candidate.id if is_touched else candidate.parent
            items = [(TASK, candidate.task, parent_key, exclude), *_continuation(tree, candidate)]
            tried.append(candidate.id)
        result = search.run(state, items)
        expansions += search.expansions
        last = result
        if result.status == "budget_exhausted":
            result.stats.update(candidates_tried=tried, kept_steps=len(executed))
            return result
        if result.status != "success":
            continue
        keep = set(touched)
        if candidate is not None:
            keep.update(a.id for a in tree.ancestors(candidate.id))
            if candidate.id in touched:
                keep.add(candidate.id)
        return _merge(tree, keep, executed, result, search, tried, candidate, started)
    assert last is not None
    last.message = f"replan from {failed_node_id} failed: tried {', '.join(tried)}; {last.message}"
    last.stats.update(candidates_tried=tried, kept_steps=len(executed),
                      seconds=round(time.perf_counter() - started, 6))
    return last


def _merge(tree: DecompositionTree, keep: set[str], executed: list[DecompositionNode], result: PlanResult,
           search: Search, tried: list[str], candidate: DecompositionNode | None, started: float) -> PlanResult:
    nodes: dict[str, DecompositionNode] = {}
    for old in tree.walk():
        if old.id in keep:
            nodes[old.id] = DecompositionNode(old.id, old.task, old.kind, old.method, dict(old.bindings), old.parent,
                                              old.state_before, old.step,
                                              [c for c in old.children if c in keep])
    roots = [r for r in tree.roots if r in keep]
    new_nodes: list[DecompositionNode] = result.extra["nodes"]
    for node in new_nodes:
        nodes[node.id] = node
    new_ids = {node.id for node in new_nodes}
    for node in new_nodes:
        if node.parent is None:
            roots.append(node.id)
        elif node.parent not in new_ids:  # children among new nodes are already linked by the search
            nodes[node.parent].children.append(node.id)
    merged = DecompositionTree(nodes, roots)
    plan = [GroundAction(p.name, p.args, p.id) for p in executed] + result.plan
    where = candidate.id if candidate is not None else "the task network"
    stats: dict[str, Any] = dict(result.stats)
    stats.update(replanned_from=where, candidates_tried=tried, kept_steps=len(executed), plan_length=len(plan),
                 tree_nodes=len(nodes), seconds=round(time.perf_counter() - started, 6))
    message = (f"replanned from {where}: kept {len(executed)} executed step(s), {len(result.plan)} new step(s)")
    return PlanResult("success", plan, merged, stats, message, result.state, {"nodes": new_nodes})
