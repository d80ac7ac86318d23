"""Which goal facts a task could still add: the planner's goal-directed dead-end test.

Offers:

* :class:`GoalAchievers` -- per ground task, a bitmask of the problem's goal facts that some decomposition of the
  task could add (:meth:`GoalAchievers.of_task`), and the goal facts a state lacks (:meth:`GoalAchievers.missing`)

Why: when a problem has goal facts, a search node whose state lacks a goal fact that no task left on its agenda
can add cannot end in a plan, however the tasks are decomposed -- the fact stays false to the end. Without this
test the search only finds out at the end of every complete decomposition (Blocksworld-GTOHP: thousands of complete
plans rejected by the goal). The mask is a relaxation, so the test is sound: preconditions are ignored, a method's
variables that its head does not bind stand for any object (``None`` in a task pattern), and a primitive's
conditional effects count as if their condition held. A task's mask is the union over its methods of their
subtasks' masks, computed as a least fixpoint over the (finite) set of task patterns reachable from it, so
recursive methods are covered. Goal facts of derived predicates are left out: an axiom can make them true without
any task adding them.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from bt_meta.htn.conditions import Var
from bt_meta.htn.state import Atom, State

Pattern = tuple  # (task name, value or None, ...): None is "any object"


class GoalAchievers:
    """Goal-fact bitmasks of tasks and states for one domain and goal."""

    def __init__(self, domain: Any, goal: Iterable[Atom]) -> None:
        self.domain = domain
        derived = domain.context.derived
        atoms = list(dict.fromkeys(a for a in goal if a[0] not in derived))
        self.atoms = atoms
        self.bits = {atom: 1 << index for index, atom in enumerate(atoms)}
        self._by_pred: dict[str, list[tuple[Atom, int]]] = {}
        for atom, bit in self.bits.items():
            self._by_pred.setdefault(atom[0], []).append((atom, bit))
        self._tasks: dict[tuple, int] = {}  # ground task -> mask
        self._patterns: dict[Pattern, int] = {}  # solved task patterns -> mask

    def __bool__(self) -> bool:
        return bool(self.atoms)

    # -- states ----------------------------------------------------------------------------------------------
    def missing(self, state: State) -> int:
        """The goal facts ``state`` lacks, as a bitmask."""
        mask = 0
        for atom, bit in self.bits.items():
            if atom not in state:
                mask |= bit
        return mask

    def missing_after(self, missing: int, before: State, state: State) -> int:
        """:meth:`missing` of ``state`` from that of ``before``: from the last step's changes when it follows it."""
        if state is before:
            return missing
        if state._parent is not before:
            return self.missing(state)
        bits = self.bits
        for atom in state._delta:
            bit = bits.get(atom)
            if bit is not None:
                if atom in state:
                    missing &= ~bit
                else:
                    missing |= bit
        return missing

    def first(self, mask: int) -> Atom:
        """The goal fact of the lowest bit set in ``mask``."""
        return self.atoms[(mask & -mask).bit_length() - 1]

    # -- tasks -----------------------------------------------------------------------------------------------
    def of_task(self, task: tuple) -> int:
        """The goal facts some decomposition of the ground ``task`` could add, as a bitmask."""
        mask = self._tasks.get(task)
        if mask is None:
            mask = self._tasks[task] = self._solve(task)
        return mask

    def _solve(self, pattern: Pattern) -> int:
        known = self._patterns
        if pattern in known:
            return known[pattern]
        base: dict[Pattern, int] = {}
        deps: dict[Pattern, list[Pattern]] = {}
        todo = [pattern]
        while todo:
            current = todo.pop()
            if current in base or current in known:
                continue
            base[current], deps[current] = self._expand(current)
            todo.extend(d for d in deps[current] if d not in base and d not in known)
        mask = dict(base)
        changed = True
        while changed:  # least fixpoint: a recursive task adds what some finite decomposition of it adds
            changed = False
            for current, subs in deps.items():
                value = mask[current]
                for sub in subs:
                    value |= mask[sub] if sub in mask else known[sub]
                if value != mask[current]:
                    mask[current] = value
                    changed = True
        known.update(mask)
        return mask[pattern]

    def _expand(self, pattern: Pattern) -> tuple[int, list[Pattern]]:
        """(goal bits the pattern's primitive adds, sub-patterns of its methods)."""
        name, args = pattern[0], pattern[1:]
        domain = self.domain
        primitive = domain.primitives.get(name)
        if primitive is not None:
            env = {p: a for p, a in zip(primitive.parameters, args, strict=False) if a is not None}
            bits = 0
            for template in primitive.add:
                bits |= self._template_bits(template, env)
            for effect in getattr(primitive, "conditional", ()):  # forall / when effects, their condition ignored
                inner = {k: v for k, v in env.items() if k not in effect.variables}
                for template in effect.add:
                    bits |= self._template_bits(template, inner)
            return bits, []
        subs: list[Pattern] = []
        for method in domain.methods_by_task.get(name, ()):
            if len(method.task_args) != len(args):
                continue
            bound: dict[str, str] = {}
            for term, value in zip(method.task_args, args, strict=True):
                if term.__class__ is Var:
                    if value is None:
                        continue
                    prior = bound.setdefault(term.name, value)
                    if prior != value:
                        break
                elif value is not None and term != value:
                    break
            else:
                subs.extend(_instantiate(template, bound) for template in method.subtasks)
        return 0, subs

    def _template_bits(self, template: tuple, env: dict[str, str]) -> int:
        candidates = self._by_pred.get(template[0])
        if not candidates:
            return 0
        values = _instantiate(template, env)[1:]
        bits = 0
        for atom, bit in candidates:
            if len(atom) - 1 == len(values) and all(v is None or v == a for v, a in zip(values, atom[1:],
                                                                                          strict=True)):
                bits |= bit
        return bits


def _instantiate(template: tuple, env: dict[str, str]) -> Pattern:
    """The template with its variables replaced by their values in ``env``, or None (any object)."""
    values: list[str | None] = []
    for term in template[1:]:
        if term.__class__ is Var:
            values.append(env.get(term.name))
        elif isinstance(term, str):
            values.append(term)
        else:
            values.append(None)
    return (template[0], *values)
