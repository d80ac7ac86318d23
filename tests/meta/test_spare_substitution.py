"""Substitution of missing entities by spares on the table, on small hand-built letter scenes (fake world).

The world reports the blocks it shows (``observe()["objects"]`` with shape and colour) and refuses to place a
block it does not show (``unknown_entity``, as the simulator's place skill does). The plan is the problem's.
"""

from __future__ import annotations

from typing import Any

import bt_meta_plugins.object_substitution as substitution
import pytest

from bt_meta.errors import ConfigError
from bt_meta.htn import load_task_file, load_task_text
from bt_meta.memory import EpisodicMemory
from bt_meta.meta import Limits, MetaExecutor
from bt_meta.resources import trees_dir
from bt_meta.world.base import FAILURE, SkillFailure
from bt_meta.world.fake import FakeWorld

from .conftest import make_host
from .test_object_substitution import A_STEPS, H_STEPS, letter_trace

NOMINAL_A = {**{f"b{i}": ("1x1", "blue") for i in range(5)}, "b5": ("1x2", "blue")}


class SceneWorld(FakeWorld):
    """A fake world showing ``objects`` (name -> (shape, colour)); placing one it does not show fails, and placing
    one of ``far`` fails as the simulator's place skill does for a block out of reach (``reachability`` in the
    approach, the block named ``out_of_reach``)."""

    def __init__(self, domain: Any, problem: Any, objects: dict[str, tuple[str, str]], far: Any = (),
                 **kwargs: Any) -> None:
        super().__init__(domain, problem, **kwargs)
        self.objects = dict(objects)
        self.far = set(far)

    def observe(self) -> dict[str, Any]:
        return {"symbolic_state": self.symbolic_state(),
                "objects": {n: {"name": n, "shape": s, "colour": c} for n, (s, c) in self.objects.items()}}

    def skill(self, action: str) -> Any:
        return AbsentBlock(self, super().skill(action)) if action == "place" else super().skill(action)


class AbsentBlock:
    """``place`` of a block the world does not show fails as ``unknown_entity``; any other runs the fake skill."""

    def __init__(self, world: SceneWorld, skill: Any) -> None:
        self.world = world
        self.skill = skill
        self.failure: SkillFailure | None = None
        self.absent = False

    def start(self, args: Any, ctx: Any = None) -> None:
        self.absent = str(args[0]) not in self.world.objects or str(args[0]) in self.world.far
        if str(args[0]) in self.world.far:
            self.failure = SkillFailure("reachability", f"move_to above {args[0]}: no IK solution",
                                        {"failed_phase": "approach", "out_of_reach": str(args[0])})
        elif self.absent:
            self.failure = SkillFailure("unknown_entity", f"place: there is no block {args[0]!r} in the world",
                                        {"object": str(args[0]), "present": sorted(self.world.objects)})
        else:
            self.skill.start(args, ctx)

    def tick(self) -> str:
        if self.absent:
            return FAILURE
        status = self.skill.tick()
        self.failure = self.skill.failure
        return status

    def __getattr__(self, name: str) -> Any:
        return getattr(self.skill, name)


@pytest.fixture(scope="module")
def letters():
    return load_task_file(trees_dir() / "letters.yaml")


def host(memory: Any = None, **settings: Any) -> Any:
    plugin = substitution.ObjectSubstitution(memory=memory, **settings)
    return make_host(("object_substitution", plugin))


def _run(task_file: Any, problem: Any, objects: dict[str, tuple[str, str]], memory: Any = None,
         faults: tuple[str, ...] = (), far: Any = (), **settings: Any) -> Any:
    world = SceneWorld(task_file.domain, problem, objects, far=far, faults=list(faults))
    report = MetaExecutor(task_file.domain, problem, world, host(memory, **settings),
                          limits=Limits(max_attempts=3)).run()
    return report, world


@pytest.mark.parametrize("missing", ["b2", "b4"])  # a leg block and the apex
def test_a_missing_block_is_replaced_by_a_spare_of_the_kind_its_method_needs(letters, missing):
    objects = {n: v for n, v in NOMINAL_A.items() if n != missing}
    objects.update({"s_red": ("1x1", "red"), "s_blue": ("1x1", "blue"), "s_big": ("1x2", "blue")})
    report, _ = _run(letters, letters.problem("A"), objects)
    assert report.ok, report.stop_reason
    assert [a.proposal["action"] for a in report.attempts] == ["substitute"]
    assert report.attempts[0].proposal["changes"]["mapping"] == {missing: "s_blue"}  # blue 1x1: the method says so
    placed = [e["args"][0] for e in report.executed if e["status"] == "SUCCESS"]
    assert "s_blue" in placed and missing not in placed and len(placed) == 6


def test_colour_does_not_count_where_the_method_does_not_name_one():
    task = load_task_text(COLOURLESS, "<colourless>")
    problem = task.problem("two")
    report, _ = _run(task, problem, {"b0": ("1x1", "blue"), "s_red": ("1x1", "red")})
    assert report.ok, report.stop_reason
    assert report.attempts[0].proposal["changes"]["mapping"] == {"b1": "s_red"}


def test_no_spare_fits_no_substitution(letters):
    """With ``colours="require"`` the methods' blue is a condition: a red 1x1 is no spare for a blue leg block."""
    objects = {n: v for n, v in NOMINAL_A.items() if n != "b2"}
    objects.update({"s_red": ("1x1", "red"), "s_big": ("1x2", "blue")})
    report, _ = _run(letters, letters.problem("A"), objects, colours="require")
    assert not report.ok
    assert all(a.proposal["action"] != "substitute" for a in report.attempts)
    assert report.reported[0]["kind"] == "unknown_entity"


def test_a_spare_of_another_colour_stands_in_only_when_none_has_the_methods_colour(letters):
    """The default (``colours="prefer"``): the methods' blue is a first choice. With only a red 1x1 on the table
    it stands in, scored below a spare of the named colour and saying so; a blue 1x1 beside it is taken instead."""
    objects = {n: v for n, v in NOMINAL_A.items() if n != "b2"}
    objects.update({"s_red": ("1x1", "red"), "s_big": ("1x2", "blue")})
    report, _ = _run(letters, letters.problem("A"), objects)
    assert report.ok, report.stop_reason
    proposal = report.attempts[0].proposal
    assert proposal["changes"]["mapping"] == {"b2": "s_red"}
    assert proposal["evidence"]["other_colour"] == ["b2"] and "colour" in proposal["description"]
    assert proposal["score"] < 0.85
    objects["s_blue"] = ("1x1", "blue")
    report, _ = _run(letters, letters.problem("A"), objects)
    assert report.ok and report.attempts[0].proposal["changes"]["mapping"] == {"b2": "s_blue"}
    assert report.attempts[0].proposal["evidence"]["other_colour"] == []


def test_substitution_colours_setting_is_checked():
    with pytest.raises(ConfigError, match="colours must be one of prefer, require"):
        substitution.ObjectSubstitution(colours="any")


def test_a_block_out_of_reach_is_replaced_by_a_spare(letters):
    """b2 cannot be reached where it lies (the place skill's approach has no IK solution and names it
    ``out_of_reach``): a ``reachability`` failure, which no other motion mends; a spare stands in for it."""
    objects = {**NOMINAL_A, "s_blue": ("1x1", "blue")}
    report, _ = _run(letters, letters.problem("A"), objects, far={"b2"})
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("reachability", "substitute")]
    assert report.attempts[0].proposal["changes"]["mapping"] == {"b2": "s_blue"}
    placed = [e["args"][0] for e in report.executed if e["status"] == "SUCCESS"]
    assert "s_blue" in placed and "b2" not in placed


def test_a_stand_in_found_out_of_reach_in_turn_is_replaced_and_never_taken_again(letters):
    """b2 and the first spare by name (a_far) are both out of reach: the run remembers both (every failure of the
    run that named an object ``out_of_reach``) and the next spare stands in; without one the run stops with the
    limit, not a loop."""
    objects = {**NOMINAL_A, "a_far": ("1x1", "blue"), "z_blue": ("1x1", "blue")}
    report, _ = _run(letters, letters.problem("A"), objects, far={"b2", "a_far"})
    assert report.ok, report.stop_reason
    assert [a.proposal["changes"]["mapping"] for a in report.attempts] == [{"b2": "a_far"}, {"a_far": "z_blue"}]
    placed = [e["args"][0] for e in report.executed if e["status"] == "SUCCESS"]
    assert "z_blue" in placed and not {"b2", "a_far"} & set(placed)
    del objects["z_blue"]
    report, _ = _run(letters, letters.problem("A"), objects, far={"b2", "a_far"})
    assert not report.ok
    assert report.reported[-1]["kind"] == "reachability"
    assert [a.proposal["changes"]["mapping"] for a in report.attempts] == [{"b2": "a_far"}]


COLOURLESS = """
domain:
  name: colourless
  types: [block]
  predicates:
    shape: [block, object]
    colour: [block, object]
    available: [block]
    at: [block, object]
  primitives:
    place:
      parameters: [?b - block, ?x]
      precondition: available(?b)
      add: [at(?b, ?x)]
      delete: [available(?b)]
  tasks:
    row: []
    cell: [?x]
  methods:
    - name: row_two
      task: row()
      subtasks: [cell(0), cell(1)]
    - name: any_1x1
      task: cell(?x)
      precondition: available(?b) and shape(?b, 1x1)
      subtasks: [place(?b, ?x)]
problems:
  two:
    objects: {block: [b0, b1]}
    init: [available(b0), shape(b0, 1x1), colour(b0, blue), available(b1), shape(b1, 1x1), colour(b1, blue)]
    tasks: [row()]
    goal: [at(b0, 0), at(b1, 1)]
"""


@pytest.fixture(scope="module")
def letters_memory(letters, tmp_path_factory):
    path = tmp_path_factory.mktemp("spares") / "memory.sqlite"
    with EpisodicMemory.open(path) as memory:
        memory.write(letter_trace(letters, "A", A_STEPS, 1000.0))
        memory.write(letter_trace(letters, "H", H_STEPS, 2000.0))
    memory = EpisodicMemory.open(path, readonly=True)
    yield memory
    memory.close()


def test_one_1x2_stands_in_for_two_1x1_after_its_placement_collides(letters, letters_memory):
    """H's bar was demonstrated with two 1x1 blocks; the scene has one blue 1x2 (b6) and no b7. Placing the 1x2
    where a 1x1 goes collides; substitution splices A's bar (one 1x2 at 1.5) for H's two placements."""
    objects = {f"b{i}": ("1x1", "blue") for i in range(6)}
    objects["b6"] = ("1x2", "blue")
    report, _ = _run(letters, letters.problem("H"), objects, letters_memory, faults=("place(b6, 1, 1)=fail:collision",))
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("collision", "splice")]
    assert report.attempts[0].proposal["changes"]["actions"] == [["place", "b6", "1.5", "1"]]
    assert report.plan[-1] == ["place", "b6", "1.5", "1"] and all("b7" not in step for step in report.plan)


def test_a_stand_in_the_plan_already_placed_is_not_taken_again(letters, letters_memory):
    """Two blocks missing, one spare: the spare stands in for the first; the second cannot be drawn (the letter is
    one block short), and neither the spares nor the memory's matches may take the placed spare from its cell."""
    objects = {n: v for n, v in NOMINAL_A.items() if n not in ("b1", "b4")}
    objects["s_blue"] = ("1x1", "blue")
    report, _ = _run(letters, letters.problem("A"), objects, letters_memory)
    assert not report.ok, "one spare cannot stand in for two blocks"
    bound = [v for a in report.attempts for v in (a.proposal.get("changes", {}).get("mapping") or {}).values()]
    bound += [x for a in report.attempts for call in a.proposal.get("changes", {}).get("actions") or [] for x in call]
    assert bound.count("s_blue") == 1, report.attempts
    placed = [e["args"][0] for e in report.executed if e["status"] == "SUCCESS" and e["action"] == "place"]
    assert placed.count("s_blue") == 1


def test_a_spare_that_leaves_another_missing_block_without_one_ranks_below_a_tiling_of_the_rest(letters):
    """b1 and b3 missing (legs' tops), one spare 1x1, and the apex block b4 a 1x2 (letters_A 0098's inventory). The
    spare alone mends b1's step and leaves b3 without a stand-in, with nothing left to tile the rest; the tiling of
    the cells still to fill (two 1x2 across the legs' tops and the bar, the spare at the apex) finishes A."""
    objects = {n: v for n, v in NOMINAL_A.items() if n not in ("b1", "b3")}
    objects.update({"b4": ("1x2", "blue"), "s_blue": ("1x1", "blue")})
    report, _ = _run(letters, letters.problem("A"), objects)
    assert report.ok, report.stop_reason
    assert [a.proposal["action"] for a in report.attempts] == ["splice"]
    placed = [e["args"] for e in report.executed if e["status"] == "SUCCESS" and e["action"] == "place"]
    assert {tuple(a[1:]) for a in placed if a[0] in ("b4", "b5")} == {("0.5", "1"), ("2.5", "1")}
    assert ["s_blue", "1.5", "2"] in placed
