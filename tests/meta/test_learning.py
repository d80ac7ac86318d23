"""Learning converges (fake world): a refinement that fails on replay is demoted and the run falls back to the
hand-written method (no learned repair turns a success into a failure); equivalent refinements are kept once; a
refinement records the robot that learned it and another robot does not replay it; a v3 memory file migrates to
v4 with its refinements intact."""

from __future__ import annotations

import json
import sqlite3
from typing import Any

from bt_meta.bt.failures import RepairProposal
from bt_meta.htn import load_task_file
from bt_meta.htn.state import atom_text
from bt_meta.memory import EpisodicMemory
from bt_meta.memory.schema import SCHEMA_VERSION
from bt_meta.meta import MetaExecutor, RefinementStore
from bt_meta.meta.refinements import Refinement
from bt_meta.plugins import hookimpl
from bt_meta.resources import trees_dir
from bt_meta.world.fake import Fault

from .conftest import VARIANT_POSE, PosedWorld, make_host
from .test_refinements import GraspFromTheOtherSide


class Robot(PosedWorld):
    """The posed stand-in world on a named robot; ``fits`` overrides which grasp pose joins the parts."""

    def __init__(self, *args: Any, robot: str = "arm_a", fits: str | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.robot_name = robot
        if fits is not None:
            self.fitting = fits


def _run(attach: Any, store: Any, **world: Any) -> tuple[Any, Robot]:
    problem = attach.problem("attach")
    made = Robot(attach.domain, problem, VARIANT_POSE, **world)
    host = make_host(("backtrack_stand_in", GraspFromTheOtherSide()))
    return MetaExecutor(attach.domain, problem, made, host, refinements=store, variant="upside down").run(), made


def test_a_refinement_that_fails_on_replay_is_demoted_and_the_run_falls_back(attach, tmp_path):
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        learned, _ = _run(attach, store)
        method = learned.refinement_saved["method"]
        assert learned.ok and learned.refinement_saved["robot"] == "arm_a"
        assert learned.refinement_saved["refines"] == [["MoveTo", "g_nominal"], ["Grasp", "active"],
                                                       ["Attach", "active", "reference"]]

        # the same start, but now the hand-written grasp is the one that fits: the learned plan fails on replay
        replay, world = _run(attach, store, fits="g_nominal")
        assert replay.ok, replay.stop_reason
        assert replay.refinements_used == [method] and replay.refinements_demoted == [method]
        assert replay.attempts == []  # the fallback is the hand-written method, not a repair
        assert replay.fallback["refinements"] == [method] and replay.fallback["to"].startswith(
            "the hand-written methods planned from where the world is now")
        assert [(s.record()["action"], s.record()["args"]) for s in world.executed][-3:] == [
            ("MoveTo", ["g_nominal"]), ("Grasp", ["active"]), ("Attach", ["active", "reference"])]
        (stored,) = store.list()
        assert (stored.status, stored.failures, stored.replays) == ("demoted", 1, 0)
        assert stored.status_reason.startswith("its replay failed: [unexpected_configuration]")

        # demoted: the next run plans the hand-written method first and needs nothing
        after, _ = _run(attach, store, fits="g_nominal")
        assert after.ok and after.refinements_used == [] and after.attempts == [] and after.fallback is None
        assert {"method": method, "reason": f"demoted: {stored.status_reason}"} in after.refinements_skipped

        # learned again from the hand-written plan where it fits again: the same refinement, kept once, active
        again, _ = _run(attach, store)
        assert again.ok and again.refinement_saved["method"] == method
        assert "kept_once" in again.refinement_saved
        (stored,) = store.list()
        assert stored.status == "active"


def test_a_replay_that_succeeds_is_counted(attach, tmp_path):
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        _run(attach, store)
        for _ in range(2):
            replay, _ = _run(attach, store)
            assert replay.ok and replay.attempts == [] and replay.refinements_used
        (stored,) = store.list()
        assert (stored.status, stored.replays, stored.failures) == ("active", 2, 0)


def test_equivalent_refinements_are_stored_once(attach, tmp_path):
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        first, _ = _run(attach, store)
        # nudged within the tolerance, learned again (without planning with the first): the same refinement
        store.note_replay(first.refinement_saved["method"], succeeded=False, reason="set aside for the test")
        problem = attach.problem("attach")
        nudged = [VARIANT_POSE[0] + 0.004, *VARIANT_POSE[1:5], VARIANT_POSE[5] + 0.02]
        world = Robot(attach.domain, problem, nudged)
        host = make_host(("backtrack_stand_in", GraspFromTheOtherSide()))
        second = MetaExecutor(attach.domain, problem, world, host, refinements=store).run()
        assert second.ok and second.refinement_saved["method"] == first.refinement_saved["method"]
        assert len(store.list()) == 1
        # farther than the tolerance: another refinement
        world = Robot(attach.domain, problem, [VARIANT_POSE[0] + 0.05, *VARIANT_POSE[1:]])
        store.note_replay(first.refinement_saved["method"], succeeded=False, reason="set aside for the test")
        third = MetaExecutor(attach.domain, problem, world, host, refinements=store).run()
        assert third.ok and third.refinement_saved["method"] != first.refinement_saved["method"]
        assert len(store.list()) == 2


def test_another_robot_does_not_replay_a_refinement(attach, tmp_path):
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        learned, _ = _run(attach, store, robot="arm_a")
        other, _ = _run(attach, store, robot="arm_b")
        assert other.ok and other.refinements_used == [] and len(other.attempts) == 1  # repaired on its own
        assert {"method": learned.refinement_saved["method"],
                "reason": "learned by the robot arm_a, not by arm_b: not replayed on another robot"} \
            in other.refinements_skipped
        assert other.refinement_saved["robot"] == "arm_b"
        again, _ = _run(attach, store, robot="arm_a")
        assert again.refinements_used == [learned.refinement_saved["method"]] and again.attempts == []


def test_a_v3_memory_migrates_with_its_refinements(attach, tmp_path):
    path = tmp_path / "old.sqlite"
    with RefinementStore.open(path) as store:
        learned, _ = _run(attach, store)
    method = learned.refinement_saved["method"]
    connection = sqlite3.connect(path)  # back to what a v3 bt-meta wrote: no v4 columns
    columns = ("robot", "refines", "status", "status_reason", "replays", "failures")
    for column in columns:
        connection.execute(f"ALTER TABLE refinements DROP COLUMN {column}")
    connection.execute("PRAGMA user_version = 3")
    connection.commit()
    before = connection.execute("SELECT method, precondition, subtasks, repair FROM refinements").fetchall()
    connection.close()
    with EpisodicMemory.open(path) as memory:
        assert memory.schema_version == SCHEMA_VERSION == 4
    connection = sqlite3.connect(path)
    after = connection.execute("SELECT method, precondition, subtasks, repair FROM refinements").fetchall()
    connection.close()
    assert after == before and json.loads(after[0][2]) == learned.refinement_saved["subtasks"]
    with RefinementStore.open(path) as store:
        (stored,) = store.list()
        assert (stored.method, stored.robot, stored.status, stored.replays) == (method, None, "active", 0)
        replay, _ = _run(attach, store, robot="arm_b")  # unknown robot: replayed as before v4
        assert replay.refinements_used == [method] and replay.attempts == []


class MoveTheBar:
    """A re-tiling stand-in: the bar b5, refused where A's plan puts it, goes down on other cells instead."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        if failure.step is None:
            return None
        return [RepairProposal("splice", 0.9, "the bar elsewhere",
                               changes={"start": failure.step, "end": failure.step + 1,
                                        "actions": [["place", "b5", "0.5", "1"]]})]


def _letters_run(letters: Any, store: Any) -> Any:
    from .test_perceived_refinements import NOMINAL_SCENE, SceneWorld

    problem = letters.problem("A")
    world = SceneWorld(letters.domain, problem, NOMINAL_SCENE)
    world.faults.append(Fault.parse("place(b5, 1.5, 1)=fail:physical"))
    host = make_host(("move_the_bar", MoveTheBar()))
    return MetaExecutor(letters.domain, problem, world, host, refinements=store).run()


def test_a_refinement_that_moves_a_seen_part_is_planned_with_again(tmp_path):
    """The goal fact about a perceived part the repair put elsewhere is restated at save (the run's guard lets it);
    the check before planning applies the same rule, so the refinement saved is also replayed (letters_A 0007,
    0020, 0023 repaired again on every exposure)."""
    letters = load_task_file(trees_dir() / "letters.yaml")
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        learned = _letters_run(letters, store)
        assert learned.ok and len(learned.attempts) == 1, learned.stop_reason
        saved = learned.refinement_saved
        assert ["at", "b5", "0.5", "1"] in saved["goal"] and ["at", "b5", "1.5", "1"] not in saved["goal"]
        assert not saved.get("facts")  # nothing perceived about b5 accounts for the restated fact
        again = _letters_run(letters, store)
        assert again.refinements_skipped == []
        assert again.ok and again.attempts == [] and again.refinements_used == [saved["method"]]


def test_a_stored_goal_that_drops_a_fact_of_a_part_its_plan_does_not_move_is_refused(tmp_path):
    """The bar's goal fact restated although the plan puts the bar where A's plan does: refused before planning."""
    letters = load_task_file(trees_dir() / "letters.yaml")
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        learned = _letters_run(letters, store)
        store.note_replay(learned.refinement_saved["method"], succeeded=False, reason="set aside for the test")
        store.add(Refinement(domain="letters", task="draw_A()", method="refined_bar_unmoved",
                             precondition="true", subtasks=[atom_text(s) for s in learned.initial_plan],
                             goal=[["at", "b5", "0.5", "1"]]))
        again = _letters_run(letters, store)
    reasons = {r["method"]: r["reason"] for r in again.refinements_skipped}
    assert reasons["refined_bar_unmoved"] == "its goal is weaker than the problem's: at(b5, 1.5, 1) dropped"
    assert again.refinements_used == [] and again.ok and len(again.attempts) == 1


def test_a_fallback_that_only_retried_says_so_when_nothing_is_saved(attach, tmp_path):
    """After the fallback, the hand-written plan is retried at a step and reaches the goal: nothing new is kept,
    and the reason says what happened (it read "the repairs did not change the plan" -- they had: the learned
    plan was dropped)."""
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        learned, _ = _run(attach, store)
        method = learned.refinement_saved["method"]
        replay, _ = _run(attach, store, fits="g_nominal", faults=["Grasp#2=fail:physical"])
        assert replay.ok and replay.fallback is not None and replay.attempts, replay.stop_reason
        assert replay.refinement_saved["saved"] is False
        reason = replay.refinement_saved["reason"]
        assert reason.startswith(f"the learned plan ({method}) failed on replay and was demoted"), reason
        assert "hand-written plan" in reason and "did not change the plan" not in reason
