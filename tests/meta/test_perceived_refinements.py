"""Refinements that rely on perceived entities (fake world, no simulator): what object substitution anchored is
kept with the refinement, guarded by ``seen`` conditions, added to the state when the same blocks are seen again,
and the goal is the one the splice rewrote. Also the pieces: ``seen``, :func:`rewrite_goal`, the store round trip.
"""

from __future__ import annotations

from typing import Any

import pytest
from bt_meta_plugins import object_substitution, refinement_predicates

from bt_meta.bt.context import RunContext
from bt_meta.errors import PluginError
from bt_meta.htn import load_task_file
from bt_meta.memory import EpisodicMemory
from bt_meta.meta import MetaExecutor, RefinementStore
from bt_meta.meta.refinements import domain_with_pose_predicate, rewrite_goal, seen_holds
from bt_meta.resources import trees_dir
from bt_meta.world.fake import FakeWorld, Fault

from .conftest import make_host
from .test_object_substitution import A_STEPS, H_STEPS, letter_trace

LETTERS = trees_dir() / "letters.yaml"
NOMINAL = {f"b{i}": ("1x1", "blue", [0.55 + 0.09 * (i % 3), -0.31 - 0.09 * (i // 3), 0.0, 0.0, 0.0, 0.0])
           for i in range(5)}
NOMINAL_SCENE = {**NOMINAL, "b5": ("1x2", "blue", [0.60, -0.50, 0.0, 0.0, 0.0, 0.0])}
TWO_RED = {**NOMINAL, "b5": ("1x1", "red", [0.56, -0.50, 0.0, 0.0, 0.0, 0.0]),
           "b6": ("1x1", "red", [0.65, -0.50, 0.0, 0.0, 0.0, 0.0])}
RED_AND_BLUE = {**TWO_RED, "b6": ("1x1", "blue", [0.65, -0.50, 0.0, 0.0, 0.0, 0.0])}


class SceneWorld(FakeWorld):
    """The fake world of problem A's symbols with the blocks a camera would report; a 1x1 block put where A's
    1x2 bar goes fails with ``unknown_entity``, as the grid-map monitor objects in the simulator."""

    def __init__(self, domain: Any, problem: Any, scene: dict[str, tuple[str, str, list[float]]]) -> None:
        faults = ["place(b5, 1.5, 1)=fail:unknown_entity"] if scene["b5"][0] == "1x1" else []
        super().__init__(domain, problem, faults=faults)
        self.scene = scene

    def observe(self) -> dict[str, Any]:
        return {"symbolic_state": self.symbolic_state(),
                "objects": {n: {"name": n, "shape": s, "colour": c, "pose": list(p)}
                            for n, (s, c, p) in self.scene.items()}}


@pytest.fixture
def letters():
    return load_task_file(LETTERS)


@pytest.fixture
def memory_file(letters, tmp_path):
    path = tmp_path / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        memory.write(letter_trace(letters, "A", A_STEPS, 1000.0))
        memory.write(letter_trace(letters, "H", H_STEPS, 2000.0))
    return path


def run_a(letters: Any, memory_file: Any, scene: dict[str, Any]) -> tuple[Any, SceneWorld]:
    problem = letters.problem("A")
    world = SceneWorld(letters.domain, problem, scene)
    host = make_host(("object_substitution", object_substitution.ObjectSubstitution(matcher="gridmap")))
    with EpisodicMemory.open(memory_file) as memory, RefinementStore.open(memory_file) as store:
        report = MetaExecutor(letters.domain, problem, world, host, refinements=store, memory=memory,
                              variant="two red 1x1").run()
    return report, world


def test_the_substituted_blocks_are_remembered_and_the_refinement_applies_only_when_seen_again(letters, memory_file):
    first, world = run_a(letters, memory_file, TWO_RED)
    assert first.ok, first.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in first.attempts] == [("unknown_entity", "splice")]
    assert ("at", "b6", "2", "1") in world.symbolic_state()
    saved = first.refinement_saved
    assert saved["facts"]["add"] == [["available", "b6"], ["block", "b6"], ["colour", "b5", "red"],
                                     ["colour", "b6", "red"], ["shape", "b5", "1x1"], ["shape", "b6", "1x1"]]
    assert saved["facts"]["delete"] == [["colour", "b5", "blue"], ["shape", "b5", "1x2"]]
    assert saved["precondition"].endswith("seen(b5, colour, red) and seen(b5, shape, 1x1) and seen(b6, colour, red)"
                                          " and seen(b6, shape, 1x1)")
    assert saved["goal"] == [["at", "b5", "1", "1"], ["at", "b6", "2", "1"]]

    second, world = run_a(letters, memory_file, TWO_RED)
    assert second.ok and second.attempts == [] and second.refinements_used == [saved["method"]]
    assert second.initial_plan == first.plan and second.refinement_saved is None
    assert {("at", "b5", "1", "1"), ("at", "b6", "2", "1")} <= set(world.symbolic_state())
    assert ("at", "b5", "1.5", "1") not in world.symbolic_state()  # verified against the rewritten goal

    nominal, world = run_a(letters, memory_file, NOMINAL_SCENE)
    assert nominal.ok and nominal.attempts == [] and nominal.refinements_used == []
    assert ("at", "b5", "1.5", "1") in world.symbolic_state()
    assert not any("b6" in fact for fact in world.symbolic_state())  # nothing of the refinement was added

    other, _ = run_a(letters, memory_file, RED_AND_BLUE)  # b6 seen blue: not the blocks the refinement saw
    assert saved["method"] not in other.refinements_used and len(other.attempts) == 1 and other.ok


def test_a_refinement_stores_and_reads_back_its_facts_and_goal(letters, memory_file):
    run_a(letters, memory_file, TWO_RED)
    with RefinementStore.open(memory_file, readonly=True) as store:
        (refinement,) = store.list(domain="letters")
        add, delete = refinement.fact_atoms()
        assert ("block", "b6") in add and ("shape", "b5", "1x2") in delete
        assert refinement.goal_atoms() == [("at", "b5", "1", "1"), ("at", "b6", "2", "1")]
        assert "facts" not in refinement.repair and refinement.repair["attempts"] == 1
        exported = store.export_yaml(letters.domain)
    assert "seen:\n    - object\n    - object\n    - object" in exported


def test_seen_predicate_reads_the_installed_run_world(letters):
    world = SceneWorld(letters.domain, letters.problem("A"), TWO_RED)
    hook = refinement_predicates.bt_meta_external_predicate
    assert hook("seen", ("b6", "colour", "red"), None) is False  # no run installed: not confirmed
    RunContext(world).install()
    assert hook("seen", ("b6", "colour", "red"), None) is True
    assert hook("seen", ("b6", "colour", "blue"), None) is False
    assert hook("seen", ("b7", "colour", "red"), None) is False
    assert hook("seen", ("b6", "weight", "red"), None) is False
    assert hook("at", ("b6", "1", "1"), None) is None
    with pytest.raises(PluginError, match=r"seen takes 3 arguments \(object, attribute, value\), got 2"):
        hook("seen", ("b6", "colour"), None)
    assert seen_holds({"b6": {"shape": "1x1"}}, "b6", "shape", "1x1")


def test_rewrite_goal_replaces_what_the_repaired_plan_no_longer_achieves(letters):
    domain = letters.domain
    problem = letters.problem("A")
    old = [["place", "b5", "1.5", "1"], ["place", "b4", "1.5", "2"]]
    new = [["place", "b5", "1", "1"], ["place", "b6", "2", "1"], ["place", "b4", "1.5", "2"]]
    start_new = problem.state.apply(add=[("block", "b6"), ("available", "b6")])
    assert rewrite_goal(domain, problem.goal, old, new, problem.state, start_new) == [
        ("at", "b5", "1", "1"), ("at", "b6", "2", "1")]
    # every goal fact still achieved (another block for the apex): the goal stays
    other = [["place", "b5", "1.5", "1"], ["place", "b3", "1.5", "2"]]
    assert rewrite_goal(domain, problem.goal, old, other, problem.state, problem.state) == [("at", "b5", "1.5", "1")]
    assert rewrite_goal(domain, problem.goal, old, old, problem.state, problem.state) == [("at", "b5", "1.5", "1")]
    assert rewrite_goal(domain, [], old, new, problem.state, start_new) == []
    # a re-tiling took the drawn bar off its place mid-plan (its at fact undone) and laid it elsewhere: the undone
    # fact no longer counts as achieved, and the goal becomes what the re-tiled plan achieves
    retiled = [["place", "b5", "1.5", "1"], ["place", "b5", "0.5", "1"], ["place", "b4", "1.5", "2"]]
    assert rewrite_goal(domain, problem.goal, old, retiled, problem.state, problem.state) == [("at", "b5", "1.5", "1")]
    assert rewrite_goal(domain, problem.goal, old, retiled, problem.state, problem.state,
                        undone=[("at", "b5", "1.5", "1")]) == [("at", "b5", "0.5", "1")]


def test_a_domain_already_using_seen_cannot_take_refinements(letters):
    import dataclasses

    from bt_meta.htn.conditions import DomainContext
    from bt_meta.meta import RefinementError

    domain = letters.domain
    clash = dataclasses.replace(domain, context=DomainContext(
        arities={**domain.context.arities, "seen": 2}, derived=set(domain.context.derived),
        external=set(domain.context.external), axioms=domain.context.axioms))
    with pytest.raises(RefinementError, match="domain letters already uses 'seen' for something else"):
        domain_with_pose_predicate(clash)


def test_a_failed_replay_falls_back_to_the_hand_written_plan_without_the_refinement_s_facts(letters, memory_file):
    """The learned plan's first substituted placement fails on replay (on the Panda, the grasp of b5 beside the spare
    collides from where b5 starts; the learning run grasped it where the failed placement had left it). The run
    goes back to the hand-written plan at that step with the refinement's perceived facts taken out of the world's
    state -- with them, b5 believed a 1x1, the hand-written methods plan nothing and the first exposure's own repair
    is never reached -- and repairs it as the first exposure did (letters_A Panda s11 0008)."""
    first, _ = run_a(letters, memory_file, TWO_RED)
    method = first.refinement_saved["method"]
    problem = letters.problem("A")
    world = SceneWorld(letters.domain, problem, TWO_RED)
    world.faults.append(Fault.parse("place(b5, 1, 1)#1=fail:collision"))
    host = make_host(("object_substitution", object_substitution.ObjectSubstitution(matcher="gridmap")), retry=False)
    with EpisodicMemory.open(memory_file) as memory, RefinementStore.open(memory_file) as store:
        second = MetaExecutor(letters.domain, problem, world, host, refinements=store, memory=memory,
                              variant="two red 1x1").run()
        (stored,) = store.list()
    assert second.refinements_used == [method] and second.refinements_demoted == [method]
    assert second.fallback["to"] == "the hand-written plan from step 4 (the refinements' perceived facts taken back)"
    assert second.ok, second.stop_reason
    assert [(a.kind, a.proposal["plugin"]) for a in second.attempts] == [("unknown_entity", "object_substitution")]
    assert second.plan == first.plan
    assert (stored.method, stored.status, stored.failures) == (method, "demoted", 1)
