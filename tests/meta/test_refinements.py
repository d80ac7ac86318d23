"""Learned refinements: saved after a repaired run, exported as a task file that loads, used first next time."""

from __future__ import annotations

from typing import Any

import pytest
from bt_meta_plugins.refinement_predicates import pose_within

from bt_meta.bt.failures import RepairProposal
from bt_meta.cli import main
from bt_meta.htn import load_task_file, load_task_text, plan
from bt_meta.meta import MetaExecutor, RefinementError, RefinementStore, task_file_yaml
from bt_meta.meta.refinements import Refinement, domain_with_pose_predicate
from bt_meta.plugins import hookimpl
from bt_meta.resources import trees_dir

from .conftest import NOMINAL_POSE, VARIANT_POSE, PosedWorld, make_host


class GraspFromTheOtherSide:
    """A stand-in for pose backtracking: after a misaligned attachment, go back to the MoveTo and use g_alt."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        if failure.action != "Attach" or failure.kind.value != "unexpected_configuration":
            return None
        plan = failure.evidence["plan"]
        move = max(s["step"] for s in plan if s["action"] == "MoveTo" and s["step"] < failure.step)
        return [RepairProposal("backtrack", 0.9, "grasp pose that fits the part's pose",
                               changes={"to_step": move, "args": {str(move): ["g_alt"]}},
                               evidence={"R_p": failure.evidence.get("R_p")})]


def _run(attach, pose, store, **options):
    problem = attach.problem("attach")
    world = PosedWorld(attach.domain, problem, pose)
    host = make_host(("backtrack_stand_in", GraspFromTheOtherSide()))
    return MetaExecutor(attach.domain, problem, world, host, refinements=store, variant="upside down",
                        **options).run(), world


def test_a_repaired_variant_is_saved_and_the_next_run_needs_no_repair(attach, tmp_path):
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        first, _ = _run(attach, VARIANT_POSE, store)
        assert first.ok, first.stop_reason
        assert [(a.kind, a.proposal["action"], a.change) for a in first.attempts] == [
            ("unexpected_configuration", "backtrack", "backtrack to step 0; step 0 now MoveTo(g_alt)")]
        saved = first.refinement_saved
        assert saved is not None and saved["id"] == 1
        assert saved["task"] == "MagneticAttach(active, reference)"
        assert saved["subtasks"] == ["MoveTo(g_alt)", "Grasp(active)", "Attach(active, reference)"]
        assert saved["poses"]["active"] == VARIANT_POSE
        assert saved["precondition"].startswith("pose_within(active, 0.6, -0.2, 0.8, 3.14159, 0, 0, 0.02, 0.1)")
        assert saved["repair"]["kinds"] == ["unexpected_configuration"]

        second, world = _run(attach, VARIANT_POSE, store)
        assert second.ok and second.attempts == [] and second.failures == []
        assert [(s.record()["action"], s.record()["args"]) for s in world.executed] == [
            ("MoveTo", ["g_alt"]), ("Grasp", ["active"]), ("Attach", ["active", "reference"])]
        assert second.refinements_used == [saved["method"]]
        assert second.initial_plan == [["MoveTo", "g_alt"], ["Grasp", "active"], ["Attach", "active", "reference"]]
        assert second.refinement_saved is None
        assert len(store.list()) == 1

        # the nominal pose fails the refinement's pose check: the nominal method is planned, and works
        nominal, _ = _run(attach, NOMINAL_POSE, store)
        assert nominal.ok and nominal.attempts == [] and nominal.refinements_used == []
        assert nominal.initial_plan[0] == ["MoveTo", "g_nominal"]


def test_without_a_store_every_run_repairs_again(attach):
    first, _ = _run(attach, VARIANT_POSE, None)
    second, _ = _run(attach, VARIANT_POSE, None)
    assert len(first.attempts) == len(second.attempts) == 1


def test_retries_alone_are_not_saved(blocks, tmp_path):
    from bt_meta.world.fake import FakeWorld

    problem = blocks.problem("two")
    with RefinementStore.open(tmp_path / "m.sqlite") as store:
        world = FakeWorld(blocks.domain, problem, faults=["pick#1=fail:physical"])
        report = MetaExecutor(blocks.domain, problem, world, make_host(), refinements=store).run()
        assert report.ok and len(report.attempts) == 1
        assert report.refinement_saved == {"saved": False, "reason": "the repairs did not change the plan (retries "
                                                                     "only): nothing new to keep"}
        assert store.list() == []


def test_the_export_is_a_task_file_that_loads_and_plans_with_the_refinement_first(attach, tmp_path):
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        _run(attach, VARIANT_POSE, store)
        text = store.export_yaml(attach.domain, attach.problems.values())
    loaded = load_task_text(text, "<exported>")
    domain = loaded.domain
    assert domain.methods[0].name.startswith("refined_MagneticAttach_")
    assert domain.methods[1].name == "nominal"
    assert "pose_within" in domain.external
    seen: list[tuple[str, tuple[str, ...]]] = []

    def external(name, args, state):
        seen.append((name, args))
        return pose_within(VARIANT_POSE, args) if args[0] == "active" else True

    result = plan(domain, loaded.problem("attach"), external=external)
    assert [(a.name, a.args) for a in result.plan] == [("MoveTo", ("g_alt",)), ("Grasp", ("active",)),
                                                       ("Attach", ("active", "reference"))]
    assert seen and seen[0][0] == "pose_within"
    result = plan(domain, loaded.problem("attach"), external=lambda name, args, state: False)
    assert result.plan[0].args == ("g_nominal",)


@pytest.mark.parametrize("name", ["letters.yaml", "magnetic_attach.yaml", "housing_insertion.yaml"])
def test_the_task_file_writer_round_trips_the_shipped_task_files(name):
    original = load_task_file(trees_dir() / name)
    again = load_task_text(task_file_yaml(original.domain, original.problems.values()), f"<{name}>")
    assert list(again.domain.primitives) == list(original.domain.primitives)
    assert [m.name for m in again.domain.methods] == [m.name for m in original.domain.methods]
    for problem_name, problem in original.problems.items():
        copy = again.problem(problem_name)
        assert (copy.state, copy.tasks, copy.goal) == (problem.state, problem.tasks, problem.goal)
        try:
            expected = plan(original.domain, problem, max_seconds=5)
        except Exception as error:  # external predicates without a plugin: both must fail the same way
            with pytest.raises(type(error)):
                plan(again.domain, copy, max_seconds=5)
            continue
        got = plan(again.domain, copy, max_seconds=5)
        assert [(a.name, a.args) for a in got.plan] == [(a.name, a.args) for a in expected.plan]


def test_a_refinement_that_does_not_fit_its_domain_is_a_clear_error(attach):
    broken = Refinement(domain="attach", task="MagneticAttach(active, reference)", method="refined_x",
                        precondition="true", subtasks=["Fly(active)"])
    with pytest.raises(RefinementError, match=r"refinement refined_x does not fit domain attach: .*Fly"):
        broken.to_method(domain_with_pose_predicate(attach.domain))


def test_a_stored_refinement_that_no_longer_fits_is_skipped_with_a_warning(attach, tmp_path, caplog):
    with RefinementStore.open(tmp_path / "m.sqlite") as store:
        store.add(Refinement(domain="attach", task="MagneticAttach(active, reference)", method="refined_old",
                             precondition="true", subtasks=["Fly(active)"]))
        report, _ = _run(attach, VARIANT_POSE, store)
    assert report.ok and report.refinements_used == [] and len(report.attempts) == 1
    assert "skipping a stored refinement: refinement refined_old does not fit domain attach" in caplog.text


def test_a_method_name_is_stored_once(attach, tmp_path):
    refinement = Refinement(domain="attach", task="MagneticAttach(active, reference)", method="refined_y",
                            precondition="true", subtasks=["MoveTo(g_alt)"])
    with RefinementStore.open(tmp_path / "m.sqlite") as store:
        store.add(refinement)
        with pytest.raises(RefinementError, match="a refinement named refined_y is already stored"):
            store.add(Refinement(**{**refinement.to_dict(), "id": None}))


def test_cli_lists_and_exports_refinements(attach, tmp_path, capsys):
    memory = tmp_path / "memory.sqlite"
    with RefinementStore.open(memory) as store:
        first, _ = _run(attach, VARIANT_POSE, store)
    task_path = tmp_path / "attach.yaml"
    from .conftest import ATTACH

    task_path.write_text(ATTACH, encoding="utf-8")
    assert main(["refinements", "ls", "--memory", str(memory)]) == 0
    out = capsys.readouterr().out
    assert first.refinement_saved["method"] in out and "MagneticAttach(active, reference)" in out
    assert main(["refinements", "ls", "--json", "--memory", str(memory)]) == 0
    import json

    listed = json.loads(capsys.readouterr().out)
    assert listed[0]["subtasks"][0] == "MoveTo(g_alt)"
    out_file = tmp_path / "refined.yaml"
    assert main(["refinements", "export", str(task_path), "--memory", str(memory), "-o", str(out_file)]) == 0
    loaded = load_task_file(out_file)
    assert loaded.domain.methods[0].name == first.refinement_saved["method"]
    assert set(loaded.problems) == {"attach"}


def test_cli_export_finds_the_recorded_task_file(tmp_path, capsys):
    from .conftest import ATTACH

    task_path = tmp_path / "attach.yaml"
    task_path.write_text(ATTACH, encoding="utf-8")
    memory = tmp_path / "memory.sqlite"
    with RefinementStore.open(memory) as store:
        report, _ = _run(load_task_file(task_path), VARIANT_POSE, store)
        assert store.list()[0].domain_path == str(task_path.resolve())
    assert main(["refinements", "export", "--memory", str(memory)]) == 0
    loaded = load_task_text(capsys.readouterr().out, "<stdout>")
    assert loaded.domain.methods[0].name == report.refinement_saved["method"]
    task_path.unlink()
    assert main(["refinements", "export", "--memory", str(memory)]) == 2
    assert "the task file of domain attach is unknown or gone" in capsys.readouterr().err


def test_cli_errors(tmp_path, capsys):
    missing = tmp_path / "none.sqlite"
    assert main(["refinements", "ls", "--memory", str(missing)]) == 2  # like `bt-meta memory ls`
    assert "no episodic memory here" in capsys.readouterr().err
    assert not missing.exists()
    task = tmp_path / "t.yaml"
    task.write_text("domain: [oops", encoding="utf-8")
    with RefinementStore.open(tmp_path / "m.sqlite"):
        pass
    assert main(["refinements", "export", str(task), "--memory", str(tmp_path / "m.sqlite")]) == 2
    assert "t.yaml:1:" in capsys.readouterr().err
    assert main(["refinements", "export", "--memory", str(tmp_path / "m.sqlite")]) == 2
    assert "no refinements to export in" in capsys.readouterr().err


def test_a_replay_plan_is_kept_only_when_no_other_plugin_changed_the_plan_before():
    """A re-orientation's replay plan is planned from the problem's initial state: kept as the refinement's plan
    when it made the run's only repairs; after another plugin's splice (a tiling of a 1x2 where two 1x1 were), it
    knows nothing of that change, and the plan as run is kept."""
    from bt_meta.meta.executor import RunReport
    from bt_meta.meta.kept_plan import replayed as _replayed
    from bt_meta.meta.kept_plan import unkept_attempts as _unkept
    from bt_meta.meta.reasoner import Attempt

    def attempt(number: int, plugin: str, outcome: str, replay: list | None = None, action: str = "splice"
                ) -> Attempt:
        evidence = {"replay_plan": replay} if replay else {}
        return Attempt(number, {}, "reachability", {"plugin": plugin, "action": action, "evidence": evidence}, "", 0,
                       0.0, outcome)

    as_run = [["place", "b1", "0.5", "1"], ["turn_over", "b7"], ["place", "b7", "2", "1"]]
    replay = [["turn_over", "b7"], ["place", "b1", "0", "1"], ["place", "b7", "2", "1"]]
    alone = RunReport("success", "H", attempts=[attempt(1, "reorientation", "repaired", replay)], plan=as_run)
    assert _replayed(alone).plan == replay
    twice = RunReport("success", "H", attempts=[attempt(1, "reorientation", "failed_again", replay),
                                                 attempt(2, "reorientation", "repaired", replay)], plan=as_run)
    assert _replayed(twice).plan == replay
    after = RunReport("success", "H", attempts=[attempt(1, "object_substitution", "failed_again"),
                                                 attempt(2, "reorientation", "repaired", replay)], plan=as_run)
    assert _replayed(after).plan == as_run
    # a rebinding after it changes no step (generated letters_A s1 0052: b0 turned, then the missing b2's spare)
    rebound = RunReport("success", "H", attempts=[attempt(1, "reorientation", "failed_again", replay),
                                                   attempt(2, "object_substitution", "repaired", action="rebind")],
                        plan=as_run)
    assert _replayed(rebound).plan == replay
    # a later splice is made again in the replay plan where the steps it replaced are (letters_A s1 0118)
    later = attempt(2, "object_substitution", "repaired")
    later.proposal["changes"] = {"actions": [["place", "s0", "2", "1"], ["place", "s1", "3", "1"]]}
    later.replaced = [["place", "b7", "2", "1"]]
    spliced = RunReport("success", "H", attempts=[attempt(1, "reorientation", "failed_again", replay), later],
                        plan=as_run)
    assert _replayed(spliced).plan == [*replay[:2], ["place", "s0", "2", "1"], ["place", "s1", "3", "1"]]
    later.replaced = [["place", "b9", "2", "1"]]  # not in the replay plan: the plan as run
    assert _replayed(spliced).plan == as_run
    # a backtrack's new pose goes to the step it rewrote (magnetic s1 0016: turns, then the attach's pose)
    moved = attempt(2, "pose_backtracking", "repaired", action="backtrack")
    moved.proposal["changes"] = {"to_step": 5, "args": {"5": ["held:ref:0:0:0.05:0:0:0"]}}
    moved.replaced = [["place", "b7", "2", "1"]]
    backtracked = RunReport("success", "H", attempts=[attempt(1, "reorientation", "failed_again", replay), moved],
                            plan=as_run)
    assert _replayed(backtracked).plan == [*replay[:2], ["place", "held:ref:0:0:0.05:0:0:0"]]
    # mid-plan, turns put in before the rest of the failed plan after a tiling: the plan as run is the refinement
    midway = attempt(2, "reorientation", "repaired", replay)
    midway.proposal["evidence"]["as_run_replays"] = True
    tiled_then_turned = RunReport("success", "H", attempts=[attempt(1, "object_substitution", "failed_again"),
                                                             midway], plan=as_run)
    assert _replayed(tiled_then_turned).plan == as_run and _unkept(tiled_then_turned.attempts, as_run) == []
    del midway.proposal["evidence"]["as_run_replays"]  # a replay plan that cannot be used, the plan as run no good
    assert _unkept(tiled_then_turned.attempts, as_run) == [2]
    renamed = attempt(2, "object_substitution", "repaired", action="substitute")
    renamed.proposal["changes"] = {"mapping": {"b7": "s0"}}
    renamed.replaced = [["place", "b1", "0", "1"]]
    substituted = RunReport("success", "H", attempts=[attempt(1, "reorientation", "failed_again", replay), renamed],
                            plan=as_run)
    assert _replayed(substituted).plan == [["turn_over", "b7"], ["place", "b1", "0", "1"], ["place", "s0", "2", "1"]]
