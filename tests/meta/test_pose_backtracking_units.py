"""Pose backtracking without the simulator: the object-gripper transform, sampling good poses from traces, the
step-by-step R_p/R_n comparison, durable pose symbols, and how the reasoner reports a motion limit a plugin found."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from bt_meta_plugins import pose_backtracking as pb

from bt_meta.bt.failures import Failure, FailureKind, RepairProposal
from bt_meta.errors import BtMetaError
from bt_meta.memory import Episode, ObjectState, State, Step, Trace
from bt_meta.meta import MetaExecutor
from bt_meta.plugins import hookimpl
from bt_meta.world.fake import FakeWorld, Fault
from bt_meta.world.simulation.objects import matrix_to_pose, pose_to_matrix
from bt_meta.world.simulation.sim_world import parse_pose_symbol, pose_symbol

from .conftest import make_host

# An active part whose magnet (AP) is 3 cm below its centre, normal -z; the reference's on its top, normal +z.
ACTIVE_AP, ACTIVE_AN = np.array([0.0, 0.0, -0.03]), np.array([0.0, 0.0, -1.0])
REF_AP, REF_AN = np.array([0.0, 0.0, 0.02]), np.array([0.0, 0.0, 1.0])


def state_of(name: str, pose: list[float], ap_local: np.ndarray, an_local: np.ndarray) -> ObjectState:
    t = pose_to_matrix(pose)
    return ObjectState(name, tuple(pose), tuple(t[:3, :3] @ ap_local + t[:3, 3]), tuple(an_local))


def observed(name: str, pose: list[float], ap_local: np.ndarray, an_local: np.ndarray) -> dict[str, Any]:
    """An object as ``world.observe()`` reports it: AP and AN in the base frame."""
    t = pose_to_matrix(pose)
    return {"name": name, "pose": list(pose), "ap": list(t[:3, :3] @ ap_local + t[:3, 3]),
            "an": list(t[:3, :3] @ an_local)}


def joined_trace(reference_pose: list[float], yaw: float, seed: int) -> Trace:
    """Three steps: the active part far away, above the reference, joined on it (AP on AP, normals opposed)."""
    x, y, z = reference_pose[:3]
    joined = [x, y, z + 0.05, 0.0, 0.0, yaw]  # 0.02 + 0.03: the magnets meet
    poses = [[x + 0.3, y, z, 0.0, 0.0, yaw], [x, y, z + 0.15, 0.0, 0.0, yaw], joined]
    steps = tuple(Step(i, "MoveTo", (f"p{i}",), state=State(objects=(
        state_of("reference", reference_pose, REF_AP, REF_AN), state_of("active", pose, ACTIVE_AP, ACTIVE_AN))))
        for i, pose in enumerate(poses))
    return Trace(Episode("Attach", "attach.yaml", "nominal", started=float(seed), outcome="success", seed=seed), steps)


def test_gripper_pose_for_inverts_the_grasp():
    gripper = pose_to_matrix([0.6, -0.2, 0.1, math.pi, 0.1, -0.4])
    grasp = pose_to_matrix([0.0, 0.01, 0.04, math.pi / 2, 0.0, 0.3])  # object in the gripper frame
    held = gripper @ grasp
    assert np.allclose(pb.gripper_pose_for(held, grasp), gripper)
    # a wanted object pose gives the gripper pose that, with the same grasp, puts the object there
    wanted = pose_to_matrix([0.62, -0.1, -0.13, 0.0, 0.0, 1.0])
    assert np.allclose(pb.gripper_pose_for(wanted, grasp) @ grasp, wanted)


def test_local_keypoints_are_intrinsic():
    for pose in ([0.5, 0.1, 0.0, 0.0, 0.0, 0.0], [0.2, -0.3, 0.4, math.pi / 2, 0.2, -1.0]):
        ap, an = pb.local_keypoints(observed("active", pose, ACTIVE_AP, ACTIVE_AN))
        assert np.allclose(ap, ACTIVE_AP) and np.allclose(an, ACTIVE_AN)


def test_good_poses_put_the_attachment_point_and_normal_where_the_traces_had_them_relative_to_the_reference():
    traces = [joined_trace([0.62, -0.10, -0.18, 0.0, 0.0, 0.0], yaw=0.2, seed=s) for s in range(3)]
    # now the reference stands elsewhere and turned; the active part lies on its side
    reference_now = [0.55, 0.05, -0.18, 0.0, 0.0, math.pi / 2]
    active_now = observed("active", [0.3, -0.4, -0.17, math.pi / 2, 0.0, 0.0], ACTIVE_AP, ACTIVE_AN)
    turns = [0.0, math.pi / 2, math.pi]
    candidates = pb.good_object_poses(traces, 2, "active", "reference", turns=turns, order=[2, 0, 1],
                                      reference_now=observed("reference", reference_now, REF_AP, REF_AN),
                                      active_now=active_now)
    assert [(c.trace, c.turn) for c in candidates] == [(j, t) for j in (2, 0, 1) for t in turns]
    ref = pose_to_matrix(reference_now)
    expected_ap = ref[:3, :3] @ REF_AP + ref[:3, 3]  # joined: the active's magnet on the reference's
    for candidate in candidates:
        pose = candidate.object_pose
        assert np.allclose(pose[:3, :3] @ ACTIVE_AP + pose[:3, 3], expected_ap, atol=1e-9)
        assert np.allclose(pose[:3, :3] @ ACTIVE_AN, -(ref[:3, :3] @ REF_AN), atol=1e-9)  # normals opposed
        assert np.allclose(candidate.ap, expected_ap) and np.allclose(candidate.an, [0.0, 0.0, -1.0])
    # turn 0 keeps the trace's own orientation relative to the reference (yaw 0.2 on top of the reference's)
    assert np.isclose(matrix_to_pose(candidates[0].object_pose)[5], math.pi / 2 + 0.2)
    # a quarter turn about the attachment normal (pointing down: a right-hand turn about -z lowers the yaw)
    assert np.isclose(matrix_to_pose(candidates[1].object_pose)[5], 0.2)
    # a trace without the step or the objects gives nothing
    assert pb.good_object_poses(traces, 7, "active", "reference", turns=turns, order=[0],
                                reference_now=observed("reference", reference_now, REF_AP, REF_AN),
                                active_now=active_now) == []


def test_step_relations_find_the_first_deviating_step():
    traces = [joined_trace([0.62, -0.10, -0.18, 0.0, 0.0, 0.0], yaw=0.0, seed=s) for s in range(3)]
    reference = observed("reference", [0.62, -0.10, -0.18, 0.0, 0.0, 0.0], REF_AP, REF_AN)

    def now(pose):
        return {"reference": reference, "active": observed("active", pose, ACTIVE_AP, ACTIVE_AN)}

    actions = {0: "MoveTo", 1: "MoveTo", 2: "MoveTo"}
    nominal = {0: now([0.92, -0.10, -0.18, 0, 0, 0]), 1: now([0.62, -0.10, -0.03, 0, 0, 0]),
               2: now([0.62, -0.10, -0.13, 0, 0, 0])}
    rows = pb.step_relations(nominal, traces, "active", "reference", actions)
    assert [r.deviates for r in rows] == [False, False, False]
    assert rows[2].r_p == pytest.approx(0.0, abs=1e-9) and rows[2].expected_n == pytest.approx(math.pi)
    on_side = dict(nominal)
    on_side[1] = now([0.62, -0.10, -0.03, math.pi / 2, 0, 0])
    on_side[2] = now([0.62, -0.10, -0.13, math.pi / 2, 0, 0])
    rows = pb.step_relations(on_side, traces, "active", "reference", actions)
    assert [r.deviates for r in rows] == [False, True, True]
    assert math.degrees(rows[1].r_n) == pytest.approx(90.0)
    assert rows[1].as_dict()["expected_R_n"] == pytest.approx(math.pi, abs=1e-4)
    # a step the traces ran with another action is not compared
    rows = pb.step_relations(on_side, traces, "active", "reference", {0: "MoveTo", 1: "Grasp", 2: "MoveTo"})
    assert [r.step for r in rows] == [0, 2]


def _record(step: int, action: str, *args: str, tasks: tuple[str, ...] = ("Attach",), node: str | None = None
            ) -> dict[str, Any]:
    return {"step": step, "action": action, "args": list(args), "tasks": list(tasks), "node_id": node or f"n{step}"}


def test_align_steps_follows_a_splice_to_the_tasks_latest_run():
    from bt_meta_plugins._trace_relations import align_steps

    traces = [joined_trace([0.62, -0.10, -0.18, 0.0, 0.0, 0.0], yaw=0.0, seed=0)]  # MoveTo p0, p1, p2
    # the plain plan: every step is the trace's own
    plan = [_record(k, "MoveTo", f"p{k}") for k in range(3)]
    assert align_steps(plan, traces[0], 2) == {0: 0, 1: 1, 2: 2}
    # a re-orientation spliced after the first run (turn, turn), then the task again: its steps 5..7 play 0..2,
    # a pose a repair rewrote (held:...) plays the one it replaced, and a step before the failure counts forwards
    spliced = [*plan, _record(3, "MoveTo", "turn_high"), _record(4, "Grasp"),
               _record(5, "MoveTo", "p0"), _record(6, "MoveTo", "held:ref:0:0:0.05:0:0:0"), _record(7, "MoveTo", "p2")]
    assert align_steps(spliced, traces[0], 7) == {5: 0, 6: 1, 7: 2}
    assert align_steps(spliced, traces[0], 6) == {5: 0, 6: 1, 7: 2}
    # a failure at a step the traces never ran (the repair's own) aligns nothing
    assert align_steps(spliced, traces[0], 4) == {}


def test_align_steps_keeps_the_indices_of_a_plan_nothing_was_spliced_into():
    """A trace of a repaired run (its rewritten moves are ``held:...`` symbols) and a plan that repeats a pattern:
    the plan's steps up to the failed one are the trace's at the same index, so they stay there, even where another
    start in the trace would match as long (the tutorial's peg: the second repaired run found no pose when the
    pick was aligned with the verification's)."""
    from types import SimpleNamespace

    from bt_meta_plugins._trace_relations import align_steps

    def step(action, *args):
        return SimpleNamespace(action=action, args=args)

    trace = SimpleNamespace(steps=[step("MoveTo", "above"), step("MoveTo", "held:base:0:0:0.05:0:0:0"),
                                   step("Grasp"), step("MoveTo", "above"), step("MoveTo", "grasp"), step("Grasp")])
    plan = [_record(0, "MoveTo", "above"), _record(1, "MoveTo", "joint"), _record(2, "Grasp")]
    assert align_steps(plan, trace, 2) == {0: 0, 1: 1, 2: 2}


def test_step_relations_and_the_window_compare_the_aligned_run():
    from bt_meta_plugins._trace_relations import align_steps

    traces = [joined_trace([0.62, -0.10, -0.18, 0.0, 0.0, 0.0], yaw=0.0, seed=s) for s in range(3)]
    reference = observed("reference", [0.62, -0.10, -0.18, 0.0, 0.0, 0.0], REF_AP, REF_AN)

    def now(pose):
        return {"reference": reference, "active": observed("active", pose, ACTIVE_AP, ACTIVE_AN)}

    # first run upside down (deviates from step 1), a turn spliced in, then the second run on its side
    upside_down, side = math.pi, math.pi / 2
    current = {0: now([0.92, -0.10, -0.18, upside_down, 0, 0]), 1: now([0.62, -0.10, -0.03, upside_down, 0, 0]),
               2: now([0.62, -0.10, -0.13, upside_down, 0, 0]), 3: now([0.50, -0.28, -0.10, side, 0, 0]),
               4: now([0.92, -0.10, -0.18, side, 0, 0]), 5: now([0.62, -0.10, -0.03, side, 0, 0]),
               6: now([0.62, -0.10, -0.13, side, 0, 0])}
    plan = [_record(0, "MoveTo", "p0"), _record(1, "MoveTo", "p1"), _record(2, "MoveTo", "p2"),
            # the spliced steps carry the tasks of the step they replaced, here a verification's
            _record(3, "MoveTo", "turn_high", tasks=("Attach", "Verify"), node="n9"),
            _record(4, "MoveTo", "p0", tasks=("Attach", "Verify"), node="n10"),
            _record(5, "MoveTo", "p1", tasks=("Attach", "Verify"), node="n11"),
            _record(6, "MoveTo", "p2", tasks=("Attach", "Verify"), node="n12")]
    actions = {int(r["step"]): r["action"] for r in plan}
    alignment = align_steps(plan, traces[0], 6)
    assert alignment == {4: 0, 5: 1, 6: 2}
    rows = pb.step_relations(current, traces, "active", "reference", actions, alignment=alignment)
    assert [r.step for r in rows] == [4, 5, 6]  # the second run only, against the traces' steps 0..2
    assert math.degrees(rows[1].r_n) == pytest.approx(90.0)
    plugin = pb.PoseBacktracking()
    # the trace's steps ran as nodes n0..n2 (the plan's first run): their tasks say these are not a verification,
    # so the second run's moves are in the window (without the alignment, the verification's tasks hid them)
    traces = [dataclasses.replace(t, steps=tuple(dataclasses.replace(st, node_id=f"n{st.index}") for st in t.steps))
              for t in traces]
    assert plugin._window(plan, current, traces, "active", 5, alignment) == [5, 6]
    assert plugin._window(plan, current, traces, "active", 5) == []


def test_pose_symbols_round_trip_and_refuse_bad_input():
    symbol = pose_symbol([0.61, -0.2, 0.8, 0.0, -0.0, 1.5707963])
    assert symbol == "pose:0.61:-0.2:0.8:0:0:1.5708"
    assert parse_pose_symbol(symbol) == [0.61, -0.2, 0.8, 0.0, 0.0, 1.5708]
    for other in ("joint", "pose:1:2:3", "pose:a:0:0:0:0:0", "pose:1:2:3:4:5:nan"):
        assert parse_pose_symbol(other) is None
    with pytest.raises(BtMetaError, match="6 finite numbers"):
        pose_symbol([0.0, 1.0, math.inf, 0.0, 0.0, 0.0])


def test_plugin_settings_are_checked():
    with pytest.raises(ValueError, match="n must be >= 1"):
        pb.PoseBacktracking(n=0)
    with pytest.raises(ValueError, match="max_candidates"):
        pb.PoseBacktracking(max_candidates=0)


class BlockedByExperience:
    """Knows the repair the failure needs and that the arm cannot make it: answers with the motion limit."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[Any]:
        if failure.kind is not FailureKind.VERIFICATION:
            return []
        return [Failure(FailureKind.COLLISION, "the good pose puts the gripper inside b1", step=1, action="put",
                        evidence={"pair": ["right_gripper", "b1"], "target": [0.6, -0.1, -0.1, 0, 0, 0]})]


def test_a_motion_limit_found_by_a_plugin_stops_the_repair_and_is_reported_with_its_evidence(blocks):
    problem = blocks.problem("one")
    fault = Fault("put", mode="partial", args=("b0", "0", "0"), occurrence=1,
                  drop=(("at", "b0", "0", "0"), ("held", "b0")))
    world = FakeWorld(blocks.domain, problem, faults=[fault])
    report = MetaExecutor(blocks.domain, problem, world,
                          make_host(("blocked", BlockedByExperience()), perception=False)).run()
    # without the limit the retry baseline's replan repairs this failure (test_executor); a limit drops blind repairs
    assert report.status == "failed" and report.attempts == []
    assert "collision blocks the repair of verification at step 1" in report.stop_reason
    assert "not looped on" in report.stop_reason
    kinds = [entry["kind"] for entry in report.reported]
    assert kinds == ["verification", "collision"]
    limit = report.reported[1]
    assert limit["evidence"] == {"pair": ["right_gripper", "b1"], "target": [0.6, -0.1, -0.1, 0, 0, 0]}
    assert limit["plugin"] == "blocked" and limit["blocks_repair_of"] == {"kind": "verification", "step": 1}
    assert [f["kind"] for f in report.failures] == ["verification", "collision"]


class ReplanButDoNotKeep:
    """A repair that works from where the run stands but would not replay from the initial state."""

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[Any]:
        return [RepairProposal("replan", 0.9, "replan here", changes={}, evidence={"keep": False})]


def test_a_repair_its_plugin_says_does_not_replay_is_not_kept_as_a_refinement(blocks, tmp_path):
    from bt_meta.meta import RefinementStore

    problem = blocks.problem("one")
    fault = Fault("put", mode="partial", args=("b0", "0", "0"), occurrence=1,
                  drop=(("at", "b0", "0", "0"), ("held", "b0")))
    world = FakeWorld(blocks.domain, problem, faults=[fault])
    with RefinementStore.open(tmp_path / "memory.sqlite") as store:
        plugins = make_host(("here", ReplanButDoNotKeep()), perception=False)
        report = MetaExecutor(blocks.domain, problem, world, plugins, refinements=store).run()
        assert report.ok and [a.proposal["plugin"] for a in report.attempts] == ["here"]
        assert report.refinement_saved == {
            "saved": False, "reason": "attempt(s) [1]: the proposing plugin says the repaired plan does not replay "
                                      "from the start"}
        assert store.list() == []


def test_a_chain_that_works_only_from_where_the_run_stands_ranks_below_a_repair_that_replays():
    """The same chain, scored as replayable, as kept through a replay of the moves the part was held in, and as
    working only from here: the last ranks below a re-orientation's 0.6 (it replays from the start), so a part on
    its side is turned upright first and the repair is kept (generated magnetic s1 0030, 0038, 0042, 0043, 0051)."""
    from bt_meta_plugins.reorientation import Reorientation

    class World:
        def register_pose(self, symbol: str) -> bool:
            return True

    plugin = pb.PoseBacktracking()
    chain = [(5, np.eye(4), {"relative": [0.0, 0.0, 0.05, 0.0, 0.0, 0.0]})]

    def score(replayable: bool, replay_plan: list | None = None) -> float:
        (proposal,) = plugin._proposal(World(), [5], chain, [], [], {"reference": "reference"}, "active", [1, 2, 3],
                                       replayable, replay_plan)
        return proposal.score

    kept_through_moves = score(False, [(4, "MoveTo", ["joint_above"]), (5, "MoveTo", ["joint"])])
    assert score(True) > kept_through_moves > score(False)
    assert Reorientation().score > score(False) > 0.3  # still above a retry
    # after a failed repair (a re-orientation that did not join the parts) it ranks as a kept one would
    (later,) = plugin._proposal(World(), [5], chain, [], [], {"reference": "reference", "first_repair": False},
                                "active", [1, 2, 3], False, None)
    assert later.score == kept_through_moves
