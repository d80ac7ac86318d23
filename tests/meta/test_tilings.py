"""Shape substitutions from the task's geometry (``bt_meta_plugins._tilings``): the cells the remaining placements
need, covered anew with the blocks on the table. Units on cells and shapes, then A's letter on a small hand-built
scene (fake world) where one 1x2 stands where two 1x1 blocks that are not side by side were planned."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest
from bt_meta_plugins._tilings import (
    cells_in_the_way,
    covers_the_same_cells,
    footprint,
    lands_on_a_block,
    tile,
    tiling_proposals,
)

from bt_meta.bt.failures import Failure, FailureKind, RepairProposal
from bt_meta.htn import load_task_file
from bt_meta.meta import Limits, MetaExecutor
from bt_meta.resources import trees_dir

from .test_object_substitution import A_STEPS
from .test_spare_substitution import NOMINAL_A, SceneWorld, _run, host

A_CELLS = [(0.0, 0.0), (0.0, 1.0), (3.0, 0.0), (3.0, 1.0), (1.0, 1.0), (2.0, 1.0), (1.5, 2.0)]


@pytest.fixture(scope="module")
def letters():
    return load_task_file(trees_dir() / "letters.yaml")


def test_footprints_lay_one_row_blocks_along_x():
    assert footprint("1x2", 1.5, 1) == [(1.0, 1.0), (2.0, 1.0)]
    assert footprint("1x1", 3, 0) == [(3.0, 0.0)]
    assert footprint("1x3", 1, 2) == [(0.0, 2.0), (1.0, 2.0), (2.0, 2.0)]
    assert footprint("2x2", 0, 0) is None and footprint(None, 0, 0) is None


def test_a_letter_is_tiled_with_the_blocks_on_hand_or_not_at_all():
    tiles = tile(A_CELLS, {"1x1": 3, "1x2": 2})
    assert sorted(tiles) == [("1x1", (0.0, 0.0)), ("1x1", (1.5, 2.0)), ("1x1", (3.0, 0.0)),
                             ("1x2", (0.5, 1.0)), ("1x2", (2.5, 1.0))]
    # the demonstrated drawing when the plan's shapes are preferred and on hand
    prefer = {c: "1x1" for c in A_CELLS} | {(1.0, 1.0): "1x2", (2.0, 1.0): "1x2"}
    assert ("1x2", (1.5, 1.0)) in tile(A_CELLS, {"1x1": 5, "1x2": 1}, prefer)
    assert tile(A_CELLS, {"1x1": 2, "1x2": 2}) is None  # 6 cells' worth for 7 cells
    assert tile(A_CELLS, {"1x2": 4}) is None  # the apex and the feet need 1x1 blocks


def test_a_remembered_splice_that_covers_other_cells_is_told_apart():
    plan = [{"step": 0, "action": "place", "args": ["b0", "0", "0"]},
            {"step": 1, "action": "place", "args": ["b1", "0", "1"]}]
    assumed = {"b0": "1x1", "b1": "1x1", "b3": "1x1"}
    elsewhere = RepairProposal("splice", 0.7, changes={"start": 0, "end": 2, "actions": [["place", "b3", "1.5", "1"]]})
    assert covers_the_same_cells(elsewhere, plan, assumed, {"b3": "1x2"}) is False
    same = RepairProposal("splice", 0.7, changes={"start": 0, "end": 2, "actions": [["place", "b3", "0.5", "0"]]})
    assert covers_the_same_cells(same, [{"step": 0, "action": "place", "args": ["b0", "0", "0"]},
                                        {"step": 1, "action": "place", "args": ["b1", "1", "0"]}],
                                 assumed, {"b3": "1x2"}) is True
    moving = RepairProposal("splice", 0.7, changes={"start": 0, "end": 1, "actions": [["pick", "b3"]]})
    assert covers_the_same_cells(moving, plan, assumed, {}) is None  # not placements: the geometry cannot tell


def test_one_1x2_where_two_1x1_that_are_not_side_by_side_were_planned_is_tiled_into_the_letter(letters):
    """b0 (a foot) is gone and b3 (the top of the other leg) is a 1x2: 3 1x1 + 2 1x2 still cover A's 7 cells, the
    two 1x2 laid across the leg tops and the bar cells. No demonstration decomposes A so; the geometry does."""
    objects = {n: v for n, v in NOMINAL_A.items() if n != "b0"}
    objects["b3"] = ("1x2", "blue")
    report, _ = _run(letters, letters.problem("A"), objects)
    assert report.ok, report.stop_reason
    assert [(a.kind, a.proposal["action"]) for a in report.attempts] == [("unknown_entity", "splice")]
    proposal = report.attempts[0].proposal
    assert proposal["evidence"]["matcher"] == "tiling" and proposal["evidence"]["colour_required"] == "blue"
    placed = sorted((a[1], a[2], a[3]) for a in proposal["changes"]["actions"])
    assert placed == [("b1", "0", "0"), ("b2", "3", "0"), ("b3", "2.5", "1"), ("b4", "1.5", "2"),
                      ("b5", "0.5", "1")]
    cells = sorted(c for _, block, x, y in proposal["changes"]["actions"]
                   for c in footprint(objects[block][0], float(x), float(y)))
    assert cells == sorted(A_CELLS)


def _tilings(report):
    return [a for a in report.attempts if (a.proposal.get("evidence") or {}).get("matcher") == "tiling"]


def test_colour_counts_where_the_plan_s_blocks_share_one(letters):
    """Every block of A's plan is blue (its methods ask for blue). With ``colours="require"`` a red 1x2 spare does
    not stand in for the missing b0 and b1, so no tiling; a blue one does."""
    objects = {n: v for n, v in NOMINAL_A.items() if n not in ("b0", "b1")}
    objects["spare"] = ("1x2", "red")
    report, _ = _run(letters, letters.problem("A"), objects, colours="require")
    assert not _tilings(report)
    objects["spare"] = ("1x2", "blue")  # 3 1x1 (b2, b3, b4) and 2 1x2 (b5, spare): A's 7 cells
    report, _ = _run(letters, letters.problem("A"), objects, colours="require")
    tilings = _tilings(report)
    assert report.ok and len(tilings) == 1, report.stop_reason
    assert "spare" in {a[1] for a in tilings[0].proposal["changes"]["actions"]}
    assert tilings[0].proposal["evidence"]["other_colour"] == []


def test_a_tiling_takes_another_colour_only_when_the_methods_colour_cannot_tile(letters):
    """The default (``colours="prefer"``): the red 1x2 tiles A when no blue block can, scored lower and saying
    which block differs; with a blue 1x2 beside it, the blue one is taken."""
    objects = {n: v for n, v in NOMINAL_A.items() if n not in ("b0", "b1")}
    objects["spare"] = ("1x2", "red")
    report, _ = _run(letters, letters.problem("A"), objects)
    tilings = _tilings(report)
    assert report.ok and len(tilings) == 1, report.stop_reason
    proposal = tilings[0].proposal
    assert "spare" in {a[1] for a in proposal["changes"]["actions"]}
    assert proposal["evidence"]["other_colour"] == ["spare"] and "not blue" in proposal["description"]
    objects["another"] = ("1x2", "blue")
    report, _ = _run(letters, letters.problem("A"), objects)
    tilings = _tilings(report)
    assert report.ok and len(tilings) == 1, report.stop_reason
    used = {a[1] for a in tilings[0].proposal["changes"]["actions"]}
    assert "another" in used and "spare" not in used


def test_a_block_out_of_reach_is_left_out_of_the_tiling(letters):
    """b5 (the bar) cannot be reached where it lies and no 1x2 spare is on the table, but two 1x1 are: the
    tiling draws the bar with them and never names b5."""
    objects = {**NOMINAL_A, "s0": ("1x1", "blue"), "s1": ("1x1", "blue")}
    report, _ = _run(letters, letters.problem("A"), objects, far={"b5"})
    assert report.ok, report.stop_reason
    assert [a.kind for a in report.attempts] == ["reachability"]
    placed = [e["args"][0] for e in report.executed if e["status"] == "SUCCESS"]
    assert "b5" not in placed and {"s0", "s1"} <= set(placed)


class _LetterGrounding:
    frames = {"letter": {"anchor": "letter_origin", "unit": 0.061}}
    skills = {"place": {"skill": "place", "frame": "letter"}}


class LetterTable:
    """The world as the tilings read it: blocks with table poses, and the letter frame (origin (0.6, -0.2), turned
    90 degrees on the table, 0.061 m a cell) as :meth:`SimWorld.ground_cell` maps it."""

    grounding = _LetterGrounding()
    ORIGIN, YAW, UNIT = (0.6, -0.2), math.pi / 2, 0.061

    def __init__(self, objects: dict[str, dict]) -> None:
        self.objects = objects

    def ground_cell(self, frame: str, x: str, y: str) -> tuple[float, float, float]:
        u, v = float(x), float(y)
        c, s = math.cos(self.YAW), math.sin(self.YAW)
        return (self.ORIGIN[0] + self.UNIT * (c * u - s * v), self.ORIGIN[1] + self.UNIT * (s * u + c * v), self.YAW)

    def at(self, shape: str, x: float, y: float, along: str = "x", pitch: float = 0.0) -> dict:
        """A blue block of ``shape`` lying centred on letter point (x, y), its long axis along the letter's x or y."""
        tx, ty, yaw = self.ground_cell("letter", str(x), str(y))
        return {"shape": shape, "colour": "blue", "pose": [tx, ty, 0.8, 0.0, pitch, yaw + (math.pi / 2 if along == "y"
                                                                                              else 0.0)]}

    def observe(self) -> dict:
        return {"objects": self.objects}


def test_the_cells_a_block_lies_on_are_read_in_the_letter_s_frame():
    table = LetterTable({})
    objects = {"across": table.at("1x2", 0, 0), "up": table.at("1x2", 3, 0.5, along="y"),
               "away": table.at("1x1", 8, 8), "on_end": table.at("1x2", 1.5, 2, pitch=math.pi / 2),
               "held": {**table.at("1x1", 1, 1), "held_by": "right"}}
    hit = cells_in_the_way(table, "letter", objects, A_CELLS)
    assert hit == {"across": {(0.0, 0.0)}, "up": {(3.0, 0.0), (3.0, 1.0)}, "on_end": {(1.5, 2.0)}}
    assert cells_in_the_way(table, "elsewhere", objects, A_CELLS) == {}  # a frame the world does not ground


def test_a_block_the_failed_placement_left_on_the_letter_is_moved_before_its_cell_is_filled(letters):
    """Two 1x1 of A's first leg replaced by one 1x2 (b0; no b1): placing b0 where a 1x1 goes left it lying across
    cell (0, 0). The tiling lays b0 across a leg top and fills (0, 0) only after b0 has been moved."""
    problem = letters.problem("A")
    table = LetterTable({})
    table.objects["b0"] = table.at("1x2", 0, 0)
    for i, name in enumerate(["b2", "b3", "b4"]):
        table.objects[name] = table.at("1x1", 8 + i, 6)
    table.objects["b5"] = table.at("1x2", 8, 8)
    plan = [{"step": i, "action": "place", "args": [b, x, y], "done": False}
            for i, (b, x, y, *_) in enumerate(A_STEPS)]
    failure = Failure(kind=FailureKind.COLLISION, message="place b0", step=0, action="place",
                      evidence={"plan": plan})
    context = SimpleNamespace(world=table, run=SimpleNamespace(problem=problem))
    vector = SimpleNamespace(to_dict=lambda: {})
    (proposal,) = tiling_proposals(vector, failure, context)
    actions = proposal.changes["actions"]
    order = [a[1] for a in actions]
    cell_of = {a[1]: (float(a[2]), float(a[3])) for a in actions}
    assert proposal.evidence["in_the_way"] == {"b0": [[0.0, 0.0]]}
    assert cell_of["b0"] in {(0.5, 1.0), (2.5, 1.0)}  # the 1x2 goes across a leg top and a bar cell
    filler = next(b for b, c in cell_of.items() if c == (0.0, 0.0))
    assert order.index("b0") < order.index(filler)
    cells = sorted(c for _, b, x, y in actions for c in footprint(table.objects[b]["shape"], float(x), float(y)))
    assert cells == sorted(A_CELLS)


def test_a_stand_in_put_down_where_the_failed_block_still_lies_would_land_on_it():
    table = LetterTable({})
    table.objects.update(b0=table.at("1x2", 0, 0), spare=table.at("1x1", 8, 8), far=table.at("1x1", 3, 0))
    context = SimpleNamespace(world=table)
    failure = Failure(kind=FailureKind.UNKNOWN_ENTITY, message="b0 is a 1x2", step=0, action="place",
                      args=("b0", "0", "0"))
    assert lands_on_a_block(failure, {"b0": "spare"}, context)
    moved = Failure(kind=FailureKind.UNKNOWN_ENTITY, message="b1 missing", step=1, action="place",
                    args=("b1", "0", "1"))
    assert not lands_on_a_block(moved, {"b1": "spare"}, context)  # (0, 1) is free


def test_steps_an_earlier_repair_planned_are_read_with_the_shapes_it_anchored(letters):
    """H's b1 is seen as a 1x2 (b7 gone) and an earlier tiling laid it across (2, 1) and (3, 1) at x = 2.5, the
    belief anchoring its shape; b4 (the foot of the second leg) is then found out of reach. The steps still to run
    need the cells they were planned for -- b1's two, not the half cell 2.5 the problem's 1x1 would read -- and
    the blocks left (four 1x1 and b1) cannot cover those six: no tiling, so no splice that would leave a hole."""
    problem = letters.problem("H")

    class Table(LetterTable):
        def symbolic_state(self):
            return [("shape", "b1", "1x2")]

    table = Table({})
    table.objects["b0"] = table.at("1x1", 0, 0)
    table.objects["b3"] = table.at("1x1", 0, 2)
    for i, name in enumerate(["b2", "b5", "b6"]):
        table.objects[name] = table.at("1x1", 8 + i, 6)
    table.objects["b1"] = table.at("1x2", 8, 8)
    done = [("b0", "0", "0"), ("b3", "0", "2")]
    todo = [("b4", "3", "0"), ("b1", "2.5", "1"), ("b2", "0", "1"), ("b5", "3", "2"), ("b6", "1", "1")]
    plan = [{"step": i, "action": "place", "args": list(a), "done": i < len(done)}
            for i, a in enumerate(done + todo)]
    failure = Failure(kind=FailureKind.REACHABILITY, message="b4 out of reach", step=2, action="place",
                      args=("b4", "3", "0"), evidence={"plan": plan, "out_of_reach": "b4"})
    context = SimpleNamespace(world=table, run=SimpleNamespace(problem=problem))
    vector = SimpleNamespace(to_dict=lambda: {}, unusable=("b4",))
    assert tiling_proposals(vector, failure, context) == []
    table.objects["spare"] = table.at("1x1", 9, 9)  # one more 1x1: the six cells can be covered
    (proposal,) = tiling_proposals(vector, failure, context)
    assert sorted(map(tuple, proposal.evidence["cells"])) == [(0.0, 1.0), (1.0, 1.0), (2.0, 1.0), (3.0, 0.0),
                                                               (3.0, 1.0), (3.0, 2.0)]
    assert "b4" not in {a[1] for a in proposal.changes["actions"]}


class LetterScene(SceneWorld):
    """A :class:`SceneWorld` whose blocks lie at poses in the letters' frame, as the tilings read them
    (:class:`LetterTable`): a block lying on a cell is in the way of the placement that fills it."""

    def __init__(self, domain: Any, problem: Any, objects: dict[str, tuple[str, str]],
                 at: dict[str, tuple[float, float]]) -> None:
        super().__init__(domain, problem, objects)
        self.table = LetterTable({})
        self.grounding = self.table.grounding
        self.poses = {n: self.table.at(objects[n][0], *xy)["pose"] for n, xy in at.items()}

    def ground_cell(self, frame: str, x: str, y: str) -> tuple[float, float, float]:
        return self.table.ground_cell(frame, x, y)

    def observe(self) -> dict[str, Any]:
        seen = super().observe()
        for name, state in seen["objects"].items():
            state["pose"] = self.poses[name]
        return seen


def test_a_spare_lying_on_a_cell_still_to_fill_stands_in_before_one_off_the_drawing(letters):
    """b0 missing, two green 1x1 and no blue one: ``s_a`` off the drawing, ``s_z`` lying on b3's cell (3, 1). The
    spare in the way stands in although its name sorts last: placed at b0's cell, it leaves b3's cell free
    (letters_A s0 0101). Off the drawing both, the name order decides."""
    objects = {n: v for n, v in NOMINAL_A.items() if n != "b0"}
    objects.update({"s_a": ("1x1", "green"), "s_z": ("1x1", "green")})
    away = {n: (8.0 + i, 6.0) for i, n in enumerate(sorted(objects))}
    for s_z_at, expected in (((3.0, 1.0), "s_z"), ((9.0, 8.0), "s_a")):
        world = LetterScene(letters.domain, letters.problem("A"), objects, {**away, "s_z": s_z_at})
        report = MetaExecutor(letters.domain, letters.problem("A"), world, host(),
                              limits=Limits(max_attempts=3)).run()
        assert report.ok, report.stop_reason
        (attempt,) = report.attempts
        assert attempt.proposal["action"] == "substitute"
        assert attempt.proposal["changes"]["mapping"] == {"b0": expected}, attempt.proposal
