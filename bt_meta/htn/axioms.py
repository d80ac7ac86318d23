"""Derived predicates (axioms): stratified, recursive rules evaluated on demand and cached per state.

Offers:

* :class:`Axiom` -- one rule ``head :- condition``; several rules with the same head predicate are alternatives
* :class:`AxiomSet` -- checks stratification (no recursion through ``not``) and computes the extension of a
  derived predicate in a state with a semi-naive fixpoint over its strongly connected component, the first
  time a condition asks for it in that state
* :class:`DerivedIndex` -- the computed atoms of one derived predicate, indexed like a state
* :class:`StratificationError` -- a derived predicate depends negatively on itself
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from bt_meta.htn.conditions import DNEG, DPOS, Condition, Step, Term, Var, ground, match_clause
from bt_meta.htn.state import Atom, State


class StratificationError(Exception):
    """A derived predicate depends on itself through negation; ``axiom`` is a rule on the cycle."""

    def __init__(self, message: str, axiom: Axiom) -> None:
        super().__init__(message)
        self.message = message
        self.axiom = axiom


@dataclass
class Axiom:
    head_pred: str
    head_args: tuple[Term, ...]
    condition: Condition
    source: str
    line: int | None = None
    column: int | None = None


class DerivedIndex:
    """The atoms of one derived predicate; offers the lookups the matcher uses on a State."""

    __slots__ = ("_all", "_by_first", "_order")

    def __init__(self) -> None:
        self._all: set[Atom] = set()
        self._order: list[Atom] = []
        self._by_first: dict[str, list[Atom]] = {}

    def add(self, atom: Atom) -> bool:
        if atom in self._all:
            return False
        self._all.add(atom)
        self._order.append(atom)
        if len(atom) > 1:
            self._by_first.setdefault(atom[1], []).append(atom)
        return True

    def __contains__(self, atom: object) -> bool:
        return atom in self._all

    def __len__(self) -> int:
        return len(self._all)

    def atoms_of(self, pred: str) -> Sequence[Atom]:
        return self._order

    def with_first(self, pred: str, first: str) -> Sequence[Atom]:
        return self._by_first.get(first, ())


def _unify(args: Sequence[Term], atom: Atom, env: dict[str, str]) -> dict[str, str] | None:
    if len(atom) != len(args) + 1:
        return None
    new = dict(env)
    for arg, value in zip(args, atom[1:], strict=False):
        if isinstance(arg, Var):
            prior = new.get(arg.name)
            if prior is None:
                new[arg.name] = value
            elif prior != value:
                return None
        elif arg != value:
            return None
    return new


class AxiomSet:
    """All axioms of a domain, grouped by head predicate and by strongly connected component."""

    def __init__(self, axioms: Sequence[Axiom]) -> None:
        self.axioms = list(axioms)
        self._key = object()
        self.rules: dict[str, list[Axiom]] = {}
        for axiom in self.axioms:
            self.rules.setdefault(axiom.head_pred, []).append(axiom)
        graph: dict[str, set[str]] = {p: set() for p in self.rules}
        negative: list[tuple[str, str, Axiom]] = []
        for axiom in self.axioms:
            for clause in axiom.condition.clauses:
                for step in clause:
                    if step[0] in (DPOS, DNEG):
                        graph[axiom.head_pred].add(step[1])
                        if step[0] == DNEG:
                            negative.append((axiom.head_pred, step[1], axiom))
        reach: dict[str, set[str]] = {}
        for pred in graph:
            seen: set[str] = set()
            todo = list(graph[pred])
            while todo:
                nxt = todo.pop()
                if nxt not in seen:
                    seen.add(nxt)
                    todo.extend(graph.get(nxt, ()))
            reach[pred] = seen
        self.group: dict[str, frozenset[str]] = {}
        for pred in graph:
            self.group[pred] = frozenset({pred} | {q for q in reach[pred] if pred in reach.get(q, set())})
        for head, dep, axiom in negative:
            if dep == head or dep in self.group[head]:
                raise StratificationError(
                    f"derived predicate {head} depends on itself through 'not {dep}(...)'; recursion through "
                    "negation has no well-defined meaning (stratify the axioms)", axiom)
        # Semi-naive join plans: for each rule clause, each positive literal of the same component first.
        self._recursive: dict[str, list[tuple[Axiom, int, Step, list[Step]]]] = {}
        for axiom in self.axioms:
            component = self.group[axiom.head_pred]
            for clause in axiom.condition.clauses:
                for j, step in enumerate(clause):
                    if step[0] == DPOS and step[1] in component:
                        rest = [s for k, s in enumerate(clause) if k != j]
                        self._recursive.setdefault(step[1], []).append((axiom, j, step, rest))

    def extension(self, state: State, pred: str) -> DerivedIndex:
        cache: dict[Any, Any] = state._derived
        key = (self._key, pred)
        found = cache.get(key)
        if found is None:
            self._evaluate(state, self.group[pred])
            found = cache[key]
        return found

    def derived_atoms(self, state: State) -> list[Atom]:
        """Every derived atom true in ``state`` (for display and tests)."""
        atoms: list[Atom] = []
        for pred in sorted(self.rules):
            atoms.extend(sorted(self.extension(state, pred).atoms_of(pred)))
        return atoms

    def _evaluate(self, state: State, component: frozenset[str]) -> None:
        known = {p: DerivedIndex() for p in component}

        def source(pred: str) -> Any:
            index = known.get(pred)
            return index if index is not None else self.extension(state, pred)

        pending: list[Atom] = []
        for pred in component:
            for axiom in self.rules[pred]:
                for clause in axiom.condition.clauses:
                    if any(step[0] == DPOS and step[1] in component for step in clause):
                        continue  # needs atoms of its own component: handled by the delta rounds
                    for env in match_clause(clause, state, {}, None, self, source):
                        pending.append(ground(axiom.head_pred, axiom.head_args, env))
        delta = {p: [] for p in component}
        for atom in pending:
            if known[atom[0]].add(atom):
                delta[atom[0]].append(atom)
        while any(delta.values()):
            pending = []
            for pred, atoms in delta.items():
                for axiom, _j, step, rest in self._recursive.get(pred, ()):
                    for atom in atoms:
                        env = _unify(step[2], atom, {})
                        if env is None:
                            continue
                        for result in match_clause(rest, state, env, None, self, source):
                            pending.append(ground(axiom.head_pred, axiom.head_args, result))
            delta = {p: [] for p in component}
            for atom in pending:
                if known[atom[0]].add(atom):
                    delta[atom[0]].append(atom)
        for pred, index in known.items():
            state._derived[(self._key, pred)] = index
