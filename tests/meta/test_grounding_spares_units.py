"""``rebind_proposals`` on a hand-built world (no simulator): a missing entity with a spare of its type is rebound,
but a motion failure of a step that does not use it is not answered by rebinding it (generated letters_A s1 0052:
b0 lay on its side and its carry collided; rebinding the missing b2 then ran the failed placement again, with b0
still in the gripper)."""

from __future__ import annotations

from types import SimpleNamespace

from bt_meta_plugins._grounding_spares import rebind_proposals

from bt_meta.bt.failures import Failure, FailureKind


class _World:
    grounding = SimpleNamespace(features={}, objects={}, poses={})
    scene = SimpleNamespace(objects=[SimpleNamespace(name=n, type="megablok_1x1") for n in ("b0", "b2")])

    def observe(self):
        return {"objects": {"b0": {"type": "megablok_1x1"}, "spare_b2": {"type": "megablok_1x1"}}}

    def rebind_object(self, symbol, name):
        raise AssertionError("proposing rebinds nothing")

    def pose_spec(self, symbol):
        return {}


def _failure(kind: FailureKind, step: int) -> Failure:
    plan = [{"step": 0, "action": "place", "args": ["b0", "0", "0"], "done": False},
            {"step": 1, "action": "place", "args": ["b2", "3", "0"], "done": False}]
    return Failure(kind=kind, message="failed", step=step, action="place", args=tuple(plan[step]["args"]),
                   evidence={"plan": plan})


def _context():
    problem = SimpleNamespace(objects={"block": ["b0", "b2"]}, init=[])
    return SimpleNamespace(world=_World(), run=SimpleNamespace(problem=problem))


def test_a_missing_entity_is_rebound_to_a_spare_of_its_type():
    (proposal,) = rebind_proposals(_failure(FailureKind.UNKNOWN_ENTITY, 0), _context())
    assert proposal.action == "rebind" and proposal.changes["symbols"] == {"b2": "spare_b2"}


def test_a_motion_failure_of_a_step_that_does_not_use_the_missing_entity_is_not_answered_by_rebinding_it():
    collided = _failure(FailureKind.COLLISION, 0)  # place(b0, ...) collided; b2 is used only by step 1
    assert rebind_proposals(collided, _context(), failed_step_only=True) == []
    assert rebind_proposals(collided, _context())  # without the restriction: any step still to run counts
    at_b2 = _failure(FailureKind.REACHABILITY, 1)
    (proposal,) = rebind_proposals(at_b2, _context(), failed_step_only=True)
    assert proposal.changes["symbols"] == {"b2": "spare_b2"}
