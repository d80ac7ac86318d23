"""Which failures object substitution answers and how its proposals rank (``bt_meta_plugins.object_substitution``),
on hand-built failures: a method guard naming a missing block, a proposal that leaves the failed step's block as it
was, a block seen only in another colour."""

from __future__ import annotations

from types import SimpleNamespace

import bt_meta_plugins.object_substitution as substitution
from bt_meta_plugins._mismatch import Entity, MismatchVector

from bt_meta.bt.failures import Failure, FailureKind, RepairProposal


def _guard_failure(bindings: dict[str, str] | None) -> Failure:
    evidence = {"condition": "usable(?b0, 1x1, blue) and usable(?b1, 1x1, blue) and ?b0 != ?b1"}
    if bindings is not None:
        evidence["bindings"] = bindings
    return Failure(kind=FailureKind.PRECONDITION, message="precondition of method leg_two_1x1 does not hold",
                   evidence=evidence)


def test_a_method_guard_names_the_blocks_its_method_bound():
    """A leg method's guard fails once its first block is seen as a 1x2 (no step, no arguments): the entities it
    bound are what the failure is about."""
    vector = MismatchVector(None, (Entity("b0", "1x1", "blue"), Entity("b1", "1x1", "blue")),
                            (Entity("b0", "1x2", "blue"),))
    assert substitution._names_missing(_guard_failure({"x": "0", "b0": "b0", "b1": "b1"}), vector)
    assert not substitution._names_missing(_guard_failure(None), vector)
    assert not substitution._names_missing(_guard_failure({"x": "3", "b0": "b2", "b1": "b3"}), vector)


def test_a_proposal_that_leaves_the_failed_step_as_it_was_ranks_below_those_that_change_it():
    """place(b0, 0, 0) failed because b0 is a 1x2; b5 is missing too. Substituting b5's spare or rebinding b5
    (scored higher) would run the same failing placement again, so the tiling that moves b0 comes first."""
    failure = Failure(kind=FailureKind.UNKNOWN_ENTITY, message="b0 seen as a 1x2", step=0, action="place",
                      args=("b0", "0", "0"))
    vector = MismatchVector(0, (Entity("b0", "1x1", "blue"), Entity("b5", "1x2", "blue")),
                            (Entity("b0", "1x2", "blue"), Entity("spare_b5", "1x2", "blue")))
    spare = RepairProposal("substitute", 0.85, changes={"mapping": {"b5": "spare_b5"}, "from_step": 0})
    tiling = RepairProposal("splice", 0.6, changes={"start": 0, "end": 6, "actions": [["place", "b0", "0.5", "1"]]})
    later = RepairProposal("splice", 0.7,
                           changes={"start": 4, "end": 6, "actions": [["place", "spare_b5", "1.5", "1"]]})
    rebind = RepairProposal("rebind", 0.86, changes={"symbols": {"b5": "spare_b5"}, "from_step": 0})
    ranked = substitution._mending_first([spare, rebind, later, tiling], failure, vector, SimpleNamespace(world=None))
    assert ranked[0] is tiling
    assert all(p.score < tiling.score and "does not change what failed step 0 does with b0" in p.evidence["demoted"]
               for p in ranked[1:])
    # nothing mends it: the scores stand
    assert [p.score for p in substitution._mending_first([spare, later], failure, vector, None)] == [0.85, 0.7]


class _Beliefs:
    def __init__(self, facts: set[tuple[str, ...]]) -> None:
        self.facts = set(facts)
        self.applied: list[tuple[list, list]] = []

    def symbolic_state(self) -> set[tuple[str, ...]]:
        return set(self.facts)

    def apply_symbolic(self, add=(), delete=()) -> None:
        self.applied.append((list(add), list(delete)))
        self.facts = (self.facts - set(delete)) | set(add)


def test_a_block_seen_only_in_another_colour_keeps_its_facts_while_a_stand_in_gets_its_own():
    """b4 (the apex) is yellow where the problem says blue, b5 is replaced by a spare: anchoring the spare's facts
    lets the spliced steps' guards see it; anchoring b4's colour would fail the apex method's guard, and b4 still
    fills its own role (the grid-maps compare form)."""
    facts = {("available", "b4"), ("shape", "b4", "1x1"), ("colour", "b4", "blue"), ("available", "b5"),
             ("shape", "b5", "1x2"), ("colour", "b5", "blue")}
    world = _Beliefs(facts)
    problem = SimpleNamespace(state=sorted(facts), init=sorted(facts))
    context = SimpleNamespace(world=world, run=SimpleNamespace(problem=problem), effects=([], []))
    vector = MismatchVector(4, (Entity("b4", "1x1", "blue"), Entity("b5", "1x2", "blue")),
                            (Entity("b4", "1x1", "yellow"), Entity("spare_b5", "1x2", "blue")))
    failure = Failure(kind=FailureKind.UNKNOWN_ENTITY, message="b5 missing", step=4, action="place",
                      args=("b5", "1.5", "1"))
    proposals = [RepairProposal("splice", 0.6, changes={"start": 4, "end": 6, "actions": [
        ["place", "spare_b5", "1.5", "1"], ["place", "b4", "1.5", "2"]]})]
    substitution.ObjectSubstitution().anchor_entities(vector, failure, context, proposals)
    assert ("colour", "b4", "blue") in world.facts and ("colour", "b4", "yellow") not in world.facts
    assert {("shape", "spare_b5", "1x2"), ("colour", "spare_b5", "blue"), ("available", "spare_b5")} <= world.facts
