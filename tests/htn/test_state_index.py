"""Per-argument indexes made from an ancestor's index plus the changes since equal indexes built from scratch."""

from __future__ import annotations

import random

import pytest

from bt_meta.htn.state import INDEX_DEPTH, State


def _random_step(state: State, rng: random.Random, names: list[str]) -> State:
    atoms = list(state)
    delete = rng.sample(atoms, k=min(len(atoms), rng.randint(0, 3)))
    add = [(rng.choice(["on", "clear", "at"]), *rng.sample(names, 2)) for _ in range(rng.randint(0, 3))]
    add = [a[:2] if a[0] == "clear" else a for a in add]
    if rng.random() < 0.3 and delete:
        add.append(delete[0])  # deleted and added in one step: add wins
    return state.apply(add=add, delete=delete)


@pytest.mark.parametrize("seed", range(8))
def test_index_from_ancestor_matches_fresh_build(seed: int) -> None:
    rng = random.Random(seed)
    names = [f"b{i}" for i in range(6)]
    state = State([("on", "b0", "b1"), ("on", "b2", "b3"), ("clear", "b0"), ("clear", "b2"), ("at", "b4", "b5")])
    queried = [state]
    for step in range(3 * INDEX_DEPTH):
        state = _random_step(state, rng, names)
        if rng.random() < 0.4:  # only some states ask for indexes, as in a search
            queried.append(state)
            for pred, position in (("on", 1), ("on", 2), ("clear", 1), ("at", 2)):
                for value in names:
                    fresh = State(list(state))  # no parent: built from scratch, same insertion order
                    assert state.with_arg(pred, position, value) == fresh.with_arg(pred, position, value), \
                        (step, pred, position, value)
    # the indexes of earlier states are unchanged by what their successors did
    for old in queried:
        fresh = State(list(old))
        for value in names:
            assert old.with_arg("on", 1, value) == fresh.with_arg("on", 1, value)
