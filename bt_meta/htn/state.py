"""Immutable symbolic states shared between planner nodes.

Offers:

* :class:`State` -- an immutable set of ground atoms ``(pred, arg1, ...)`` indexed by predicate and, lazily,
  by argument position; :meth:`State.apply` builds a successor that shares every untouched predicate with its
  parent, so keeping the state before every decomposition node costs only the delta.
* :func:`atom_text` -- ``pred(a, b)`` text of an atom, for messages and pretty printing.

The planner's generated code (:mod:`bt_meta.htn.codegen`) reads the private layout directly (``_preds``,
``_by_arg`` keyed by ``(pred, position)``, ``_hash``, ``_len``) and builds successors through
:meth:`State._successor` with :meth:`State._apply`'s steps: a change here must be made there too.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from operator import itemgetter
from typing import Any

Atom = tuple[str, ...]

_MASK = (1 << 64) - 1


def atom_hash(atom: Atom) -> int:
    """The atom's share of a state's hash: Python's tuple hash, mixed (MurmurHash3's 64-bit finaliser).

    A state's hash is the sum of its atoms' shares, kept up to date by adding and subtracting the changed ones.
    Plain tuple hashes do not survive that sum: atoms that swap arguments between them (``on(r1, t3)``,
    ``on(r3, r4)`` against ``on(r1, r4)``, ``on(r3, t3)``) cancel out, and the 1,024 states of a 10-ring Towers
    of Hanoi plan had 266 distinct sums, so every loop check compared whole states. Mixed, they have 1,024.
    """
    h = hash(atom) & _MASK
    h ^= h >> 33
    h = (h * 0xFF51AFD7ED558CCD) & _MASK
    h ^= h >> 33
    return h
_new_state = object.__new__
_PREDICATE = itemgetter(0)
_EMPTY: dict[Atom, None] = {}
INDEX_DEPTH = 8  # how far up the parent chain with_arg looks for an index to update instead of rebuilding


def atom_text(atom: Iterable[str]) -> str:
    pred, *args = tuple(atom)
    return f"{pred}({', '.join(args)})"


class State:
    """An immutable set of ground atoms.

    Atoms of each predicate are kept in insertion order (initial facts in the order given, effects appended),
    which makes matching, and so planning, deterministic whatever the string hash seed. The hash is the sum of
    the atoms' hashes, maintained incrementally by :meth:`apply`, so loop detection compares states in O(1)
    expected time. Derived atoms (axioms) are cached per state in ``_derived`` by the axiom evaluator, which is
    sound because a state never changes.
    """

    __slots__ = ("_by_arg", "_delta", "_derived", "_hash", "_len", "_parent", "_preds")

    def __init__(self, atoms: Iterable[Iterable[str]] = ()) -> None:
        preds: dict[str, dict[Atom, None]] = {}
        for atom in atoms:
            atom_tuple = tuple(str(part) for part in atom)
            if not atom_tuple:
                raise ValueError("an atom needs at least a predicate name")
            preds.setdefault(atom_tuple[0], {})[atom_tuple] = None
        self._preds: dict[str, dict[Atom, None]] = preds
        self._len = sum(len(s) for s in self._preds.values())
        total = 0
        for atoms_of in self._preds.values():
            for atom in atoms_of:
                total += atom_hash(atom)
        self._hash = total & _MASK
        self._by_arg: dict[tuple[str, int], dict[str, tuple[Atom, ...]]] = {}
        self._derived: dict[Any, Any] = {}
        self._parent: State | None = None
        self._delta: tuple[Atom, ...] = ()

    # -- queries -------------------------------------------------------------------------------------------
    def holds(self, atom: Iterable[str]) -> bool:
        atom_tuple = atom if isinstance(atom, tuple) else tuple(atom)
        atoms_of = self._preds.get(atom_tuple[0])
        return atoms_of is not None and atom_tuple in atoms_of

    def __contains__(self, atom: object) -> bool:
        if not isinstance(atom, tuple) or not atom:
            return False
        atoms_of = self._preds.get(atom[0])
        return atoms_of is not None and atom in atoms_of

    def atoms_of(self, pred: str) -> Iterable[Atom]:
        """Every atom of one predicate, in insertion order (do not mutate)."""
        return self._preds.get(pred, _EMPTY).keys()

    def with_arg(self, pred: str, position: int, value: str) -> tuple[Atom, ...]:
        """Atoms of ``pred`` whose argument ``position`` (1-based, as in the tuple) is ``value``."""
        index = self._by_arg.get((pred, position))
        if index is None:
            index = self.index(pred, position)
        return index.get(value, ())

    def index(self, pred: str, position: int) -> dict[str, tuple[Atom, ...]]:
        """The atoms of ``pred`` by their argument ``position`` (do not mutate); generated matchers read it.

        The index of a (predicate, position) is made the first time it is asked for in a state: from the nearest
        ancestor that has it, updated with the changes since (:meth:`_index_from_ancestor`), else from scratch.
        Successors share the indexes of the predicates an action leaves alone; the others are only rebuilt when
        asked for, so a state that is only tested for membership never pays for them.
        """
        key = (pred, position)
        index = self._by_arg.get(key)
        if index is None:
            index = self._index_from_ancestor(pred, position)
            if index is None:
                built: dict[str, list[Atom]] = {}
                for atom in self._preds.get(pred, _EMPTY):
                    if len(atom) > position:
                        built.setdefault(atom[position], []).append(atom)
                index = {k: tuple(v) for k, v in built.items()}
            self._by_arg[key] = index
        return index

    def _index_from_ancestor(self, pred: str, position: int) -> dict[str, tuple[Atom, ...]] | None:
        """The (pred, position) index of the nearest ancestor that has one, with the changes since applied.

        Each step's delta lists its deleted atoms before its added ones (see :meth:`_apply`); an atom of a delta
        was added when the state that made the step holds it. Appending added atoms keeps every index list in
        the predicate's insertion order, exactly as building it from scratch would.
        """
        chain: list[State] = []
        cursor = self
        key = (pred, position)
        for _ in range(INDEX_DEPTH):
            parent = cursor._parent
            if parent is None:
                return None
            chain.append(cursor)
            found = parent._by_arg.get(key)
            if found is not None:
                break
            cursor = parent
        else:
            return None
        index = dict(found)
        for state in reversed(chain):
            atoms_of = state._preds.get(pred, _EMPTY)
            for atom in state._delta:
                if atom[0] != pred or len(atom) <= position:
                    continue
                key = atom[position]
                if atom in atoms_of:
                    index[key] = (*index.get(key, ()), atom)
                else:
                    remaining = tuple(a for a in index.get(key, ()) if a != atom)
                    if remaining:
                        index[key] = remaining
                    else:
                        index.pop(key, None)
        return index

    def with_first(self, pred: str, first: str) -> tuple[Atom, ...]:
        """Atoms of ``pred`` whose first argument is ``first``."""
        return self.with_arg(pred, 1, first)

    def predicates(self) -> list[str]:
        return sorted(self._preds)

    def __iter__(self) -> Iterator[Atom]:
        for atoms_of in self._preds.values():
            yield from atoms_of

    def __len__(self) -> int:
        return self._len

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, State):
            return NotImplemented
        if self is other:
            return True
        if self._hash != other._hash or self._len != other._len or self._preds.keys() != other._preds.keys():
            return False
        return all(atoms.keys() == other._preds[p].keys() for p, atoms in self._preds.items())

    def __repr__(self) -> str:
        shown = ", ".join(atom_text(a) for a in sorted(self)[:8])
        more = f", ... ({self._len} atoms)" if self._len > 8 else ""
        return f"State({shown}{more})"

    # Immutable: copies are the state itself; pickling keeps only the atoms (not the parent chain or caches).
    def __copy__(self) -> State:
        return self

    def __deepcopy__(self, memo: dict[int, Any]) -> State:
        return self

    def __reduce__(self) -> tuple[Any, ...]:
        return (State, (list(self),))

    def to_list(self) -> list[list[str]]:
        """The atoms as sorted lists, the JSON form."""
        return [list(atom) for atom in sorted(self)]

    # -- successors ----------------------------------------------------------------------------------------
    def apply(self, add: Iterable[Iterable[str]] = (), delete: Iterable[Iterable[str]] = ()) -> State:
        """The successor state: ``(self - delete) | add`` (add wins when an atom is in both, as in STRIPS)."""
        add_t = [a if isinstance(a, tuple) else tuple(a) for a in add]
        del_t = [a if isinstance(a, tuple) else tuple(a) for a in delete]
        return self._apply(add_t, del_t)

    def _apply(self, add: list[Atom], delete: list[Atom]) -> State:
        """:meth:`apply` for lists of atom tuples (the planner's hot path)."""
        preds = self._preds
        changed: dict[str, dict[Atom, None]] = {}  # predicate -> its successor dict (copied on first change)
        delta: list[Atom] = []
        hash_ = self._hash
        length = self._len
        for atom in delete:
            pred = atom[0]
            atoms_of = changed.get(pred)
            if atoms_of is None:
                atoms_of = preds.get(pred)
                if atoms_of is None or atom not in atoms_of or atom in add:
                    continue
                atoms_of = changed[pred] = atoms_of.copy()
            elif atom not in atoms_of or atom in add:
                continue
            del atoms_of[atom]
            hash_ -= atom_hash(atom)
            length -= 1
            delta.append(atom)
        fresh: list[Atom] = []
        for atom in add:
            atoms_of = changed.get(atom[0])
            if atoms_of is None:
                atoms_of = preds.get(atom[0])
            if (atoms_of is None or atom not in atoms_of) and atom not in fresh:
                fresh.append(atom)
        if len(fresh) > 1 and len(set(map(_PREDICATE, fresh))) < len(fresh):
            # several new atoms of one predicate go in sorted, predicates in the order they first appear
            grouped: dict[str, list[Atom]] = {}
            for atom in fresh:
                grouped.setdefault(atom[0], []).append(atom)
            fresh = [atom for group in grouped.values() for atom in sorted(group)]
        for atom in fresh:
            pred = atom[0]
            atoms_of = changed.get(pred)
            if atoms_of is None:
                found = preds.get(pred)
                atoms_of = changed[pred] = found.copy() if found is not None else {}
            atoms_of[atom] = None
            hash_ += atom_hash(atom)
        if not fresh and not delta:
            return self
        delta.extend(fresh)
        return self._successor(changed, delta, hash_, length + len(fresh))

    def _successor(self, changed: dict[str, dict[Atom, None]], delta: list[Atom], hash_: int, length: int) -> State:
        """The state whose predicates in ``changed`` are the given dicts (an empty one drops the predicate).

        ``delta`` lists the atoms deleted, then those added; ``hash_`` and ``length`` are the successor's. Shared by
        :meth:`_apply` and the generated primitive code (:meth:`bt_meta.htn.codegen.Generated.primitive_stepper`).
        """
        new_preds = self._preds.copy()
        for pred, atoms_of in changed.items():
            if atoms_of:
                new_preds[pred] = atoms_of
            else:
                new_preds.pop(pred, None)
        successor = _new_state(State)
        successor._preds = new_preds
        successor._len = length
        successor._hash = hash_ & _MASK
        # indexes of unchanged predicates are shared; the others are remade on demand (see index)
        by_arg = self._by_arg
        if by_arg:
            by_arg = by_arg.copy()
            for key in self._by_arg:
                if key[0] in changed:
                    del by_arg[key]
        else:
            by_arg = {}
        successor._by_arg = by_arg
        successor._derived = {}
        # parent and changed atoms let indexes and axiom memos be inherited (see index, AxiomSet.holds)
        successor._parent = self
        successor._delta = tuple(delta)
        return successor
