"""The fake world: symbolic state from the problem, multi-tick skills, scripted faults."""

from __future__ import annotations

import pytest

from bt_meta.bt.failures import FailureKind
from bt_meta.errors import BtMetaError
from bt_meta.htn import load_task_text
from bt_meta.world.base import Skill, World
from bt_meta.world.fake import FakeWorld, Fault, FaultSpecError

TASKS = """
domain:
  name: cups
  predicates:
    on: [cup, place]
    free: [place]
  primitives:
    move:
      parameters: [?c, ?to]
      precondition: on(?c, ?from) and free(?to)
      add: [on(?c, ?to), free(?from)]
      delete: [on(?c, ?from), free(?to)]
problems:
  one:
    init: [on(c1, shelf), free(table)]
    tasks: []
"""


@pytest.fixture
def world_of():
    task_file = load_task_text(TASKS, "<cups>")

    def make(**options):
        return FakeWorld(task_file.domain, task_file.problem("one"), **options)

    return make


def _run(skill, limit=20):
    statuses = []
    for _ in range(limit):
        statuses.append(skill.tick())
        if statuses[-1] != "RUNNING":
            return statuses
    raise AssertionError("skill never finished")


def test_protocols_and_initial_state(world_of):
    world = world_of()
    assert isinstance(world, World)
    assert ("on", "c1", "shelf") in world.symbolic_state()
    assert world.observe()["symbolic_state"] is world.symbolic_state()
    assert isinstance(world.skill("move"), Skill)


def test_skill_takes_its_ticks_and_applies_effects_bound_by_the_precondition(world_of):
    world = world_of(ticks_per_skill={"move": 3})
    skill = world.skill("move")
    skill.start(("c1", "table"))
    assert _run(skill) == ["RUNNING", "RUNNING", "SUCCESS"]
    state = world.symbolic_state()
    assert ("on", "c1", "table") in state and ("free", "shelf") in state and ("on", "c1", "shelf") not in state
    assert skill.record() == {"action": "move", "args": ["c1", "table"], "ticks": 3, "outcome": "SUCCESS",
                              "fault": None}
    assert world.total_ticks == 3


def test_skill_whose_precondition_fails_in_the_true_state(world_of):
    world = world_of()
    skill = world.skill("move")
    skill.start(("c1", "shelf"))  # shelf is not free
    assert _run(skill) == ["FAILURE"]
    assert skill.failure.kind == "precondition" and "does not hold in the true state" in skill.failure.message


def test_faults_fail_silent_partial_and_raise(world_of):
    world = world_of(faults=[Fault("move", "fail", kind="collision", occurrence=1),
                             Fault("move", "partial", occurrence=2, drop=[("free", "shelf")]),
                             Fault("move", "silent", args=("c1", "shelf"), occurrence=1),
                             "move#4=raise"])
    first = world.skill("move")
    first.start(("c1", "table"))
    assert _run(first) == ["FAILURE"] and first.failure.kind == "collision"
    assert ("on", "c1", "shelf") in world.symbolic_state()  # a failed skill changes nothing
    second = world.skill("move")
    second.start(("c1", "table"))
    assert _run(second) == ["SUCCESS"]
    assert ("on", "c1", "table") in world.symbolic_state() and ("free", "shelf") not in world.symbolic_state()
    world.apply_symbolic(add=[("free", "shelf")], delete=[])
    third = world.skill("move")
    third.start(("c1", "shelf"))
    assert _run(third) == ["SUCCESS"] and third.record()["fault"] == "silent"
    assert ("on", "c1", "table") in world.symbolic_state()  # nothing happened
    fourth = world.skill("move")
    fourth.start(("c1", "shelf"))
    with pytest.raises(RuntimeError, match="scripted fault"):
        fourth.tick()


@pytest.mark.parametrize(("text", "expected"), [
    ("place=silent", Fault("place", "silent")),
    ("place(b0, 2, 1)#2=fail:reachability", Fault("place", "fail", FailureKind.REACHABILITY, ("b0", "2", "1"), 2)),
    ("pick()=raise", Fault("pick", "raise", args=())),
])
def test_fault_specs_parse(text, expected):
    assert Fault.parse(text) == expected


@pytest.mark.parametrize(("text", "message"), [
    ("place", "expected ACTION"),
    ("place=explode", "unknown fault mode 'explode'"),
    ("place=fail:tired", "unknown failure kind 'tired'"),
])
def test_bad_fault_specs_are_clear_input_errors(text, message):
    with pytest.raises(FaultSpecError, match=message):
        Fault.parse(text)


def test_unknown_skill_and_wrong_arity(world_of):
    world = world_of()
    with pytest.raises(BtMetaError, match="no skill 'fly'; known primitives: move"):
        world.skill("fly")
    with pytest.raises(BtMetaError, match="takes 2 arguments, got 1"):
        world.skill("move").start(("c1",))
