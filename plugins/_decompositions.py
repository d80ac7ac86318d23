"""The decompositions object substitution retrieves (paper, section 6.4, steps 3-5): task occurrences of the
episodic memory's successful episodes with the shape and colour of their blocks, and the one-to-one binding of a
decomposition's blocks to the entities seen.

Offers:

* :class:`Decomposition` -- one stored task occurrence: its calls and its blocks' (shape, colour)
* :func:`bind` -- a one-to-one binding of a decomposition's blocks to entities (shape, and colour when asked)
* :func:`why_not` -- why a decomposition cannot be bound, in words
* :class:`Library` -- P_a of every successful episode, indexed, read once per retrieval
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from bt_meta_plugins._mismatch import Entity, attributes

__all__ = ["MAX_BINDING", "Decomposition", "Library", "bind", "why_not"]

MAX_BINDING = 6
"""Entities bound by brute force; a variant replacing more blocks than this is not searched."""


@dataclass(frozen=True)
class Decomposition:
    """One stored task occurrence: its steps (calls) and the shape and colour of the blocks they use."""

    episode_id: int
    task: str
    parent_task: str | None
    parent_node: str | None
    first_step: int
    calls: tuple[tuple[str, tuple[str, ...]], ...]
    blocks: Mapping[str, tuple[str | None, str | None]]

    def block_args(self) -> list[str]:
        """The blocks used, in the order the steps first name them."""
        seen: list[str] = []
        for _, args in self.calls:
            for arg in args:
                if arg in self.blocks and arg not in seen:
                    seen.append(arg)
        return seen

    def lifted_facts(self) -> Counter[tuple[Any, ...]]:
        """The symbolic expectation without object names: each block's shape and colour, each step's other
        arguments (a placement's cell)."""
        facts: Counter[tuple[Any, ...]] = Counter()
        for name in self.block_args():
            shape, colour = self.blocks[name]
            facts[("shape", shape)] += 1
            facts[("colour", colour)] += 1
        for action, args in self.calls:
            facts[(action, *(a for a in args if a not in self.blocks))] += 1
        return facts

    def signature(self) -> tuple[Any, ...]:
        """What two occurrences of the same decomposition share (blocks lifted to their kind)."""
        return (self.parent_task, tuple(
            (action, tuple(self.blocks.get(a, a) for a in args)) for action, args in self.calls))

    def describe(self) -> str:
        return "; ".join(f"{a}({', '.join(args)})" for a, args in self.calls)


# -- binding ------------------------------------------------------------------------------------------------------


def bind(decomposition: Decomposition, entities: Sequence[Entity], *, colour: bool) -> dict[str, str] | None:
    """A one-to-one binding of the decomposition's blocks to ``entities`` (all of them used), matching shape (and
    colour when ``colour``); the first in name order, or ``None``."""
    blocks = decomposition.block_args()
    if len(blocks) != len(entities) or not blocks or len(blocks) > MAX_BINDING:
        return None
    ordered = sorted(entities, key=lambda e: e.name)
    for permutation in itertools.permutations(ordered):
        ok = True
        for block, entity in zip(blocks, permutation, strict=True):
            shape, block_colour = decomposition.blocks[block]
            if entity.shape != shape or (colour and entity.colour != block_colour):
                ok = False
                break
        if ok:
            return {block: entity.name for block, entity in zip(blocks, permutation, strict=True)}
    return None


def why_not(decomposition: Decomposition, entities: Sequence[Entity], *, colour: bool) -> str:
    needs = ", ".join(f"{(c or '?') + ' ' if colour else ''}{s}" for s, c in
                      (decomposition.blocks[b] for b in decomposition.block_args()))
    has = ", ".join(f"{(e.colour or '?') + ' ' if colour else ''}{e.shape}" for e in entities) or "nothing"
    return f"needs {needs}; the unknown entities are {has}"


# -- the memory's side ----------------------------------------------------------------------------------------------


class Library:
    """P_a of every successful episode, indexed, with each episode's block attributes (read once per call)."""

    def __init__(self, memory: Any) -> None:
        self.memory = memory
        self.rows = memory.plan_executions()
        self.by_step = {(r.episode_id, r.step_index): r for r in self.rows}
        self._attributes: dict[int, dict[str, tuple[str | None, str | None]]] = {}

    def attributes(self, episode_id: int) -> dict[str, tuple[str | None, str | None]]:
        found = self._attributes.get(episode_id)
        if found is None:
            trace = self.memory.trace(episode_id)
            facts = list(trace.initial.facts) + [f for s in trace.steps for f in s.state.facts]
            found = self._attributes[episode_id] = attributes(facts)
        return found

    def occurrence(self, episode_id: int, step_index: int) -> Decomposition | None:
        """The task occurrence step ``step_index`` of an episode belongs to (consecutive steps, same parent)."""
        row = self.by_step.get((episode_id, step_index))
        if row is None:
            return None
        key = (row.parent_task, row.parent_node)
        first = step_index
        while (prev := self.by_step.get((episode_id, first - 1))) is not None \
                and (prev.parent_task, prev.parent_node) == key:
            first -= 1
        calls = []
        index = first
        while (r := self.by_step.get((episode_id, index))) is not None and (r.parent_task, r.parent_node) == key:
            calls.append((r.action, tuple(str(a) for a in r.args)))
            index += 1
        attributes = self.attributes(episode_id)
        blocks = {a: attributes[a] for _, args in calls for a in args if a in attributes}
        return Decomposition(episode_id, row.task, row.parent_task, row.parent_node, first, tuple(calls), blocks)

    def ends_task(self, episode_id: int, step_index: int) -> bool:
        row = self.by_step.get((episode_id, step_index))
        nxt = self.by_step.get((episode_id, step_index + 1))
        return row is not None and (nxt is None or (nxt.parent_task, nxt.parent_node)
                                    != (row.parent_task, row.parent_node))

    def occurrences(self) -> list[Decomposition]:
        out = []
        for row in self.rows:
            if self.ends_task(row.episode_id, row.step_index):
                found = self.occurrence(row.episode_id, row.step_index)
                if found is not None:
                    out.append(found)
        return out


