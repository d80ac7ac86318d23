"""Re-tiling a drawing whose remaining cells no tiling covers (``bt_meta_plugins._retiling``): the blocks already
placed are moved. Hand-built letter A scenes in the letters' frame (the tilings' fake world), the shape of the
generated letters_A variants where two blocks became one 1x2 (seed 1: 0015, 0046, 0056)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from bt_meta_plugins._retiling import SCORE, acyclic_order, retiling_proposals
from bt_meta_plugins._tilings import cells_in_the_way, footprint, tiling_proposals

from bt_meta.bt.failures import Failure, FailureKind, RepairProposal
from bt_meta.htn import load_task_file
from bt_meta.meta import MetaExecutor
from bt_meta.plugins import hookimpl
from bt_meta.resources import trees_dir
from bt_meta.world.fake import FakeWorld

from .conftest import make_host
from .test_object_substitution import A_STEPS
from .test_tilings import A_CELLS, LetterTable


@pytest.fixture(scope="module")
def letters():
    return load_task_file(trees_dir() / "letters.yaml")


def _scene(table: LetterTable, b2_at: tuple[float, float] | None) -> None:
    """b0 and b1 drawn as the first leg; b2 a 1x2 (put down at ``b2_at`` by the failed step, else on the table);
    b3 gone; b4 and the bar b5 on the table."""
    table.objects["b0"] = table.at("1x1", 0, 0)
    table.objects["b1"] = table.at("1x1", 0, 1)
    table.objects["b2"] = table.at("1x2", *b2_at) if b2_at else table.at("1x2", 8, 6)
    table.objects["b4"] = table.at("1x1", 9, 6)
    table.objects["b5"] = table.at("1x2", 8, 8)


def _failure_at_b2(done: int = 2) -> Failure:
    plan = [{"step": i, "action": "place", "args": [b, x, y], "done": i < done}
            for i, (b, x, y, *_) in enumerate(A_STEPS)]
    return Failure(kind=FailureKind.UNKNOWN_ENTITY, message="b2 is a 1x2", step=done, action="place",
                   args=tuple(plan[done]["args"]), evidence={"plan": plan})


def _context(letters, table: LetterTable, start: dict | None = None):
    run = SimpleNamespace(problem=letters.problem("A"), domain=letters.domain, start_objects=start or {})
    return SimpleNamespace(world=table, run=run)


def _shape(table: LetterTable, block: str) -> str:
    return table.objects[block]["shape"]


def test_a_leg_top_moves_when_the_cells_left_cannot_be_tiled(letters):
    """b2, planned for the foot (3, 0), is a 1x2 and lies there; b3 is gone. The cells left -- (3, 0), (3, 1), the
    bar and the apex -- want three 1x1 where one (b4) is left: no tiling of them. With the drawn b1 moved, two 1x2
    lie across the leg tops and the bar cells and every block goes down on free cells."""
    table = LetterTable({})
    _scene(table, b2_at=(3, 0))
    start = dict(table.objects)
    start.update(b0=table.at("1x1", 7, 0), b1=table.at("1x1", 7, 2), b2=table.at("1x2", 8, 6))
    failure = _failure_at_b2()
    vector = SimpleNamespace(to_dict=lambda: {}, unusable=())
    context = _context(letters, table, start)
    assert tiling_proposals(vector, failure, context) == []
    (proposal,) = retiling_proposals(vector, failure, context)
    assert isinstance(proposal, RepairProposal) and proposal.action == "splice" and proposal.score == SCORE
    assert (proposal.changes["start"], proposal.changes["end"]) == (2, 6)
    actions = proposal.changes["actions"]
    assert {a[1] for a in actions} == {"b1", "b2", "b4", "b5"}  # b0 stays on its foot
    assert proposal.evidence["moved"] == ["b1"] and proposal.evidence["kept"] == ["b0"]
    # every cell of the letter covered once, b0 where it was
    drawn = [c for _, b, x, y in actions for c in footprint(_shape(table, b), float(x), float(y))]
    assert sorted([*drawn, (0.0, 0.0)]) == sorted(A_CELLS)
    # in the order given, no block goes down on a cell another block still lies on
    lying = {n: set(v) for n, v in cells_in_the_way(table, "letter", table.objects, A_CELLS).items()}
    for _, block, x, y in actions:
        cells = set(footprint(_shape(table, block), float(x), float(y)))
        assert not any(cells & own for other, own in lying.items() if other != block), (block, lying)
        lying[block] = cells
    # b1's placement is undone when the proposal is applied, not before
    assert proposal.changes["facts"] == {"add": [["available", "b1"]], "delete": [["at", "b1", "0", "1"]]}
    # the refinement replays the new tiling from the start: each block once, no detour
    replay = proposal.evidence["replay_plan"]
    assert sorted(step[1] for step in replay) == ["b0", "b1", "b2", "b4", "b5"]
    assert sorted(c for _, b, x, y in replay for c in footprint(_shape(table, b), float(x), float(y))) \
        == sorted(A_CELLS)


def test_no_retiling_when_the_cells_left_have_a_tiling_or_too_few_blocks_are_left(letters):
    table = LetterTable({})
    _scene(table, b2_at=None)
    table.objects["b3"] = table.at("1x1", 9, 8)  # b3 is back: the cells left tile without moving anything drawn
    table.objects["b2"] = table.at("1x1", 8, 6)
    vector = SimpleNamespace(to_dict=lambda: {}, unusable=())
    assert retiling_proposals(vector, _failure_at_b2(), _context(letters, table)) == []
    table = LetterTable({})
    _scene(table, b2_at=None)
    del table.objects["b4"]  # 6 cells' worth of blocks for A's 7 cells
    assert retiling_proposals(vector, _failure_at_b2(), _context(letters, table)) == []
    # nothing drawn yet: a tiling of the remaining cells is all there is
    table = LetterTable({})
    _scene(table, b2_at=None)
    assert retiling_proposals(vector, _failure_at_b2(done=0), _context(letters, table)) == []


def test_an_order_that_needs_a_cycle_is_refused():
    tile_a = ("1x1", (3.0, 0.0), [(3.0, 0.0)])
    tile_b = ("1x2", (0.5, 1.0), [(0.0, 1.0), (1.0, 1.0)])
    lying = {"b1": {(0.0, 1.0)}, "b2": {(3.0, 0.0)}}  # each lies where the other goes
    step_of = {(3.0, 0.0): 2, (0.0, 1.0): 1, (1.0, 1.0): 4}
    assert acyclic_order({"b1": tile_a, "b2": tile_b}, lying, step_of) is None
    assert acyclic_order({"b1": tile_a, "b2": ("1x2", (2.5, 1.0), [(2.0, 1.0), (3.0, 1.0)])}, lying,
                         {**step_of, (2.0, 1.0): 4, (3.0, 1.0): 3}) == ["b2", "b1"]


class _ProposeWithFacts:
    """Answers the first failure with a proposal that cannot be applied and one that can, each with facts."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure, context):
        return [RepairProposal("splice", 0.95, "bad", changes={"start": 99, "end": 100, "actions": [],
                                                                "facts": {"add": [["on_table", "never"]]}}),
                RepairProposal("retry", 0.9, "retry with a fact", changes={"facts": {
                    "add": [["on_table", "b9"]], "delete": [["on_table", "b2"]]}})]


def test_a_proposal_s_facts_join_the_world_only_when_it_is_applied():
    from bt_meta.htn import load_task_text

    from .conftest import BLOCKS

    blocks = load_task_text(BLOCKS, "<blocks>")
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["put(b0, 0, 0)#1=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(("facts", _ProposeWithFacts()))).run()
    assert report.ok, report.stop_reason
    assert [a.proposal["description"] for a in report.attempts] == ["retry with a fact"]
    state = world.symbolic_state()
    assert ("on_table", "b9") in state and ("on_table", "b2") not in state
    assert ("on_table", "never") not in state


def test_a_drawn_block_no_tile_is_left_for_is_set_aside_first(letters):
    """A drawn but for its apex; b4, the apex, out of reach (found only now), a green 1x2 the only stand-in: the
    letter's one tiling with the 1x2 lays two across the leg tops and the bar cells, so one drawn 1x1 is one too
    many. It is set aside first, off the drawing with a free cell between, and the rest is re-tiled (generated
    letters_A s1 0106). The replay plan draws the new tiling from the start and never moves the block set aside."""
    table = LetterTable({})
    for block, (x, y) in {"b0": (0, 0), "b1": (0, 1), "b2": (3, 0), "b3": (3, 1)}.items():
        table.objects[block] = table.at("1x1", x, y)
    table.objects["b5"] = table.at("1x2", 1.5, 1)
    table.objects["d"] = {**table.at("1x2", 9, 6), "colour": "green"}
    start = {**table.objects, "b0": table.at("1x1", 7, 0), "b1": table.at("1x1", 7, 2),
             "b2": table.at("1x1", 8, 0), "b3": table.at("1x1", 8, 2), "b5": table.at("1x2", 7, 4)}
    plan = [{"step": i, "action": "place", "args": [b, x, y], "done": i < 5}
            for i, (b, x, y, *_) in enumerate(A_STEPS)]
    failure = Failure(kind=FailureKind.REACHABILITY, message="b4 out of reach", step=5, action="place",
                      args=tuple(plan[5]["args"]), evidence={"plan": plan, "out_of_reach": "b4"})
    vector = SimpleNamespace(to_dict=lambda: {}, unusable=("b4",))
    (proposal,) = retiling_proposals(vector, failure, _context(letters, table, start))
    aside = proposal.evidence["set_aside"]
    assert len(aside) == 1 and set(aside) <= {"b1", "b3"}
    block, spot = next(iter(aside.items()))
    actions = proposal.changes["actions"]
    assert actions[0] == ["place", block, *(str(int(v)) if float(v).is_integer() else str(v) for v in spot)]
    assert min(max(abs(spot[0] - cx), abs(spot[1] - cy)) for cx, cy in A_CELLS) >= 2.0  # a free cell between
    drawn = [c for _, b, x, y in actions[1:] for c in footprint(table.objects[b]["shape"], float(x), float(y))]
    kept = [c for b in proposal.evidence["kept"] for c in {"b0": [(0.0, 0.0)], "b2": [(3.0, 0.0)]}.get(b, [])]
    assert sorted(drawn + kept) == sorted(A_CELLS) and "d" in {a[1] for a in actions}
    assert ["at", block, *plan[[p["args"][0] for p in plan].index(block)]["args"][1:]] in \
        proposal.changes["facts"]["delete"]
    replay = proposal.evidence["replay_plan"]
    assert block not in {step[1] for step in replay} and len(replay) == 5


def test_only_a_block_the_plan_names_is_set_aside():
    """Two 1x1 lying on the drawing for one 1x1 tile: one of them goes aside -- never one the task does not name
    (a distractor on a cell is the task's limit, not something a repair moves off the drawing)."""
    from bt_meta_plugins._retiling import _shape_bindings

    covers = [("1x1", (1.5, 2.0), [(1.5, 2.0)])]
    step_of, owner = {(1.5, 2.0): 5}, {(1.5, 2.0): "b4"}
    options = _shape_bindings([0], ["b1", "x"], [], covers, step_of, owner, asidable={"b1", "b3"})
    assert options == [({0: "x"}, ["b1"])]
    assert _shape_bindings([0], ["x", "y"], [], covers, step_of, owner, asidable={"b1"}) == []


class _MalformedFacts:
    """A plugin whose proposal carries facts of the wrong shape (then a good one)."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure, context):
        return [RepairProposal("retry", 0.95, "bad facts", changes={"facts": {"add": "on_table(b9)"}}),
                RepairProposal("retry", 0.9, "good", changes={"attempt": 2})]


def test_a_proposal_with_malformed_facts_is_not_applicable_and_says_why():
    from bt_meta.htn import load_task_text
    from bt_meta.meta.proposals import ProposalError, proposal_facts

    from .conftest import BLOCKS

    assert proposal_facts({"facts": {"add": [["on_table", "b9"]]}}) == ([("on_table", "b9")], [])
    for bad, words in [({"add": "on_table(b9)"}, "must be a list of atoms"), ({"put": []}, "'add' and/or 'delete'"),
                       ({"delete": [[]]}, "an atom is a list"), ([1, 2], "must be a mapping")]:
        with pytest.raises(ProposalError, match=words):
            proposal_facts({"facts": bad})
    blocks = load_task_text(BLOCKS, "<blocks>")
    problem = blocks.problem("two")
    world = FakeWorld(blocks.domain, problem, faults=["put(b0, 0, 0)#1=fail:physical"])
    report = MetaExecutor(blocks.domain, problem, world, make_host(("malformed", _MalformedFacts()))).run()
    assert report.ok and [a.proposal["description"] for a in report.attempts] == ["good"]
    assert ("on_table", "b9") not in world.symbolic_state()
