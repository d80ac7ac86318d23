"""Checking a plan and its decomposition tree against a domain and problem, independently of the planner.

Offers:

* :func:`verify_plan` -- plan steps + tree (as ``bt-meta plan --json`` prints them) -> :class:`Verdict`
* :func:`read_plan_json` -- a plan JSON file to ``(steps, tree)``, mistakes located by line and column
* :class:`Verdict` -- ``ok``, the ``errors`` found (each names the step or tree node) and counts

The semantics are those of PANDA's plan verifier, the one the IPC HTN tracks used: the primitive plan is
executable from the initial state (every step's precondition holds where it is applied), the goal holds at the
end, and the tree is a decomposition of the initial task network -- its roots are the problem's tasks in order,
every compound node names a method of its task whose head matches under the node's bindings, whose
precondition holds in the state the node starts in, and whose subtasks (in order, or in any order for
``unordered:``) are the node's children; the primitive leaves, left to right, are the plan. Nothing of the
planner's search is used: states are rebuilt here step by step and conditions are evaluated by the reference
matcher (generated code off), so a planner bug cannot vouch for itself. Effects are applied here too
(:func:`_step_effects`): conditional effects by enumerating every combination of the ``forall`` variables' type
objects and testing each ``when`` in the step's pre-state, not by the planner's :meth:`Primitive.effects`.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bt_meta.errors import UserInputError
from bt_meta.htn.conditions import Var
from bt_meta.htn.model import Domain, Primitive, Problem, types_hold
from bt_meta.htn.state import Atom, State, atom_text

MAX_FORALL_COMBINATIONS = 1_000_000  # forall bindings one conditional effect of one step may make the verifier try


@dataclass
class Verdict:
    ok: bool
    errors: list[str] = field(default_factory=list)
    steps: int = 0
    nodes: int = 0

    def summary(self) -> str:
        if self.ok:
            return f"plan verified: {self.steps} step(s), {self.nodes} tree node(s)"
        return f"plan INVALID ({len(self.errors)} problem(s)): " + "; ".join(self.errors[:5])


def read_plan_json(path: str | Path) -> tuple[list[tuple[str, ...]], dict[str, Any] | None]:
    """``{"plan": [[name, arg, ...], ...], "tree": {...}}`` (``bt-meta plan --json``), or a bare list of steps."""
    file_path = Path(path)
    if not file_path.is_file():
        raise UserInputError("no such plan file", str(path))
    text = file_path.read_text(encoding="utf-8", errors="replace")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserInputError(f"JSON syntax error: {exc.msg}", str(path), exc.lineno, exc.colno) from None
    tree = None
    if isinstance(data, dict):
        if "plan" not in data:
            raise UserInputError("expected a JSON object with 'plan' (and 'tree'), as bt-meta plan --json prints",
                                 str(path), 1, 1)
        steps_data = data["plan"]
        tree = data.get("tree")
        if tree is not None and not (isinstance(tree, dict) and isinstance(tree.get("nodes"), list)
                                     and isinstance(tree.get("roots"), list)):
            raise UserInputError("'tree' must be {\"roots\": [...], \"nodes\": [...]}", str(path), 1, 1)
    else:
        steps_data = data
    if not isinstance(steps_data, list) or not all(
            isinstance(s, list) and s and all(isinstance(x, str) for x in s) for s in steps_data):
        raise UserInputError("'plan' must be a list of steps, each a list [name, arg, ...] of strings", str(path),
                             1, 1)
    return [tuple(s) for s in steps_data], tree


def _apply_step(domain: Domain, state: State, step: tuple[str, ...]) -> tuple[State | None, str | None]:
    prim = domain.primitives.get(step[0])
    if prim is None:
        return None, f"{step[0]} is not a primitive of the domain"
    args = step[1:]
    if len(args) != len(prim.parameters):
        return None, f"{prim.name} takes {len(prim.parameters)} argument(s), got {len(args)}"
    if not types_hold(prim.types, args, state):
        return None, f"the argument types of {atom_text(step)} do not hold"
    env = dict(zip(prim.parameters, args, strict=True))
    satisfier = next(iter(prim.precondition.satisfiers(state, env)), None)
    if satisfier is None:
        return None, f"the precondition of {atom_text(step)} does not hold: {prim.precondition.source}"
    effects = _step_effects(domain, prim, state, satisfier)
    if isinstance(effects, str):
        return None, f"{atom_text(step)}: {effects}"
    add, delete = effects
    return state.apply(add=add, delete=delete), None


def _step_effects(domain: Domain, prim: Primitive, state: State, env: dict[str, str]
                  ) -> tuple[list[Atom], list[Atom]] | str:
    """(add, delete) of a step: the plain effects, then each conditional effect for every binding of its
    ``forall`` variables (objects of their types in ``state``) whose ``when`` holds in ``state`` (the pre-state).

    A message instead when a ``forall`` has more than :data:`MAX_FORALL_COMBINATIONS` bindings to try.
    """
    add: list[Atom] = []
    delete: list[Atom] = []
    for templates, out in ((prim.add, add), (prim.delete, delete)):
        for template in templates:
            atom = _ground(template, env)
            if atom is None:
                raise UserInputError(f"effect {template[0]} of {prim.name} has an unbound variable")
            out.append(atom)
    for effect in prim.conditional:
        pools = [sorted({atom[1] for atom in _extension(domain, type_name, state)}) for type_name in effect.types]
        if math.prod(len(pool) for pool in pools) > MAX_FORALL_COMBINATIONS:
            return (f"a conditional effect has {' x '.join(str(len(p)) for p in pools)} forall bindings, more than "
                    f"the {MAX_FORALL_COMBINATIONS} the verifier enumerates")
        for values in itertools.product(*pools):
            local = dict(env)
            local.update(zip(effect.variables, values, strict=True))
            if not effect.when.holds(state, local):
                continue
            for templates, out in ((effect.add, add), (effect.delete, delete)):
                for template in templates:
                    atom = _ground(template, local)
                    if atom is None:
                        raise UserInputError(f"a conditional effect {template[0]} of {prim.name} has an unbound "
                                             "variable")
                    out.append(atom)
    return add, delete


def _extension(domain: Domain, pred: str, state: State) -> list[Atom]:
    """The atoms of ``pred`` (a fact or derived predicate) true in ``state``."""
    if pred in domain.context.derived:
        return list(domain.axiom_set.extension(state, pred).atoms_of(pred))
    return [atom for atom in state.atoms_of(pred) if len(atom) == 2]


def _holds(domain: Domain, atom: Atom, state: State) -> bool:
    if atom[0] in domain.context.derived:
        return atom in domain.axiom_set.extension(state, atom[0])
    return atom in state


def _ground(template: Sequence[Any], env: dict[str, str]) -> tuple[str, ...] | None:
    out = [template[0]]
    for term in template[1:]:
        if isinstance(term, Var):
            if term.name not in env:
                return None
            out.append(env[term.name])
        else:
            out.append(str(term))
    return tuple(out)


def verify_plan(domain: Domain, problem: Problem, steps: Sequence[Sequence[str]],
                tree: dict[str, Any] | None) -> Verdict:
    """Check ``steps`` (and ``tree`` when given; PANDA's verifier needs it) against ``problem``."""
    axiom_set = domain.axiom_set
    saved = axiom_set.codegen
    axiom_set.codegen = False
    axiom_set.begin()
    try:
        return _verify(domain, problem, [tuple(str(x) for x in s) for s in steps], tree)
    finally:
        axiom_set.codegen = saved
        axiom_set.begin()


def _verify(domain: Domain, problem: Problem, steps: list[tuple[str, ...]], tree: dict[str, Any] | None) -> Verdict:
    errors: list[str] = []
    states = [problem.state]
    for index, step in enumerate(steps):
        following, error = _apply_step(domain, states[-1], step)
        if following is None:
            errors.append(f"step {index} {atom_text(step)}: {error}")
            return Verdict(False, errors, len(steps))
        states.append(following)
    missing = [atom_text(a) for a in problem.goal if not _holds(domain, a, states[-1])]
    if missing:
        errors.append(f"the goal does not hold at the end: {', '.join(missing)}")
    if tree is None:
        errors.append("no decomposition tree given (PANDA's verifier needs one: use bt-meta plan --json)")
        return Verdict(False, errors, len(steps))
    node_count = _verify_tree(domain, problem, steps, states, tree, errors)
    return Verdict(not errors, errors, len(steps), node_count)


def _verify_tree(domain: Domain, problem: Problem, steps: list[tuple[str, ...]], states: list[State],
                 tree: dict[str, Any], errors: list[str]) -> int:
    nodes: dict[str, dict[str, Any]] = {}
    for node in tree["nodes"]:
        if not isinstance(node, dict) or not isinstance(node.get("id"), str) or not isinstance(node.get("task"), list):
            errors.append(f"tree node {node!r:.60} has no 'id' and 'task'")
            return len(nodes)
        if node["id"] in nodes:
            errors.append(f"tree node id {node['id']} appears twice")
            return len(nodes)
        nodes[node["id"]] = node
    roots = tree["roots"]
    root_tasks = [tuple(nodes[r]["task"]) if r in nodes else None for r in roots]
    wanted = [tuple(t) for t in problem.tasks]
    if root_tasks != wanted:
        shown = ", ".join(atom_text(t) if t else "?" for t in root_tasks)
        errors.append(f"the tree's roots ({shown}) are not the problem's task network "
                      f"({', '.join(atom_text(t) for t in wanted)})")
        return len(nodes)
    # walk in pre-order, left to right, counting primitive leaves; no recursion (trees can be very deep)
    position = 0
    visited: set[str] = set()
    stack: list[tuple[str, str | None]] = [(r, None) for r in reversed(roots)]
    while stack:
        node_id, parent = stack.pop()
        if node_id not in nodes:
            errors.append(f"node {node_id} is referenced but not in the tree")
            continue
        if node_id in visited:
            errors.append(f"node {node_id} appears twice in the tree (a cycle or a shared child)")
            continue
        visited.add(node_id)
        node = nodes[node_id]
        task = tuple(str(x) for x in node["task"])
        where = f"node {node_id} {atom_text(task)}"
        if node.get("parent") != parent:
            errors.append(f"{where}: its parent is {node.get('parent')}, but it is a child of {parent}")
        children = node.get("children") or []
        if task[0] in domain.primitives:
            if children:
                errors.append(f"{where}: a primitive has children")
            if position >= len(steps):
                errors.append(f"{where}: a primitive leaf beyond the plan's {len(steps)} step(s)")
            elif steps[position] != task:
                errors.append(f"{where}: leaf {position} of the tree but step {position} of the plan is "
                              f"{atom_text(steps[position])}")
            position += 1
            continue
        if task[0] not in domain.tasks:
            errors.append(f"{where}: {task[0]} is neither a task nor a primitive of the domain")
            continue
        error = _check_method(domain, node, task, states[min(position, len(states) - 1)],
                              [tuple(str(x) for x in nodes[c]["task"]) if c in nodes else None for c in children])
        if error:
            errors.append(f"{where}: {error}")
        stack.extend((c, node_id) for c in reversed(children))
    if position != len(steps):
        errors.append(f"the tree has {position} primitive leaves but the plan {len(steps)} step(s)")
    unreached = set(nodes) - visited
    if unreached:
        errors.append(f"{len(unreached)} tree node(s) are not below a root: {', '.join(sorted(unreached)[:5])}")
    return len(nodes)


def _check_method(domain: Domain, node: dict[str, Any], task: tuple[str, ...], state: State,
                  children: list[tuple[str, ...] | None]) -> str | None:
    decl = domain.tasks[task[0]]
    if len(task) - 1 != len(decl.parameters):
        return f"{task[0]} takes {len(decl.parameters)} argument(s), got {len(task) - 1}"
    if not types_hold(decl.types, task[1:], state):
        return "its argument types do not hold"
    name = node.get("method")
    method = next((m for m in domain.methods_by_task.get(task[0], []) if m.name == name), None)
    if method is None:
        return f"{name!r} is not a method of {task[0]}"
    bindings = {str(k): str(v) for k, v in (node.get("bindings") or {}).items()}
    head = _ground((method.task_name, *method.task_args), bindings)
    if head != task:
        return f"method {method.name}'s head {method.task_text()} does not give this task under its bindings"
    if not method.precondition.holds(state, bindings):
        return f"the precondition of method {method.name} does not hold: {method.precondition.source}"
    expected = [_ground(t, bindings) for t in method.subtasks]
    if any(e is None for e in expected):
        return f"the bindings of method {method.name} leave a subtask variable unbound"
    if method.ordered:
        if children != expected:
            return (f"its children ({', '.join(atom_text(c) if c else '?' for c in children)}) are not the subtasks "
                    f"of {method.name} ({', '.join(atom_text(e) for e in expected if e)})")
    elif sorted(map(str, children)) != sorted(map(str, expected)):
        return f"its children are not an ordering of the unordered subtasks of {method.name}"
    return None
