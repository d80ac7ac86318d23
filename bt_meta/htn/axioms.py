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

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from bt_meta.htn.codegen import Generated
from bt_meta.htn.conditions import (
    DNEG,
    DPOS,
    POS,
    Clause,
    Condition,
    Step,
    Term,
    Var,
    candidates,
    ground,
    match_clause,
    template_builder,
)
from bt_meta.htn.fastpath import IN_PROGRESS, Unsupported
from bt_meta.htn.state import Atom, State

SEEDED_MIN = 32  # fewer seeds than this: a planner clause is matched directly (keeping units costs more)
MAX_DEPTH = 200  # nested top-down proofs before falling back to the bottom-up extension
INHERIT_DEPTH = 16  # how far up the parent chain a state looks for a memo to inherit

_IN_PROGRESS = IN_PROGRESS
_OWNED = object()  # memo key: the unit tables this memo may change in place (see AxiomSet._inherit)
_EPOCH = object()  # memo key: the epoch whose reader indexes cover the memo's entries (see AxiomSet.begin)
_NO_ENTRIES: dict[Any, Any] = {}


class _Fallback(Exception):
    """A top-down proof met a cycle or got too deep: use the bottom-up extension instead."""


class _Recorder:
    """A view of a state that records what a proof reads, so the proof can be reused by successor states."""

    __slots__ = ("deps", "keys", "state", "volatile")

    def __init__(self, state: State) -> None:
        self.state = state
        self.keys: set[tuple[str, str | None]] = set()
        self.deps: list[Atom] = []
        self.volatile = False

    def __contains__(self, atom: object) -> bool:
        assert isinstance(atom, tuple)
        self.keys.add((atom[0], atom[1] if len(atom) > 1 else None))
        return atom in self.state

    def with_arg(self, pred: str, position: int, value: str) -> Sequence[Atom]:
        self.keys.add((pred, value) if position == 1 else (pred, None))
        return self.state.with_arg(pred, position, value)

    def atoms_of(self, pred: str) -> Iterable[Atom]:
        self.keys.add((pred, None))
        return self.state.atoms_of(pred)


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
    # the head's variable names when they are all distinct variables (a ground atom binds them with one zip)
    head_names: tuple[str, ...] | None = field(default=None, init=False, repr=False, compare=False)
    head_builder: Any = field(default=None, init=False, repr=False, compare=False)  # the head as a function of env

    def __post_init__(self) -> None:
        names = tuple(a.name for a in self.head_args if isinstance(a, Var))
        if len(names) == len(self.head_args) and len(set(names)) == len(names):
            self.head_names = names
        self.head_builder = template_builder(self.head_pred, self.head_args)


class DerivedIndex:
    """The atoms of one derived predicate; offers the lookups the matcher uses on a State."""

    __slots__ = ("_all", "_by_arg", "_order")

    def __init__(self) -> None:
        self._all: set[Atom] = set()
        self._order: list[Atom] = []
        self._by_arg: dict[int, dict[str, list[Atom]]] = {}

    def add(self, atom: Atom) -> bool:
        if atom in self._all:
            return False
        self._all.add(atom)
        self._order.append(atom)
        for position, index in self._by_arg.items():
            if len(atom) > position:
                index.setdefault(atom[position], []).append(atom)
        return True

    def __contains__(self, atom: object) -> bool:
        return atom in self._all

    def __len__(self) -> int:
        return len(self._all)

    def atoms_of(self, pred: str) -> Sequence[Atom]:
        return self._order

    def with_arg(self, pred: str, position: int, value: str) -> Sequence[Atom]:
        index = self._by_arg.get(position)
        if index is None:
            index = {}
            for atom in self._order:
                if len(atom) > position:
                    index.setdefault(atom[position], []).append(atom)
            self._by_arg[position] = index
        return index.get(value, ())

    def with_first(self, pred: str, first: str) -> Sequence[Atom]:
        return self.with_arg(pred, 1, first)


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
        # Predicates whose rules use their own component positively: free queries on them are answered from the
        # full (bottom-up) extension; every other query is answered top-down (see :meth:`holds`, :meth:`query`).
        self.recursive: set[str] = set()
        for axiom in self.axioms:
            for clause in axiom.condition.clauses:
                if any(step[0] == DPOS and step[1] in self.group[axiom.head_pred] for step in clause):
                    self.recursive.update(self.group[axiom.head_pred])
        self._memo_key = (self._key, "memo")
        self._volatile_key = (self._key, "volatile")
        self._depth = 0
        self.incremental = True  # memo inheritance and per-seed units (off only to test they change nothing)
        # Method preconditions that test derived predicates run as generated code (bt_meta.htn.codegen); off:
        # the reference matcher above answers them (the two give the same satisfiers in the same order).
        self.codegen = True
        self.reference_proofs: bool | None = None  # None: chosen by state size (conditions.REFERENCE_PROOFS_MIN)
        self._generated: Any = None
        self._generated_reference: Any = None
        # Shared by every state: which memo entries read a fact key / used a derived atom (append-only, so
        # an invalidation may drop more than needed, never less).
        self._readers: dict[tuple[str, str | None], set[Any]] = {}
        self._dependents: dict[Any, set[Any]] = {}
        self._epoch = 0
        # Clauses of non-recursive derived predicates that start with a fact pattern: evaluated per seed.
        self._units: dict[int, tuple] = {}
        for axiom in self.axioms:
            if axiom.head_pred in self.recursive:
                continue
            for clause in axiom.condition.clauses:
                if clause and clause[0][0] == POS:
                    self._units[id(clause)] = (object(), clause[0], Clause(clause[1:]))
        # Semi-naive join plans: for each rule clause, each positive literal of the same component first.
        self._recursive: dict[str, list[tuple[Axiom, int, Step, list[Step]]]] = {}
        for axiom in self.axioms:
            component = self.group[axiom.head_pred]
            for clause in axiom.condition.clauses:
                for j, step in enumerate(clause):
                    if step[0] == DPOS and step[1] in component:
                        rest = Clause(s for k, s in enumerate(clause) if k != j)
                        self._recursive.setdefault(step[1], []).append((axiom, j, step, rest))

    def generated(self, reference_proofs: bool = False) -> Any:
        """The :class:`~bt_meta.htn.codegen.Generated` functions of this set (built on first use), or None."""
        attr = "_generated_reference" if reference_proofs else "_generated"
        found = getattr(self, attr)
        if found is None:
            try:
                found = Generated(self, MAX_DEPTH, reference_proofs)
            except Unsupported:
                found = False
            setattr(self, attr, found)
        return found or None

    def begin(self) -> None:
        """Start a new epoch (the planner calls this once per search): empty reader indexes.

        The indexes only grow within an epoch, so without this every search would pay for the entries of all
        earlier ones. A memo of an earlier epoch stays valid for its own state but is not inherited from.
        """
        self._epoch += 1
        self._readers = {}
        self._dependents = {}

    def extension(self, state: State, pred: str) -> DerivedIndex:
        if isinstance(state, _Recorder):
            state.volatile = True
            state = state.state
        cache: dict[Any, Any] = state._derived
        key = (self._key, pred)
        found = cache.get(key)
        if found is None:
            self._evaluate(state, self.group[pred])
            found = cache[key]
        return found

    def holds(self, state: State, atom: Atom) -> bool:
        """Truth of one ground derived atom, top-down with a per-state memo inherited from the parent state.

        Each proof records which facts it read (as (predicate, first argument) keys) and which derived atoms it
        used, in indexes shared by the states of one search (reset by :meth:`begin`); a successor state copies
        its parent's memo and drops what its changed facts reach through those indexes, so a move of one block
        re-proves only what depends on that block. Deep or cyclic derivations (an atom needed to prove itself,
        or more than ``MAX_DEPTH`` nested atoms) fall back to the bottom-up extension of the predicate, which is
        exact and needs no Python recursion beyond the number of strata.
        """
        recorder_in = None
        if isinstance(state, _Recorder):
            recorder_in = state
            state.deps.append(atom)
            state = state.state
        cache = state._derived
        pred = atom[0]
        extension = cache.get((self._key, pred))
        if extension is not None:
            if recorder_in is not None:  # not tracked by the indexes: the caller's proof is not reusable
                recorder_in.volatile = True
            return atom in extension
        memo = cache.get(self._memo_key)
        if memo is None:
            memo = cache[self._memo_key] = self._inherit(state)
        known = memo.get(atom)
        if known is None:
            known = cache.get(self._volatile_key, _NO_ENTRIES).get(atom)
            if known is not None and recorder_in is not None:
                recorder_in.volatile = True
        if known is not None:
            if known is _IN_PROGRESS:
                raise _Fallback
            return known[0]  # type: ignore[no-any-return]
        outermost = self._depth == 0
        try:
            if self._depth >= MAX_DEPTH:
                raise _Fallback
            memo[atom] = _IN_PROGRESS
            self._depth += 1
            try:
                recorder = _Recorder(state)
                result = self._prove(recorder, atom)
            finally:
                self._depth -= 1
                if memo.get(atom) is _IN_PROGRESS:
                    del memo[atom]
            self._store(state, memo, atom, (result,), recorder)
            if recorder.volatile and recorder_in is not None:  # not reusable, so neither is the caller's proof
                recorder_in.volatile = True
            return result
        except _Fallback:
            if not outermost:
                raise
            if recorder_in is not None:  # answered from the extension, which the indexes do not track
                recorder_in.volatile = True
            return atom in self.extension(state, pred)

    def _store(self, state: State, memo: dict[Any, Any], key: Any, entry: tuple, recorder: _Recorder) -> None:
        if recorder.volatile or not self.incremental:
            volatile = state._derived.get(self._volatile_key)
            if volatile is None:
                volatile = state._derived[self._volatile_key] = {}
            volatile[key] = entry
            return
        if key[0].__class__ is str:  # a derived atom
            memo[key] = entry
        else:  # a unit (token, seed, pattern): kept in its table memo[(token, pattern)], copied before writing
            table_key = (key[0], key[2])
            table = memo.get(table_key)
            owned = memo[_OWNED]
            if table is None:
                table = memo[table_key] = {}
                owned.add(table_key)
            elif table_key not in owned:
                table = memo[table_key] = dict(table)
                owned.add(table_key)
            table[key[1]] = entry
        readers = self._readers
        for fact_key in recorder.keys:
            found = readers.get(fact_key)
            if found is None:
                readers[fact_key] = {key}
            else:
                found.add(key)
        dependents = self._dependents
        for dep in recorder.deps:
            found = dependents.get(dep)
            if found is None:
                dependents[dep] = {key}
            else:
                found.add(key)

    def _inherit(self, state: State) -> dict[Any, Any]:
        """The memo of ``state``: the nearest ancestor's entries that the changes since then leave valid.

        Units live in tables shared with the ancestor until one side changes them: a memo only writes into the
        tables listed under its ``_OWNED`` key and copies any other table first (the ancestor gives up
        ownership of everything it shares here).
        """
        fresh = {_OWNED: set(), _EPOCH: self._epoch}
        if not self.incremental:
            return fresh
        changed: set[tuple[str, str | None]] = set()
        cursor = state
        for _ in range(INHERIT_DEPTH):
            parent = cursor._parent
            if parent is None:
                return fresh
            for atom in cursor._delta:
                changed.add((atom[0], None))
                if len(atom) > 1:
                    changed.add((atom[0], atom[1]))
            parent_memo = parent._derived.get(self._memo_key)
            if parent_memo is not None:
                break
            cursor = parent
        else:
            return fresh
        if parent_memo.get(_EPOCH) != self._epoch:
            return fresh
        memo = dict(parent_memo)
        parent_memo[_OWNED] = set()
        owned: set[Any] = set()
        memo[_OWNED] = owned
        readers = self._readers
        dependents = self._dependents
        todo: list[Any] = []
        pending = [key for fact_key in changed for key in readers.get(fact_key, ())]
        while pending:
            for key in pending:
                if key[0].__class__ is str:
                    if memo.pop(key, None) is not None:
                        todo.append(key)
                    continue
                table_key = (key[0], key[2])
                table = memo.get(table_key)
                if table is not None and key[1] in table:
                    if table_key not in owned:
                        table = memo[table_key] = dict(table)
                        owned.add(table_key)
                    del table[key[1]]
            pending = [key for atom in todo for key in dependents.get(atom, ())]
            todo = []
        return memo

    def _prove(self, state: Any, atom: Atom) -> bool:
        for axiom in self.rules[atom[0]]:
            names = axiom.head_names
            if names is not None and len(names) == len(atom) - 1:
                env: dict[str, str] | None = dict(zip(names, atom[1:], strict=False))
            else:
                env = _unify(axiom.head_args, atom, {})
                if env is None:
                    continue
            for clause in axiom.condition.clauses:
                for _ in match_clause(clause, state, env, None, self):
                    return True
        return False

    def query(self, state: State, pred: str, args: Sequence[Term], env: dict[str, str]) -> Iterable[dict[str, str]]:
        """Extensions of ``env`` under which ``pred(args)`` (some arguments unbound) is derived, lazily."""
        recorder_in = None
        if isinstance(state, _Recorder):
            recorder_in = state
            state = state.state
        extension = state._derived.get((self._key, pred))
        if extension is None and pred in self.recursive:
            extension = self.extension(state, pred)
        if extension is not None:
            if recorder_in is not None:
                recorder_in.volatile = True
            return candidates(extension, pred, args, env)
        pattern: tuple[str | None, ...] = tuple(
            (env.get(a.name) if a.__class__ is Var else a) for a in args  # type: ignore[misc, union-attr]
        )
        if self.incremental and any(value is not None for value in pattern):
            heads = self._query_heads(state, pred, pattern, recorder_in)
            results = []
            for atom in heads:
                result = _unify(args, atom, env)
                if result is not None:
                    results.append(result)
            return results
        if recorder_in is not None:
            recorder_in.volatile = True
        return self._stream(state, pred, args, env)

    def _query_heads(self, state: State, pred: str, pattern: tuple[str | None, ...],
                     recorder_in: _Recorder | None) -> tuple[Atom, ...]:
        """Every derived atom of a non-recursive ``pred`` matching ``pattern`` (None: any value), memoised.

        The answer is a memo entry keyed ``("?pred", *pattern)``, recorded and inherited like a proof (what it
        read, which derived atoms and nested queries it used), so a query that a successor's changes do not
        reach costs one lookup. Atoms come in the order the rules and their matches give them, first occurrence
        kept, exactly as the streamed evaluation yields them.
        """
        cache = state._derived
        memo = cache.get(self._memo_key)
        if memo is None:
            memo = cache[self._memo_key] = self._inherit(state)
        key = ("?" + pred, *pattern)
        known = memo.get(key)
        if known is None:
            known = cache.get(self._volatile_key, _NO_ENTRIES).get(key)
            if known is not None and recorder_in is not None:
                recorder_in.volatile = True
        if known is None:
            recorder = _Recorder(state)
            heads: list[Atom] = []
            seen: set[Atom] = set()
            for axiom in self.rules[pred]:
                head_env: dict[str, str] | None = {}
                for term, value in zip(axiom.head_args, pattern, strict=True):
                    if value is None:
                        continue
                    if term.__class__ is Var:
                        prior = head_env.get(term.name)  # type: ignore[union-attr]
                        if prior is None:
                            head_env[term.name] = value  # type: ignore[index, union-attr]
                        elif prior != value:
                            head_env = None
                            break
                    elif term != value:
                        head_env = None
                        break
                if head_env is None:
                    continue
                build = axiom.head_builder
                for clause in axiom.condition.clauses:
                    for found in match_clause(clause, recorder, head_env, None, self):
                        atom = build(found)
                        if atom not in seen:
                            seen.add(atom)
                            heads.append(atom)
            known = (tuple(heads),)
            self._store(state, memo, key, known, recorder)
            if recorder.volatile and recorder_in is not None:
                recorder_in.volatile = True
        if recorder_in is not None:
            recorder_in.deps.append(key)
        return known[0]  # type: ignore[no-any-return]

    def _stream(self, state: State, pred: str, args: Sequence[Term], env: dict[str, str]
                ) -> Iterator[dict[str, str]]:
        """Satisfiers of a non-recursive derived atom with unbound arguments, rule by rule, in matching order.

        A clause that starts with a positive fact pattern is evaluated per *seed* (each fact the pattern
        matches, in state order): the rest of the clause for one seed is a memo unit, recorded and inherited
        like a proof, so successor states re-evaluate only the seeds their changes touch.
        """
        pattern: tuple[str | None, ...] = tuple(
            (env.get(a.name) if isinstance(a, Var) else a) for a in args  # type: ignore[misc]
        )
        seen: set[Atom] = set()
        for axiom in self.rules[pred]:
            head_env: dict[str, str] | None = {}
            for term, value in zip(axiom.head_args, pattern, strict=True):
                if value is None:
                    continue
                if isinstance(term, Var):
                    prior = head_env.get(term.name)  # type: ignore[union-attr]
                    if prior is None:
                        head_env[term.name] = value  # type: ignore[index]
                    elif prior != value:
                        head_env = None
                        break
                elif term != value:
                    head_env = None
                    break
            if head_env is None:
                continue
            for clause in axiom.condition.clauses:
                split = self._units.get(id(clause)) if self.incremental else None
                if split is None:
                    heads: Iterable[Atom] = map(axiom.head_builder, match_clause(clause, state, head_env, None, self))
                else:
                    heads = self._unit_heads(state, axiom, split, head_env, pattern)
                for atom in heads:
                    if atom in seen:
                        continue
                    seen.add(atom)
                    result = _unify(args, atom, env)
                    if result is not None:
                        yield result

    def _unit_heads(self, state: State, axiom: Axiom, split: tuple, head_env: dict[str, str],
                    pattern: tuple[str | None, ...]) -> Iterator[Atom]:
        token, first, rest = split
        cache = state._derived
        memo = cache.get(self._memo_key)
        if memo is None:
            memo = cache[self._memo_key] = self._inherit(state)
        pred = first[1]
        vals: list[Any] = [pred]
        free: list[tuple[int, str]] = []
        for arg in first[2]:
            if isinstance(arg, Var):
                value = head_env.get(arg.name)
                if value is None:
                    free.append((len(vals), arg.name))
                vals.append(value)
            else:
                vals.append(arg)
        length = len(vals)
        pool: Iterable[Atom]
        fixed: list[tuple[int, str]] = []
        if not free:
            atom = tuple(vals)
            pool = (atom,) if atom in state else ()
        else:
            bound = [i for i in range(1, length) if vals[i] is not None]
            pool = state.with_arg(pred, bound[0], vals[bound[0]]) if bound else state.atoms_of(pred)
            fixed = [(i, vals[i]) for i in bound[1:]]
        volatile_memo = cache.get(self._volatile_key, _NO_ENTRIES)
        table_key = (token, pattern)
        table = memo.get(table_key)
        if table is not None and not volatile_memo:  # skip the seeds known to give nothing, at C speed
            get = table.get
            pool = [seed for seed in pool if (known := get(seed)) is None or known[0]]
        for seed in pool:
            if len(seed) != length:
                continue
            if fixed and any(seed[i] != v for i, v in fixed):
                continue
            unit = table.get(seed) if table is not None else None
            if unit is None:
                unit = volatile_memo.get((token, seed, pattern))
            if unit is None:
                key = (token, seed, pattern)
                seed_env = dict(head_env)
                consistent = True
                for i, name in free:
                    prior = seed_env.get(name)
                    if prior is None:
                        seed_env[name] = seed[i]
                    elif prior != seed[i]:
                        consistent = False
                        break
                if not consistent:
                    continue
                recorder = _Recorder(state)
                unit = (tuple(map(axiom.head_builder, match_clause(rest, recorder, seed_env, None, self))),)
                self._store(state, memo, key, unit, recorder)
                volatile_memo = cache.get(self._volatile_key, _NO_ENTRIES)
                table = memo.get(table_key)
            yield from unit[0]

    def seeded(self, state: State, spec: tuple, env: dict[str, str]) -> Iterable[dict[str, str]]:
        """Satisfiers of a planner clause (see ``_seeded_spec``) per seed of its first literal, memoised.

        The rest of the clause for one seed (a fact the first literal matches) is a memo unit keyed by the seed
        and the values ``env`` gives the clause's variables, recorded and inherited like an axiom's unit, so a
        successor state re-matches only the seeds its changes reach and skips the seeds known to give nothing.
        Results come in matching order (seeds in state order), as fresh dicts extending ``env``.
        """
        token, first, rest, names, clause = spec
        pred = first[1]
        vals: list[Any] = [pred]
        free: list[tuple[int, str]] = []
        for arg in first[2]:
            if arg.__class__ is Var:
                value = env.get(arg.name)  # type: ignore[union-attr]
                if value is None:
                    free.append((len(vals), arg.name))  # type: ignore[union-attr]
                vals.append(value)
            else:
                vals.append(arg)
        if not free:
            return match_clause(clause, state, env, None, self)
        length = len(vals)
        bound = [i for i in range(1, length) if vals[i] is not None]
        pool: Iterable[Atom] = state.with_arg(pred, bound[0], vals[bound[0]]) if bound else state.atoms_of(pred)
        if len(pool) < SEEDED_MIN:  # type: ignore[arg-type]
            return match_clause(clause, state, env, None, self)
        fixed = [(i, vals[i]) for i in bound[1:]]
        return self._seeded(state, token, rest, names, env, pool, length, fixed, free)

    def _seeded(self, state: State, token: object, rest: Clause, names: tuple[str, ...], env: dict[str, str],
                pool: Iterable[Atom], length: int, fixed: list[tuple[int, str]], free: list[tuple[int, str]]
                ) -> Iterator[dict[str, str]]:
        cache = state._derived
        memo = cache.get(self._memo_key)
        if memo is None:
            memo = cache[self._memo_key] = self._inherit(state)
        pattern = tuple(env.get(name) for name in names)
        base = {name: value for name, value in zip(names, pattern, strict=True) if value is not None}
        volatile_memo = cache.get(self._volatile_key, _NO_ENTRIES)
        table_key = (token, pattern)
        table = memo.get(table_key)
        if table is not None and not volatile_memo:  # skip the seeds known to give nothing, at C speed
            get = table.get
            pool = [seed for seed in pool if (known := get(seed)) is None or known[0]]
        for seed in pool:
            if len(seed) != length:
                continue
            if fixed and any(seed[i] != v for i, v in fixed):
                continue
            unit = table.get(seed) if table is not None else None
            if unit is None:
                unit = volatile_memo.get((token, seed, pattern))
            if unit is None:
                seed_env = dict(base)
                consistent = True
                for i, name in free:
                    prior = seed_env.get(name)
                    if prior is None:
                        seed_env[name] = seed[i]
                    elif prior != seed[i]:
                        consistent = False
                        break
                if not consistent:
                    continue
                recorder = _Recorder(state)
                unit = (tuple(match_clause(rest, recorder, seed_env, None, self)),)
                self._store(state, memo, (token, seed, pattern), unit, recorder)
                volatile_memo = cache.get(self._volatile_key, _NO_ENTRIES)
                table = memo.get(table_key)
            for found in unit[0]:
                result = dict(env)
                result.update(found)
                yield result

    def derived_atoms(self, state: State) -> list[Atom]:
        """Every derived atom true in ``state`` (for display and tests)."""
        atoms: list[Atom] = []
        for pred in sorted(self.rules):
            atoms.extend(sorted(self.extension(state, pred).atoms_of(pred)))
        return atoms

    def _evaluate(self, state: State, component: frozenset[str]) -> None:
        order = sorted(component)  # deterministic derivation order, whatever the string hash seed
        known = {p: DerivedIndex() for p in order}

        def source(pred: str) -> Any:
            index = known.get(pred)
            return index if index is not None else self.extension(state, pred)

        pending: list[Atom] = []
        for pred in order:
            for axiom in self.rules[pred]:
                for clause in axiom.condition.clauses:
                    if any(step[0] == DPOS and step[1] in component for step in clause):
                        continue  # needs atoms of its own component: handled by the delta rounds
                    for env in match_clause(clause, state, {}, None, self, source):
                        pending.append(ground(axiom.head_pred, axiom.head_args, env))
        delta: dict[str, list[Atom]] = {p: [] for p in order}
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
            delta = {p: [] for p in order}
            for atom in pending:
                if known[atom[0]].add(atom):
                    delta[atom[0]].append(atom)
        for pred, index in known.items():
            state._derived[(self._key, pred)] = index
