"""Pose backtracking end to end in the simulator (paper, section 7): three nominal MagneticAttach demonstrations are
recorded; a variant pose of the active part fails the staging verification; the plugin backtracks to the move that
set the part's pose, samples a known-good attachment pose from the traces, turns it into a gripper pose through the
current grasp, checks IK and collision and repairs the run; the repair is kept as a refinement that the next run of
the variant uses with no repair at all. Variants whose good poses the arm cannot take are reported with their
motion limit and evidence, never looped on."""

from __future__ import annotations

from typing import Any

import pytest
from bt_meta_plugins import classification_rules, pose_backtracking, refinement_predicates, retry_repair

from bt_meta.meta import Limits, MetaExecutor, MetaReasoner, PlanState, RefinementStore
from bt_meta.plugins import create_plugin_host
from bt_meta.resources import trees_dir

pytestmark = pytest.mark.slow

TASK_FILE = trees_dir() / "magnetic_attach.yaml"


def host(plugin: Any) -> Any:
    return create_plugin_host(entry_points=False, plugins=[
        ("classification_rules", classification_rules), ("retry_repair", retry_repair),
        ("refinement_predicates", refinement_predicates), ("pose_backtracking", plugin)])


@pytest.fixture(scope="module")
def demonstrations(tmp_path_factory):
    """A memory file with three nominal demonstrations (seeds 0, 1, 2), recorded by ``bt-meta record``'s code."""
    from bt_meta.commands.record import demonstrate
    from bt_meta.memory import EpisodicMemory

    path = tmp_path_factory.mktemp("pose_backtracking") / "demonstrations.sqlite"
    with EpisodicMemory.open(path) as memory:
        for seed in range(3):
            demonstrate(TASK_FILE, "nominal", memory, seed=seed,
                        plugins=create_plugin_host(entry_points=False, plugins=[]))
    return path


@pytest.fixture
def memory_file(demonstrations, tmp_path):
    """A private copy of the demonstrations (refinements are written into it)."""
    from bt_meta.memory import EpisodicMemory

    copy = tmp_path / "memory.sqlite"
    with EpisodicMemory.open(demonstrations, readonly=True) as source, EpisodicMemory.open(copy) as target:
        for trace in source.traces():
            target.write(trace)
    return copy


def fence_in_the_reference(world: Any, half: float = 0.075, height: float = 0.12) -> None:
    """Four static posts around the reference part: a top-down approach still fits, a hand beside the part does not."""
    from bt_meta.world.simulation.objects import AttachmentFeature, Box, ObjectModel

    x, y = world.sim.object_transform("reference")[:2, 3]
    for k, (dx, dy, sx, sy) in enumerate([(half, 0, 0.02, 0.18), (-half, 0, 0.02, 0.18), (0, half, 0.18, 0.02),
                                          (0, -half, 0.18, 0.02)]):
        model = ObjectModel(type="post", colour="red", parts=(Box((sx, sy, height)),), mass=0.0,
                            features=(AttachmentFeature("top", (0, 0, height / 2), (0, 0, 1)),), primary="top")
        world.sim.spawn(f"post{k}", model, [x + dx, y + dy, 0.0, 0.0, 0.0, 0.0], on_table=True)
    world.sync_collision()


def run_variant(memory_file, variant: str, *, attempts: int = 4, prepare: Any = None, **settings: Any):
    from bt_meta.htn import load_task_file
    from bt_meta.memory import EpisodicMemory
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(TASK_FILE)
    problem = task_file.problem("nominal")
    with quiet_stdout():
        world = SimWorld(task_file.domain, problem, load_grounding(task_file.domain.name, TASK_FILE), variant=variant,
                         seed=0)
    try:
        if prepare is not None:
            prepare(world)
        with EpisodicMemory.open(memory_file, readonly=True) as memory, RefinementStore.open(memory_file) as store:
            plugin = pose_backtracking.PoseBacktracking(memory, n=3, seed=0, **settings)
            report = MetaExecutor(task_file.domain, problem, world, host(plugin), task_file=task_file,
                                  limits=Limits(max_attempts=attempts, max_seconds=60), refinements=store,
                                  variant=variant, memory=memory).run()
        return report, list(world.sim.attachments())
    finally:
        world.close()


@pytest.mark.parametrize("variant", ["active_on_side", "active_on_side_turned"])
def test_part_on_its_side_is_repaired_by_backtracking_and_the_refinement_is_used_next_time(memory_file, variant):
    report, joined = run_variant(memory_file, variant)
    assert report.ok, report.stop_reason
    assert joined == [("active", "reference")]
    assert len(report.attempts) == 1
    attempt = report.attempts[0]
    assert (attempt.kind, attempt.step, attempt.outcome) == ("verification", 12, "repaired")
    proposal = attempt.proposal
    assert proposal["action"] == "backtrack" and proposal["plugin"] == "pose_backtracking"
    # the last move that set the part's pose (MoveTo(joint), step 5) gets a sampled known-good pose
    assert proposal["changes"]["to_step"] == 5 and list(proposal["changes"]["args"]) == ["5"]
    symbol = proposal["changes"]["args"]["5"][0]
    assert symbol.startswith("held:reference_part:")  # the part relative to the reference, not a gripper pose
    evidence = proposal["evidence"]
    assert evidence["first_deviating_step"] == 0 and evidence["pose_steps"] == [3, 4, 5]
    relations = {row["step"]: row for row in evidence["relations"]}
    assert relations[0]["deviates"] and abs(relations[0]["R_n"] - 1.5708) < 0.05  # on a side: 90 degrees
    assert abs(relations[0]["expected_R_n"] - 3.1416) < 0.05  # the demonstrations: normals opposed
    assert len(evidence["traces"]) == 3
    assert report.plan[5] == ["MoveTo", symbol] and report.initial_plan[5] == ["MoveTo", "joint"]
    saved = report.refinement_saved
    assert saved is not None and saved["variant"] == variant
    assert "pose_within(active, " in saved["precondition"]  # the world's names: what pose_within looks up
    assert "pose_within(reference, 0.62" in saved["precondition"]
    assert f"MoveTo({symbol})" in saved["subtasks"]

    again, joined = run_variant(memory_file, variant)
    assert again.ok and again.attempts == [] and joined == [("active", "reference")]
    assert again.refinements_used == [saved["method"]]
    assert again.initial_plan == report.plan

    if variant == "active_on_side":
        nominal, joined = run_variant(memory_file, "nominal")  # the part upright: the refinement's poses do not hold
        assert nominal.ok and nominal.attempts == [] and nominal.refinements_used == []
        assert joined == [("active", "reference")]


def test_each_further_attempt_backtracks_one_pose_further(memory_file):
    """After a backtrack to step 5 that did not help, the next proposal goes back to step 4 and redoes 4 and 5."""
    from bt_meta.htn import load_task_file
    from bt_meta.memory import EpisodicMemory
    from bt_meta.meta import Attempt
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(TASK_FILE)
    problem = task_file.problem("nominal")
    with quiet_stdout():
        world = SimWorld(task_file.domain, problem, load_grounding(task_file.domain.name, TASK_FILE),
                         variant="active_on_side", seed=0)
    try:
        with EpisodicMemory.open(memory_file, readonly=True) as memory:
            plugin = pose_backtracking.PoseBacktracking(memory, n=3, seed=0)
            plugins = host(plugin)
            harness = TreeHarness.from_file(TASK_FILE, "nominal", world=world, plugins=plugins)
            assert harness.tick_until("done", max_ticks=2000).value == "FAILURE"
            failures = harness.run.failures
            assert [f.kind.value for f in failures] == ["verification"]
            reasoner = MetaReasoner(plugins)
            plan_state = PlanState(harness.compiled.plan_result.tree, cursor=12)
            earlier = Attempt(1, {}, "verification", {"action": "backtrack", "changes": {"to_step": 5, "args": {}},
                                                      "evidence": {"strategy": "pose_backtracking"}}, "", 12, 0.0)
            diagnosis = reasoner.diagnose(failures, plan_state, harness.run, [earlier])
            context = reasoner.context_of(diagnosis.failure, harness.run, diagnosis.step, diagnosis.node_id,
                                          plan_state)
            proposals = plugin.bt_meta_propose_repairs(diagnosis.failure, context)
            assert len(proposals) == 1
            assert proposals[0].changes["to_step"] == 4 and sorted(proposals[0].changes["args"]) == ["4", "5"]
            # the sampling is seeded: a plugin with the same seed (and the same current trace) proposes the same poses
            twin = pose_backtracking.PoseBacktracking(memory, n=3, seed=0)
            twin._run, twin._current, twin._q = plugin._run, plugin._current, plugin._q
            assert twin.bt_meta_propose_repairs(diagnosis.failure, context)[0].changes == proposals[0].changes
            assert ("pose", proposals[0].changes["args"]["4"][0]) in world.symbolic_state()  # grounded by the world
            deeper = Attempt(2, {}, "verification", {"action": "backtrack", "changes": {"to_step": 3, "args": {}},
                                                     "evidence": {"strategy": "pose_backtracking"}}, "", 12, 0.0)
            diagnosis = reasoner.diagnose(failures, plan_state, harness.run, [earlier, deeper])
            assert plugin.bt_meta_propose_repairs(diagnosis.failure, context) is None  # the first deviating pose
    finally:
        world.close()


@pytest.mark.parametrize(("variant", "fenced", "kind", "shown"), [
    ("active_upside_down", False, "reachability", "target"),  # the grasp covers the magnet: the hand would be under
    ("active_on_side", True, "collision", "pair"),  # the hand beside the part would go through the posts
])
def test_blocked_good_poses_are_reported_with_their_motion_limit_not_looped_on(memory_file, variant, fenced, kind,
                                                                                shown):
    settings = {"turns": [0.0, 1.5708, 3.1416, -1.5708], "max_candidates": 4} if fenced else {}
    report, joined = run_variant(memory_file, variant, prepare=fence_in_the_reference if fenced else None,
                                 **settings)
    assert report.status == "failed" and joined == []
    assert report.attempts == []  # nothing was executed in vain
    assert f"{kind} blocks the repair of verification at step 12" in report.stop_reason
    assert "not looped on" in report.stop_reason
    limit = next(entry for entry in report.reported if entry["kind"] == kind)
    assert limit["plugin"] == "pose_backtracking" and limit["action"] == "MoveTo"
    assert shown in limit["evidence"]
    if fenced:
        contacts = limit["evidence"]["contacts"]  # every colliding pair met, with how many candidates met it
        assert any(name.startswith("post") for entry in contacts for name in entry["pair"])
    assert limit["blocks_repair_of"] == {"kind": "verification", "step": 12}
    assert report.refinement_saved is None


def test_a_keypoint_mismatch_mid_plan_is_kept_as_a_refinement_that_replays_through_the_run_s_own_moves(memory_file):
    """Monitoring R_p/R_n at the end of each task (section 7.5.3) flags the part on its side after PickPart
    (step 3); the plugin redoes steps 3-5 from where the arm stands. Replayed straight from the start, turning the
    part right above the table would hit it; the refinement therefore replays the run's own lift first (step 3 as
    it ran, the part in hand -- no failed attach, release or re-pick), then the repaired moves. The next run of the
    variant (monitored as the dual configuration monitors, at the staging verification) uses it with zero attempts
    and the parts are joined. (Keypoint monitors at every task end would still flag the part on its side after
    PickPart: they compare with the nominal traces, not with the refinement's run.)"""
    from bt_meta_plugins import ground_truth_perception, keypoint_expectations

    from bt_meta.htn import load_task_file
    from bt_meta.memory import EpisodicMemory
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(TASK_FILE)
    problem = task_file.problem("nominal")

    def run(task_end_monitors: bool = True) -> tuple[Any, list[Any]]:
        with quiet_stdout():
            world = SimWorld(task_file.domain, problem, load_grounding(task_file.domain.name, TASK_FILE),
                             variant="active_on_side", seed=0)
        try:
            with EpisodicMemory.open(memory_file, readonly=True) as memory, \
                    RefinementStore.open(memory_file) as store:
                monitors = [("keypoint_expectations", keypoint_expectations.KeypointExpectations(
                    memory, check="task_end"))] if task_end_monitors else []
                plugins = create_plugin_host(entry_points=False, plugins=[
                    ("classification_rules", classification_rules), ("retry_repair", retry_repair),
                    ("refinement_predicates", refinement_predicates),
                    ("ground_truth_perception", ground_truth_perception), *monitors,
                    ("pose_backtracking", pose_backtracking.PoseBacktracking(memory, n=3, seed=0))])
                report = MetaExecutor(task_file.domain, problem, world, plugins, task_file=task_file,
                                      refinements=store, variant="active_on_side", memory=memory).run()
            return report, list(world.sim.attachments())
        finally:
            world.close()

    report, joined = run()
    assert report.ok, report.stop_reason
    assert joined == [("active", "reference")]
    assert [(a.kind, a.step, a.proposal["changes"]["to_step"]) for a in report.attempts] == [
        ("unexpected_configuration", 3, 3)]
    evidence = report.attempts[0].proposal["evidence"]
    assert evidence["replayable"] is False and "keep" not in evidence
    replay = evidence["replay_plan"]
    # the prefix, step 3 as it ran (the lift with the part in hand), then the repaired steps 3.. with new poses
    assert replay[:4] == [["MoveTo", "active_above"], ["MoveTo", "active_grasp"], ["Grasp"],
                          ["MoveTo", "active_above"]]
    assert replay[4][0] == "MoveTo" and replay[4][1].startswith("held:reference_part:")
    assert replay[4:] == report.plan[3:]
    assert len(replay) == len(report.plan) + 1
    saved = report.refinement_saved
    assert saved is not None and saved.get("saved", True) is not False, saved
    assert saved["subtasks"][:4] == ["MoveTo(active_above)", "MoveTo(active_grasp)", "Grasp()", "MoveTo(active_above)"]

    again, joined = run(task_end_monitors=False)
    assert again.ok and again.attempts == [] and again.refinements_used == [saved["method"]]
    assert joined == [("active", "reference")]
