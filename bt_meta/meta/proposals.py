"""Repair proposals: the changes a repair plugin may propose, and how each changes the plan being executed.

A proposal is a :class:`~bt_meta.bt.failures.RepairProposal` (``action`` names its kind, ``changes`` its
parameters, ``score`` ranks it). The executor keeps the plan as a :class:`PlanState` -- the decomposition tree, the
*cursor* (how many of its steps have run) and the *committed* steps of earlier plans -- and a proposal turns one
:class:`PlanState` into the next. Steps are plan indices of the tree (``DecompositionNode.step``).

Kinds (``RepairProposal.action``) and their ``changes``:

================== ============================================================ ================================
kind               changes                                                      effect
================== ============================================================ ================================
``retry``          ``{}`` (any extra keys, e.g. ``attempt``, only tell retries   run the failed step again
                   apart)
``rewrite_args``   ``{"step": k, "args": [..]}`` (``step`` defaults to the       new arguments for step k >= the
                   failed step)                                                  failed step; resume there
``substitute``     ``{"mapping": {old: new}, "from_step": k}`` (default: the     rename objects in every step
                   failed step)                                                  from k on; resume at k
``backtrack``      ``{"to_step": k, "args": {"k2": [..], ...}}``                 re-execute from step k <= the
                                                                                 failed step, with new arguments
                                                                                 for the listed steps
``splice``         ``{"start": i, "end": j, "actions": [[name, arg..], ..]}``    replace steps i..j-1 by these
                                                                                 primitives; resume at i
``replan``         ``{"node_id": n}`` (default: the failed node)                 ``htn.replan`` from node n,
                                                                                 keeping the executed prefix
``replan_scratch`` ``{}``                                                        plan the problem's task network
                                                                                 afresh from the current state
``rebind``         ``{"symbols": {symbol: object}, "from_step": k}`` (default:   ground task-file symbols as other
                   the failed step)                                              world objects from now on (a
                                                                                 spare for a missing part that the
                                                                                 plan names only through poses);
                                                                                 resume at k
================== ============================================================ ================================

A ``rebind`` changes no step: the plan state records it (:attr:`PlanState.rebound`) and the executor tells the world
(``world.rebind_object(symbol, object)``) before it runs the plan again.

Offers:

* :class:`RepairProposal` -- re-exported from :mod:`bt_meta.bt.failures`
* the kind names (:data:`RETRY`, ...) and :data:`PROPOSAL_KINDS`
* :class:`PlanState` -- tree, cursor, committed prefix; :meth:`PlanState.full_plan`, :meth:`PlanState.remaining_tree`
* :func:`apply_proposal` -- one proposal applied to a :class:`PlanState` (returns a new one)
* :func:`proposal_key` -- what makes two proposals the same (the reasoner never applies one twice to one failure)
* :func:`plan_effect` -- what an applied proposal would do: where the plan resumes and the steps it would run,
  with the objects and poses they bind (the executor never applies two proposals with the same effect)
* :class:`ProposalError` -- a proposal that cannot be applied (bad step, wrong arity, no plan); the reasoner then
  tries the next one
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from bt_meta.bt.failures import RepairProposal
from bt_meta.errors import BtMetaError
from bt_meta.htn.state import State
from bt_meta.htn.tree import DecompositionNode, DecompositionTree

__all__ = [
    "BACKTRACK",
    "PROPOSAL_KINDS",
    "REBIND",
    "REPLAN",
    "REPLAN_SCRATCH",
    "RETRY",
    "REWRITE_ARGS",
    "SPLICE",
    "SUBSTITUTE",
    "PlanState",
    "ProposalError",
    "RepairProposal",
    "apply_proposal",
    "plan_effect",
    "proposal_facts",
    "proposal_key",
]

RETRY = "retry"
REWRITE_ARGS = "rewrite_args"
SUBSTITUTE = "substitute"
BACKTRACK = "backtrack"
SPLICE = "splice"
REPLAN = "replan"
REPLAN_SCRATCH = "replan_scratch"
REBIND = "rebind"
PROPOSAL_KINDS: tuple[str, ...] = (RETRY, REWRITE_ARGS, SUBSTITUTE, BACKTRACK, SPLICE, REPLAN, REPLAN_SCRATCH, REBIND)


class ProposalError(BtMetaError):
    """A repair proposal that cannot be applied to the current plan."""


def proposal_facts(changes: Any) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]]:
    """(add, delete) atoms of a proposal's ``changes["facts"]`` (``{"add": [[predicate, arg, ...], ...],
    "delete": [...]}``: what the repair makes true or false when it is applied); ``([], [])`` without. Raises
    :class:`ProposalError` naming what is wrong with malformed facts (a plugin's, not to crash the run)."""
    facts = (changes or {}).get("facts") if isinstance(changes, Mapping) else None
    if facts is None:
        return [], []
    if not isinstance(facts, Mapping) or set(facts) - {"add", "delete"}:
        raise ProposalError(f"facts must be a mapping with 'add' and/or 'delete', got {facts!r}")
    out: list[list[tuple[str, ...]]] = []
    for key in ("add", "delete"):
        atoms = facts.get(key) or []
        if isinstance(atoms, (str, bytes)) or not isinstance(atoms, Sequence):
            raise ProposalError(f"facts[{key!r}] must be a list of atoms, got {atoms!r}")
        parsed = []
        for atom in atoms:
            if isinstance(atom, (str, bytes)) or not isinstance(atom, Sequence) or not atom \
                    or not all(isinstance(a, (str, int, float)) for a in atom):
                raise ProposalError(f"facts[{key!r}]: an atom is a list [predicate, arg, ...], got {atom!r}")
            parsed.append(tuple(str(a) for a in atom))
        out.append(parsed)
    return out[0], out[1]


Step = tuple[str, tuple[str, ...]]


@dataclass
class PlanState:
    """The plan being executed: ``tree`` (its steps numbered 0..n-1), ``cursor`` (steps of it already run) and
    ``committed`` (steps that ran under earlier plans, before a from-scratch replan)."""

    tree: DecompositionTree
    cursor: int = 0
    committed: list[Step] = field(default_factory=list)
    unguarded: frozenset[str] = frozenset()
    """Compound nodes whose method precondition is not checked again: a repair changed steps below them, knowingly
    departing from the method's bindings (e.g. another arm than the method's precondition chose)."""
    rebound: dict[str, str] = field(default_factory=dict)
    """Task-file symbols grounded as other world objects than the grounding file says (``rebind`` proposals, in
    the order applied): part of what the plan does, so of its effect."""

    def steps(self) -> list[DecompositionNode]:
        return self.tree.primitives()

    def step_node(self, step: int) -> DecompositionNode:
        steps = self.steps()
        if not 0 <= step < len(steps):
            raise ProposalError(f"no step {step}: the plan has steps 0..{len(steps) - 1}")
        return steps[step]

    def full_plan(self) -> list[Step]:
        """Every step from the initial state: the committed ones, then the tree's."""
        return [*self.committed, *((n.task[0], tuple(n.task[1:])) for n in self.steps())]

    def describe(self) -> list[dict[str, Any]]:
        """The tree's steps as JSON-able records (what repair plugins see in ``evidence["plan"]``); ``tasks`` names
        the compound tasks above each step, outermost first (a plugin tells a verification task's steps apart)."""
        return [{"step": n.step, "action": n.task[0], "args": list(n.task[1:]), "node_id": n.id,
                 "done": n.step is not None and n.step < self.cursor,
                 "tasks": [a.task[0] for a in reversed(self.tree.ancestors(n.id))]} for n in self.steps()]

    def remaining_tree(self) -> DecompositionTree:
        """The steps from the cursor on, with their ancestors; an ancestor part of which already ran loses its
        method, so the compiled tree does not check its precondition again (it was checked when it started)."""
        keep: set[str] = set()
        touched: set[str] = set(self.unguarded)
        for node in self.steps():
            ancestors = [a.id for a in self.tree.ancestors(node.id)]
            if node.step is not None and node.step < self.cursor:
                touched.update(ancestors)
            else:
                keep.add(node.id)
                keep.update(ancestors)
        nodes: dict[str, DecompositionNode] = {}
        for node in self.tree.walk():
            if node.id not in keep:
                continue
            nodes[node.id] = DecompositionNode(
                node.id, node.task, node.kind, None if node.id in touched else node.method, dict(node.bindings),
                node.parent, node.state_before, node.step, [c for c in node.children if c in keep])
        return DecompositionTree(nodes, [r for r in self.tree.roots if r in keep])


def proposal_key(proposal: RepairProposal) -> str:
    """The identity of a proposal: its kind and changes (the score, description and evidence do not count)."""
    return f"{proposal.action}:{json.dumps(proposal.changes, sort_keys=True, default=str)}"


def plan_effect(plan_state: PlanState) -> str:
    """The identity of an attempt by its effect, not by the node ids or wording of the proposal that made it.

    Two plan states have the same effect when execution resumes at the same place of the whole run (steps already
    committed plus the cursor) and would run the same steps with the same arguments (objects, cells, pose symbols).
    A replan from a new decomposition node that yields the plan that already failed is the same attempt again."""
    steps = plan_state.steps()
    suffix = [[n.task[0], *map(str, n.task[1:])] for n in steps[plan_state.cursor:]]
    effect: dict[str, Any] = {"at": len(plan_state.committed) + plan_state.cursor, "run": suffix}
    if plan_state.rebound:  # the same steps on another object are another attempt
        effect["rebound"] = dict(sorted(plan_state.rebound.items()))
    return json.dumps(effect)


# -- tree surgery ----------------------------------------------------------------------------------------------


def copy_tree(tree: DecompositionTree) -> DecompositionTree:
    nodes = {node_id: dataclasses.replace(node, bindings=dict(node.bindings), children=list(node.children))
             for node_id, node in tree.nodes.items()}
    return DecompositionTree(nodes, list(tree.roots))


def _renumber(tree: DecompositionTree) -> None:
    step = 0
    for node in tree.walk():
        if node.kind == "primitive":
            node.step = step
            step += 1


def _next_id(tree: DecompositionTree) -> int:
    numbers = [int(i[1:]) for i in tree.nodes if i.startswith("n") and i[1:].isdigit()]
    return max(numbers, default=-1) + 1


def _check_call(domain: Any, name: str, args: Sequence[Any]) -> tuple[str, ...]:
    primitive = domain.primitives.get(name)
    if primitive is None:
        raise ProposalError(f"unknown primitive {name!r}; known: {', '.join(sorted(domain.primitives))}")
    args = tuple(str(a) for a in args)
    if len(args) != len(primitive.parameters):
        raise ProposalError(f"{name} takes {len(primitive.parameters)} argument(s), got {len(args)}: {list(args)}")
    return args


def _rewrite(tree: DecompositionTree, domain: Any, step: int, args: Sequence[Any]) -> None:
    node = next((n for n in tree.primitives() if n.step == step), None)
    if node is None:
        raise ProposalError(f"no step {step} in the plan")
    new_args = _check_call(domain, node.task[0], args)
    primitive = domain.primitives[node.task[0]]
    node.task = (node.task[0], *new_args)
    node.bindings.update(zip(primitive.parameters, new_args, strict=True))


def _int(changes: dict[str, Any], key: str, default: int | None = None) -> int:
    value = changes.get(key, default)
    if value is None:
        raise ProposalError(f"the proposal needs {key!r} in its changes")
    try:
        return int(value)
    except (TypeError, ValueError):
        raise ProposalError(f"{key!r} must be a step number, got {value!r}") from None


# -- applying ---------------------------------------------------------------------------------------------------


def apply_proposal(
    proposal: RepairProposal,
    plan_state: PlanState,
    *,
    failed_step: int,
    failed_node: str | None,
    domain: Any,
    problem: Any,
    state: State,
    external: Callable[..., bool] | None = None,
    max_seconds: float | None = None,
) -> tuple[PlanState, str]:
    """Apply ``proposal`` to ``plan_state`` after a failure at ``failed_step`` (node ``failed_node``) in ``state``.

    Returns the new :class:`PlanState` and a one-line account of the change. Raises :class:`ProposalError`.
    """
    kind = proposal.action
    changes = proposal.changes or {}
    proposal_facts(changes)  # malformed facts make the proposal inapplicable, before anything changes
    steps = plan_state.steps()
    if kind == RETRY:
        return dataclasses.replace(plan_state, cursor=failed_step), f"retry step {failed_step}"
    if kind == REWRITE_ARGS:
        step = _int(changes, "step", failed_step)
        if step < failed_step:
            raise ProposalError(f"rewrite_args of step {step} before the failed step {failed_step}: use backtrack")
        tree = copy_tree(plan_state.tree)
        _rewrite(tree, domain, step, changes.get("args", ()))
        return _changed(plan_state, tree, failed_step, [step]), f"step {step} now {_call(tree, step)}"
    if kind == BACKTRACK:
        to_step = _int(changes, "to_step")
        if not 0 <= to_step <= failed_step:
            raise ProposalError(f"backtrack to step {to_step}: must be between 0 and the failed step {failed_step}")
        tree = copy_tree(plan_state.tree)
        rewritten, changed_steps = [], []
        for key, args in dict(changes.get("args") or {}).items():
            step = _int({"step": key}, "step")
            if step < to_step:
                raise ProposalError(f"backtrack to step {to_step} cannot change the earlier step {step}")
            _rewrite(tree, domain, step, args)
            changed_steps.append(step)
            rewritten.append(f"step {step} now {_call(tree, step)}")
        account = f"backtrack to step {to_step}" + (f"; {'; '.join(rewritten)}" if rewritten else "")
        return _changed(plan_state, tree, to_step, changed_steps), account
    if kind == SUBSTITUTE:
        mapping = {str(k): str(v) for k, v in dict(changes.get("mapping") or {}).items()}
        if not mapping:
            raise ProposalError("substitute needs a non-empty 'mapping' {old: new}")
        from_step = _int(changes, "from_step", failed_step)
        if not 0 <= from_step <= failed_step:
            raise ProposalError(f"substitute from step {from_step}: must be between 0 and the failed step")
        tree = copy_tree(plan_state.tree)
        changed_steps = []
        for node in tree.primitives():
            if node.step is None or node.step < from_step:
                continue
            new_task = (node.task[0], *(mapping.get(a, a) for a in node.task[1:]))
            if new_task != node.task:
                changed_steps.append(node.step)
                _rewrite(tree, domain, node.step, new_task[1:])
        for node in tree.walk():  # compound nodes entirely after from_step: keep their labels truthful
            if node.kind == "compound" and all(p.step is not None and p.step >= from_step
                                               for p in tree.primitives(node.id)):
                node.task = (node.task[0], *(mapping.get(a, a) for a in node.task[1:]))
                node.bindings = {k: mapping.get(v, v) for k, v in node.bindings.items()}
        if not changed_steps:
            raise ProposalError(f"substitute {mapping}: no step from {from_step} on uses these objects")
        pairs = ", ".join(f"{k} -> {v}" for k, v in mapping.items())
        account = f"substitute {pairs} in {len(changed_steps)} step(s)"
        return _changed(plan_state, tree, from_step, changed_steps), account
    if kind == SPLICE:
        start = _int(changes, "start", failed_step)
        end = _int(changes, "end", start + 1)
        if not 0 <= start <= failed_step or not start <= end <= len(steps):
            raise ProposalError(f"splice {start}..{end}: need 0 <= start <= failed step {failed_step} and "
                                f"start <= end <= {len(steps)}")
        actions = [list(a) for a in changes.get("actions") or []]
        if not actions or any(not a for a in actions):
            raise ProposalError("splice needs 'actions': a non-empty list of [name, arg, ...]")
        tree = copy_tree(plan_state.tree)
        ordered = tree.primitives()
        anchor = ordered[start] if start < len(ordered) else ordered[-1]
        parent = anchor.parent
        siblings = tree.nodes[parent].children if parent is not None else tree.roots
        position = siblings.index(anchor.id) + (0 if start < len(ordered) else 1)
        for node in ordered[start:end]:
            holder = tree.nodes[node.parent].children if node.parent is not None else tree.roots
            if node.id in holder[:position] and holder is siblings:
                position -= 1
            holder.remove(node.id)
            del tree.nodes[node.id]
        next_id = _next_id(tree)
        new_ids = []
        for offset, action in enumerate(actions):
            name, args = str(action[0]), _check_call(domain, str(action[0]), action[1:])
            node_id = f"n{next_id + offset}"
            primitive = domain.primitives[name]
            tree.nodes[node_id] = DecompositionNode(node_id, (name, *args), "primitive", None,
                                                    dict(zip(primitive.parameters, args, strict=True)), parent,
                                                    anchor.state_before, None, [])
            new_ids.append(node_id)
        siblings[position:position] = new_ids
        _renumber(tree)
        calls = ", ".join(_call(tree, s) for s in range(start, start + len(actions)))
        account = f"steps {start}..{end - 1} replaced by {calls}"
        return _changed(plan_state, tree, start, range(start, start + len(actions))), account
    if kind == REBIND:
        symbols = {str(k): str(v) for k, v in dict(changes.get("symbols") or {}).items()}
        if not symbols:
            raise ProposalError("rebind needs a non-empty 'symbols' {symbol: object}")
        from_step = _int(changes, "from_step", failed_step)
        if not 0 <= from_step <= failed_step:
            raise ProposalError(f"rebind from step {from_step}: must be between 0 and the failed step")
        if all(plan_state.rebound.get(k) == v for k, v in symbols.items()):
            raise ProposalError(f"rebind {symbols}: the symbols are bound so already")
        pairs = ", ".join(f"{k} -> {v}" for k, v in symbols.items())
        return (dataclasses.replace(plan_state, cursor=from_step, rebound={**plan_state.rebound, **symbols}),
                f"rebind {pairs}; resume at step {from_step}")
    if kind == REPLAN:
        from bt_meta.htn import replan

        node_id = str(changes.get("node_id") or failed_node or "")
        if node_id not in plan_state.tree.nodes:
            raise ProposalError(f"replan from {node_id or 'an unknown node'}: no such decomposition node")
        goal = list(getattr(problem, "goal", None) or []) or None
        result = replan(domain, plan_state.tree, node_id, state, external=external, max_seconds=max_seconds,
                        goal=goal)
        if result.status != "success" or result.tree is None:
            raise ProposalError(f"replan from {node_id}: {result.status}: {result.message}")
        kept = int(result.stats.get("kept_steps", 0))
        kept_ids = set(result.tree.nodes)
        return PlanState(result.tree, kept, list(plan_state.committed),
                         frozenset(i for i in plan_state.unguarded if i in kept_ids),
                         dict(plan_state.rebound)), result.message
    if kind == REPLAN_SCRATCH:
        from bt_meta.htn import plan

        if problem is None:
            raise ProposalError("replan_scratch needs the problem")
        fresh = dataclasses.replace(problem, state=state, init=sorted(state))
        started = time.perf_counter()
        result = plan(domain, fresh, external=external, max_seconds=max_seconds)
        if result.status != "success" or result.tree is None:
            raise ProposalError(f"replan from scratch: {result.status}: {result.message}")
        done = [(n.task[0], tuple(n.task[1:])) for n in steps[:failed_step]]
        account = (f"planned the task network afresh: {len(result.plan)} step(s) in "
                   f"{time.perf_counter() - started:.3f} s")
        return PlanState(result.tree, 0, [*plan_state.committed, *done], rebound=dict(plan_state.rebound)), account
    raise ProposalError(f"unknown proposal kind {kind!r}; expected one of: {', '.join(PROPOSAL_KINDS)}")


def _changed(plan_state: PlanState, tree: DecompositionTree, cursor: int, steps: Iterable[int]) -> PlanState:
    """The next plan state after steps ``steps`` of ``tree`` changed: their ancestors lose their guards."""
    wanted = set(steps)
    unguarded = set(plan_state.unguarded)
    for node in tree.primitives():
        if node.step in wanted:
            unguarded.update(a.id for a in tree.ancestors(node.id))
    return PlanState(tree, cursor, list(plan_state.committed), frozenset(unguarded), dict(plan_state.rebound))


def _call(tree: DecompositionTree, step: int) -> str:
    node = next(n for n in tree.primitives() if n.step == step)
    return f"{node.task[0]}({', '.join(node.task[1:])})"
