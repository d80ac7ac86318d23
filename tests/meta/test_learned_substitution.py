"""A refinement learned from an object substitution is used the next time the same blocks are seen (simulator).

Letters A and H are recorded; A with two red 1x1 blocks instead of the blue 1x2 is repaired by splicing H's bar
(one attempt) and saved as a refinement whose precondition holds the starting poses and what was seen of the
new blocks, with the facts substitution anchored and the goal the splice rewrote. The second run plans with it
and needs no repair; the nominal scene (the blue 1x2 back) and a scene with a blue 1x1 as b6 do not use it.
"""

from __future__ import annotations

from typing import Any

import pytest

from bt_meta.meta import Limits, MetaExecutor, RefinementStore
from bt_meta.resources import trees_dir

pytestmark = pytest.mark.slow

LETTERS = trees_dir() / "letters.yaml"
A_CELLS = sorted([(0.0, 0.0), (0.0, 1.0), (3.0, 0.0), (3.0, 1.0), (1.0, 1.0), (2.0, 1.0), (1.5, 2.0)])


@pytest.fixture(scope="module")
def memory_file(tmp_path_factory):
    """A memory with the nominal A and H recorded by ``bt-meta record``'s code."""
    from bt_meta.commands.record import demonstrate
    from bt_meta.memory import EpisodicMemory
    from bt_meta.plugins import create_plugin_host

    path = tmp_path_factory.mktemp("learned_substitution") / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        for problem in ("A", "H"):
            demonstrate(LETTERS, problem, memory, plugins=create_plugin_host(entry_points=False, plugins=[]))
    return path


def run_a(memory_file: Any, variant: str | None) -> tuple[Any, list[tuple[float, float]], set[Any]]:
    """Problem A in ``variant`` with repairs, the memory's refinements and the shipped plugins (entry points)."""
    from bt_meta.experiments.substitution import letter_cells
    from bt_meta.htn import load_task_file
    from bt_meta.memory import EpisodicMemory
    from bt_meta.plugins import create_plugin_host
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(LETTERS)
    problem = task_file.problem("A")
    with quiet_stdout():
        world = SimWorld(task_file.domain, problem, load_grounding("letters", LETTERS), variant=variant, seed=0)
    try:
        with EpisodicMemory.open(memory_file) as memory, RefinementStore.open(memory_file) as store:
            report = MetaExecutor(task_file.domain, problem, world, create_plugin_host(project_file=LETTERS),
                                  task_file=task_file, limits=Limits(max_attempts=3, max_seconds=120),
                                  refinements=store, variant=variant, memory=memory).run()
        cells = sorted((round(u * 2) / 2, round(v * 2) / 2) for u, v in letter_cells(world))
        return report, cells, set(world.symbolic_state())
    finally:
        world.close()


def test_substitution_refinement_is_used_for_the_same_blocks_and_only_for_them(memory_file):
    first, cells, state = run_a(memory_file, "A_two_1x1_same_colour")
    assert first.ok, first.stop_reason
    # the bar step's placement was undone when substitution anchored the blocks: the belief is where they are
    assert ("at", "b5", "1", "1") in state and ("at", "b5", "1.5", "1") not in state
    assert [(a.kind, a.proposal["action"], a.proposal["plugin"]) for a in first.attempts] == [
        ("unknown_entity", "splice", "object_substitution")]
    assert ["place", "b5", "1", "1"] in first.plan and ["place", "b6", "2", "1"] in first.plan
    assert cells == A_CELLS
    saved = first.refinement_saved
    assert saved and saved.get("method", "").startswith("refined_draw_A_"), saved
    # what substitution anchored from perception is kept, and must be seen again for the refinement to apply
    for condition in ("seen(b5, shape, 1x1)", "seen(b5, colour, red)", "seen(b6, shape, 1x1)",
                      "seen(b6, colour, red)", "pose_within(b6, 0.64"):
        assert condition in saved["precondition"], saved["precondition"]
    assert saved["facts"] == {  # how what was seen differs from what problem A assumed
        "add": [["available", "b6"], ["block", "b6"], ["colour", "b5", "red"], ["colour", "b6", "red"],
                ["shape", "b5", "1x1"], ["shape", "b6", "1x1"]],
        "delete": [["colour", "b5", "blue"], ["shape", "b5", "1x2"]]}
    assert saved["goal"] == [["at", "b5", "1", "1"], ["at", "b6", "2", "1"]]  # the splice's rewrite of at(b5, 1.5, 1)

    second, cells, state = run_a(memory_file, "A_two_1x1_same_colour")
    assert second.ok, (second.stop_reason, second.message)
    assert second.attempts == [] and second.refinements_used == [saved["method"]]
    assert second.initial_plan == first.plan and second.refinement_saved is None
    assert cells == A_CELLS
    assert {("at", "b5", "1", "1"), ("at", "b6", "2", "1")} <= state and ("at", "b5", "1.5", "1") not in state

    nominal, cells, state = run_a(memory_file, None)
    assert nominal.ok and nominal.attempts == [] and nominal.refinements_used == []
    assert ["place", "b5", "1.5", "1"] in nominal.plan
    assert not any("b6" in fact for fact in state) and ("shape", "b5", "1x2") in state  # nothing anchored

    # b6 seen blue, not red: the same-colour refinement does not apply (this variant is repaired on its own)
    other, _, _ = run_a(memory_file, "A_two_1x1_different_colours")
    assert saved["method"] not in other.refinements_used
    assert other.ok and len(other.attempts) == 1, other.stop_reason
    with RefinementStore.open(memory_file, readonly=True) as store:
        assert {r.variant for r in store.list(domain="letters")} == {"A_two_1x1_same_colour",
                                                                     "A_two_1x1_different_colours"}
