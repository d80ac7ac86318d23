"""Pose backtracking (paper, section 7.4): repair an attachment that failed its verification from past successes.

On a ``verification`` (or keypoint ``unexpected_configuration``) failure the plugin

1. takes the last N successful traces of the problem's root task (``EpisodicMemory.last_traces``) and, step by
   step, the mean R_p / R_n of the active and reference objects (:mod:`bt_meta.perception.keypoints`); it compares
   them with the same relation in the current execution (object states it snapshots after every step through
   ``bt_meta_observe``) and finds the first deviating step -- step for step as the traces ran them: after a repair
   spliced steps in (a re-orientation, then the task again) the task's latest run is compared, not the first
   (:func:`~bt_meta_plugins._trace_relations.align_steps`);
2. collects the *pose-setting* primitives from there on: ``MoveTo`` steps during which the active object moved
   (it was in hand), never a verification step (under a task named ``verify...``, or with a pose that declares a
   check such as ``verify_lifted``: :func:`bt_meta.meta.invariants.is_verification`);
3. backtracks to the last of them; on a later failure (``evidence["repair_history"]`` shows where it went) one
   further back, until the first pose that differs from the traces -- every pose-setting step from ``to_step`` on,
   up to the next grasp or release (the part held with one grasp), gets a new pose;
4. samples (seeded) a known-good pose of the active object for each such step from the traces, relative to the
   reference object (its attachment point and normal where they were in a success, the rotation about the normal
   the trace's first, then others), turns it into a gripper pose through the current object-gripper relation
   (``gripper = object @ inverse(grasp)``), checks IK and collision of the chain of moves -- and of the plan's
   next move once the part is let go -- from the current configuration and from the one a later replay of the
   repaired plan starts in (the world's collision-aware IK and its collision checker, joint-space paths included,
   the same solver and seed as the MoveTo skill); a chain that only works from where the run stands is still
   proposed, marked ``keep: False`` so the executor does not save it as a refinement;
5. proposes ``backtrack {"to_step": k, "args": {step: [pose symbol]}}`` with a durable pose symbol the world grounds
   and registers (``world.register_pose``): the held part's pose in the reference's frame
   (``held:REFERENCE:x:y:z:roll:pitch:yaw``, REFERENCE the task-file symbol), which the world turns into a gripper
   pose through the grasp at the time of the move -- so a refinement that keeps it stays right when the reference
   has moved within the refinement's tolerance, or the part was picked a little differently (an absolute gripper
   pose ``pose:...`` keeps the first run's reference and grasp, and misses the joint); an absolute symbol only for a
   world that does not ground held poses. Scored by how well the traces agree, and lower (:data:`UNKEPT`) for a
   chain no replay of the repaired plan reaches: below a repair that replays from the start;
   when no sampled pose at any remaining depth is feasible it answers with a ``collision`` or ``reachability``
   :class:`~bt_meta.bt.failures.Failure` carrying the evidence (the colliding pair, the unreachable target): the
   reasoner reports it and never loops on it.

Offers:

* :class:`PoseBacktracking` -- the plugin as an object (memory, N, seed, tolerances, candidates per depth)
* :func:`step_relations` -- per-step R_p / R_n, current against the traces' means, and the first deviating step
* :func:`good_object_poses` -- seeded candidate poses of the active object from the traces (relative to the
  reference, then placed on the reference as it is now)
* :func:`gripper_pose_for` -- the gripper pose that holds an object at a pose, through the grasp transform
* :func:`configure` and the module-level hooks (``bt_meta_observe``, ``bt_meta_propose_repairs``): the entry point

The geometry lives in ``_good_poses``, the step comparison in ``_trace_relations`` (re-exported here).
"""

from __future__ import annotations

import logging
import math
import time
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from bt_meta_plugins._good_poses import good_object_poses, gripper_pose_for, local_keypoints
from bt_meta_plugins._good_poses import matrix_of as _matrix
from bt_meta_plugins._good_poses import state_pose as _state_pose
from bt_meta_plugins._trace_relations import StepRelation, align_steps, step_relations
from bt_meta_plugins._trace_relations import moved as _moved
from bt_meta_plugins._trace_relations import moved_in_trace as _moved_in_trace

from bt_meta.bt.failures import Failure, FailureKind, RepairProposal
from bt_meta.meta.invariants import is_verification
from bt_meta.perception.recall import memory_for, root_task
from bt_meta.plugins import ConfiguredPlugin, hookimpl
from bt_meta.world.simulation.objects import matrix_to_pose, pose_to_matrix

__all__ = ["PoseBacktracking", "StepRelation", "configure", "good_object_poses", "gripper_pose_for",
           "local_keypoints", "step_relations"]

log = logging.getLogger("bt_meta.meta.pose_backtracking")

STRATEGY = "pose_backtracking"

UNKEPT = 0.55
"""Score factor of a chain that works only from where the run stands (no replay of the repaired plan reaches it),
as the run's first repair: at most 0.52, below a repair that replays from the start (a re-orientation, 0.6), so the
robot first tries a repair it can keep. Magnetic s1 0030, 0038, 0042, 0043, 0051 (a part on its side): the
backtrack through the grasp the failed attach left repaired them, and the second exposure repeated it; turned
upright first, they keep the repair and replay it with zero attempts. After a failed repair it is scored as any
other (magnetic s0 0055: turned twice and still not joined, a third turn instead of the backtrack failed)."""
KINDS = (FailureKind.VERIFICATION, FailureKind.UNEXPECTED_CONFIGURATION)


# -- the plugin -------------------------------------------------------------------------------------------------


class PoseBacktracking:
    """The repair plugin (see the module docstring).

    ``memory``: an :class:`~bt_meta.memory.EpisodicMemory` (default: the run's, else ``BT_META_MEMORY``, else the
    default file); ``n`` traces; ``seed`` for the sampling; ``turns`` rotations about the attachment normal tried
    per trace (radians; the trace's own orientation first; default every 22.5 degrees); ``pose_actions`` the
    primitives that set a pose; ``max_candidates`` chains checked per backtracking depth (candidates are ordered
    trace by trace, so the first ones are the turns of one trace); ``max_check_seconds`` bounds the IK and
    collision checks of one proposal round (the limits found so far are then reported).
    """

    def __init__(self, memory: Any = None, *, n: int = 3, seed: int = 0, position_tolerance: float | None = 0.01,
                 angle_tolerance: float | None = math.radians(15.0), turns: Sequence[float] | None = None,
                 pose_actions: Iterable[str] = ("MoveTo",), max_candidates: int = 48,
                 max_check_seconds: float = 20.0) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        if max_candidates < 1:
            raise ValueError(f"max_candidates must be >= 1, got {max_candidates}")
        if max_check_seconds <= 0:
            raise ValueError(f"max_check_seconds must be > 0, got {max_check_seconds}")
        self.memory = memory
        self.n = n
        self.seed = seed
        self.position_tolerance = position_tolerance
        self.angle_tolerance = angle_tolerance
        self.turns = list(turns) if turns is not None else [k * math.pi / 8.0 for k in range(16)]
        self.pose_actions = frozenset(pose_actions)
        self.max_candidates = max_candidates
        self.max_check_seconds = max_check_seconds
        self._run: Any = None
        self._world: Any = None
        self._current: dict[int, dict[str, Any]] = {}
        self._q: dict[int, np.ndarray] = {}
        """The robot's configuration after each step of the run (where a replay of a repaired plan passes)."""
        self._grasps: dict[int, dict[str, np.ndarray]] = {}
        """After each step, each held object's pose in its gripper's frame (the grasp a replay holds it with)."""

    # -- the current trace ---------------------------------------------------------------------------------------

    @hookimpl
    def bt_meta_observe(self, world: Any, context: Any) -> dict[str, Any] | None:
        """Snapshot the object states after each step of the run (the current trace T_curr); observes nothing."""
        observe = getattr(world, "observe", None)
        step = getattr(context, "step", None)
        if observe is None or step is None:
            return None
        run = getattr(context, "run", None)
        if run is not self._run:
            self._run, self._current, self._q, self._grasps = run, {}, {}, {}
        seen = observe()
        objects = seen.get("objects") or {}
        self._current[int(step)] = {name: dict(state) for name, state in objects.items()}
        grippers = seen.get("gripper") or {}
        self._grasps[int(step)] = {
            name: np.linalg.inv(_matrix(grippers[arm])) @ _state_pose(objects[name])
            for arm, name in (seen.get("held") or {}).items() if name in objects and arm in grippers}
        current_q = getattr(world, "current_q", None)
        if current_q is not None:
            self._q[int(step)] = np.array(current_q(), dtype=float)
        return None

    # -- proposing -----------------------------------------------------------------------------------------------

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Failure, context: Any) -> list[Any] | None:
        if failure.kind not in KINDS or context is None:
            return None
        world = getattr(context, "world", None)
        memory = memory_for(context, self.memory)
        task = root_task(context)
        if world is None or memory is None or task is None:
            return None
        traces = memory.last_traces(task, self.n)
        if not traces:
            log.info("pose backtracking: no successful trace of %s in memory", task)
            return None
        active, reference = self._pair(context, world)
        if active is None or reference is None:
            return None
        plan = list(failure.evidence.get("plan") or [])
        failed = failure.step if failure.step is not None else len(plan) - 1
        actions = {int(s["step"]): str(s["action"]) for s in plan}
        current = {s: objs for s, objs in self._current.items() if s <= failed} if self._run is context.run else {}
        # which trace step each plan step plays: after a splice (a re-orientation, then the task again) the task's
        # second run is compared with the traces, not its first
        alignment = align_steps(plan, traces[0], failed)
        aligned = alignment if alignment and any(k != v for k, v in alignment.items()) else None
        rows = step_relations(current, traces, active, reference, actions,
                              position_tolerance=self.position_tolerance, angle_tolerance=self.angle_tolerance,
                              alignment=aligned)
        deviating = [r.step for r in rows if r.deviates]
        evidence: dict[str, Any] = {"strategy": STRATEGY, "active": active, "reference": reference,
                                    "traces": [t.episode.id for t in traces], "relations": [r.as_dict() for r in rows]}
        if not deviating:
            log.info("pose backtracking: the current trace agrees with the traces at every step; nothing to do")
            return None
        first = deviating[0]
        evidence["first_deviating_step"] = first
        self._world = world
        window = self._window(plan, current, traces, active, first, aligned)
        evidence["pose_steps"] = window
        done = [int(a["proposal"]["changes"]["to_step"]) for a in failure.evidence.get("repair_history") or []
                if (a.get("proposal") or {}).get("evidence", {}).get("strategy") == STRATEGY]
        targets = [s for s in window if s <= failed and (not done or s < min(done))]
        if not targets:
            log.info("pose backtracking: backtracked to the first pose that differs from the traces already")
            return None
        now = world.observe()
        held_by = next((arm for arm, name in (now.get("held") or {}).items() if name == active), None)
        if held_by is None:
            log.info("pose backtracking: %s is not in hand; the pose-setting moves cannot be redone", active)
            return None
        objects = now["objects"]
        grasp = np.linalg.inv(_matrix(now["gripper"][held_by])) @ _state_pose(objects[active])
        rng = np.random.default_rng(self.seed + len(done))
        limits: list[dict[str, Any]] = []
        deadline = time.perf_counter() + self.max_check_seconds
        fallback = None
        for to_step in reversed(targets):  # the last pose-setting step first, then one further back
            steps = self._held_moves(plan, window, to_step)
            after = self._next_move(world, held_by, plan, steps[-1])
            replay = self._q.get(to_step - 1) if self._run is context.run else None
            # a replay holds the part as this run held it before the first rewritten move, not as it holds it now
            # (the part may have been picked again since, from somewhere else)
            replay_grasp = (self._grasps.get(to_step - 1) or {}).get(active, grasp) if replay is not None else grasp
            chain, replayable = self._feasible_chain(world, held_by, steps, traces, active, reference, objects, grasp,
                                                     rng, limits, after, deadline, starts=[(replay, replay_grasp)],
                                                     trace_steps=aligned)
            if chain is not None and not replayable:
                fallback = fallback or (steps, chain)
                continue
            if chain is None:
                continue
            return self._proposal(world, steps, chain, rows, limits, evidence, active, traces, True)
        if fallback is not None:
            replay_plan = self._replay_through(plan, fallback[0][0], failed, failure.kind)
            evidence["first_repair"] = not failure.evidence.get("repair_history")
            return self._proposal(world, *fallback, rows, limits, evidence, active, traces, False, replay_plan)
        return [self._limit(limits, window, evidence)]

    def _proposal(self, world: Any, steps: list[int], chain: list[tuple[int, np.ndarray, dict[str, Any]]],
                  rows: list[StepRelation], limits: list[dict[str, Any]], evidence: dict[str, Any], active: str,
                  traces: Sequence[Any], replayable: bool, replay_plan: list[list[str]] | None = None
                  ) -> list[RepairProposal] | None:
        """The ``backtrack`` proposal for a feasible chain (its pose symbols registered with the world);
        ``replay_plan`` (with the chain's steps still to be filled in) when the plan replays only through the moves
        this run made before the repair."""
        symbols = {}
        relative_to = self._reference_symbol(world, evidence["reference"])
        for step, pose, where in chain:
            symbol = self._symbol(world, pose, relative_to, where.get("relative"))
            if symbol is None:
                return None
            symbols[str(step)] = [symbol]
        agreement = self._agreement(rows, steps)
        evidence.update(to_step=steps[0], rewritten=steps, candidates=[where for _, _, where in chain],
                        infeasible_before=len(limits), agreement=round(agreement, 4), replayable=replayable)
        if not replayable and replay_plan is not None:
            # The chain works from where this run stands; a replay gets there through the same moves (the part
            # held all along): keep that plan -- the run's prefix, then the repaired steps -- not the tree's.
            evidence["replay_plan"] = [[a, *(symbols.get(str(k), args) if k is not None else args)]
                                       for k, a, args in replay_plan]
            evidence["replay"] = "through the moves this run made before the repair (the part held all along)"
        elif not replayable:
            evidence["keep"] = False  # works from where this run stands, not in a replay from the start
            evidence["not_kept_because"] = next((item for item in limits if item.get("from")), {})
        # a repair that cannot be kept yields to one that can only as the run's first: once repairs have failed,
        # the one that works from here goes first (magnetic s0 0055: turned twice, still not joined)
        kept = replayable or "replay_plan" in evidence or not evidence.get("first_repair", True)
        return [RepairProposal(
            "backtrack", (0.35 + 0.6 * agreement) * (1.0 if replayable else 0.9 if kept else UNKEPT),
            f"back to step {steps[0]}: {len(steps)} pose(s) of {active} from {len(traces)} successful trace(s), "
            f"turned into gripper poses through the current grasp",
            changes={"to_step": steps[0], "args": symbols}, evidence=evidence)]

    # -- helpers -------------------------------------------------------------------------------------------------

    def _replay_through(self, plan: list[dict[str, Any]], to_step: int, failed: int, kind: FailureKind
                        ) -> list[tuple[int | None, str, list[str]]] | None:
        """A plan that replays from the start and reaches the repaired steps as this run did: the steps before
        ``to_step``, the executed steps ``to_step..failed`` as they ran, then the plan from ``to_step`` again
        (``(step, action, args)``; ``step`` is ``None`` for the moves kept as they ran, so the repair's new
        arguments go into the repeated ones only). ``None`` unless those executed steps are pose-setting moves
        only (no grasp, no release: nothing of a failed attempt is replayed) that finished (a monitor or a
        verification objected after the move: ``kind``)."""
        if kind not in KINDS or failed < to_step:
            return None
        by_step = {int(r["step"]): r for r in plan}
        between = [by_step.get(k) for k in range(to_step, failed + 1)]
        if any(r is None or r["action"] not in self.pose_actions
               or any(str(t).lower().startswith("verify") for t in r.get("tasks") or []) for r in between):
            return None
        prefix = [(int(r["step"]), str(r["action"]), [str(a) for a in r["args"]]) for r in plan
                  if int(r["step"]) < to_step]
        ran = [(None, str(r["action"]), [str(a) for a in r["args"]]) for r in between if r is not None]
        rest = [(int(r["step"]), str(r["action"]), [str(a) for a in r["args"]]) for r in plan
                if int(r["step"]) >= to_step]
        return [*prefix, *ran, *rest]

    def _held_moves(self, plan: list[dict[str, Any]], window: list[int], to_step: int) -> list[int]:
        """The steps of ``window`` from ``to_step`` on up to the plan's next step that is not a pose-setting move (a
        grasp or a release): the part is held with one grasp along them, which the sampled poses assume (a move
        after the release -- lifting the reference with the part joined to it -- is no pose of the held part)."""
        stop = min((int(r["step"]) for r in plan if int(r["step"]) > to_step
                    and str(r["action"]) not in self.pose_actions), default=None)
        return [s for s in window if s >= to_step and (stop is None or s < stop)]

    def _pair(self, context: Any, world: Any) -> tuple[str | None, str | None]:
        tasks = getattr(getattr(context.run, "problem", None), "tasks", None) or []
        if not tasks or len(tasks[0]) < 3:
            return None, None
        to_world = getattr(world, "object_name", None)
        names = []
        for symbol in (str(tasks[0][1]), str(tasks[0][2])):
            try:
                names.append(str(to_world(symbol)) if to_world is not None else symbol)
            except Exception:  # a symbol the world does not know as an object: keep it
                names.append(symbol)
        return names[0], names[1]

    def _window(self, plan: list[dict[str, Any]], current: Mapping[int, Mapping[str, Any]], traces: Sequence[Any],
                active: str, first: int, alignment: Mapping[int, int] | None = None) -> list[int]:
        """Pose-setting steps of the attachment (not of its verification) from the first deviating step on: the
        active object moved during them in this run, or -- for steps not run yet -- in the first trace.

        With an ``alignment`` (plan step -> trace step, :func:`align_steps`) only the aligned steps count, and a
        step's task is the one its trace step ran under (steps a repair spliced in carry the tasks of the step
        they replaced: a second attach spliced in after the verification is not part of the verification)."""
        out = []
        tasks_of_node = ({str(r.get("node_id")): r.get("tasks") or [] for r in plan if r.get("node_id")}
                         if alignment is not None else {})
        for record in plan:
            step = int(record["step"])
            if step < first or record["action"] not in self.pose_actions:
                continue
            index = step
            tasks = record.get("tasks") or []
            if alignment is not None:
                if step not in alignment:
                    continue
                index = alignment[step]
                node = traces[0].steps[index].node_id if index < len(traces[0].steps) else None
                tasks = tasks_of_node.get(str(node), tasks) if node is not None else tasks
            if is_verification(self._world, [record["action"], *record.get("args", [])], tasks):
                continue  # a verification step is never rewritten (bt_meta.meta.invariants)
            before, after = current.get(step - 1), current.get(step)
            if before is not None and after is not None and active in before and active in after:
                moved = _moved(before[active], after[active])
            else:
                moved = _moved_in_trace(traces[0], index, active)
            if moved:
                out.append(step)
        return out

    def _feasible_chain(self, world: Any, arm: str, steps: list[int], traces: Sequence[Any], active: str,
                        reference: str, objects: Mapping[str, Any], grasp: np.ndarray, rng: np.random.Generator,
                        limits: list[dict[str, Any]], after: tuple[int, np.ndarray] | None = None,
                        deadline: float = math.inf,
                        starts: Sequence[tuple[np.ndarray | None, np.ndarray]] = (),
                        trace_steps: Mapping[int, int] | None = None,
                        ) -> tuple[list[tuple[int, np.ndarray, dict[str, Any]]] | None, bool]:
        """The first sampled candidate (trace, turn) whose gripper poses for ``steps`` are all reachable without
        collision in a row from the current configuration and from each of ``starts`` (configuration and grasp
        where a later run that replays the repaired plan begins the first of them: the part's poses relative to
        the reference are the candidate's, the gripper's follow from that grasp), and from whose last pose the
        plan's next move
        (``after``: step and gripper pose, the retreat once the part is let go) is free too: ``(chain, True)``.
        Else the first that works from the current configuration only: ``(chain, False)``; else ``(None, False)``.
        Failures are appended to ``limits``. ``trace_steps``: the trace step each of ``steps`` plays (default the
        same index)."""
        order = [int(j) for j in rng.permutation(len(traces))]
        turns = [self.turns[0], *(self.turns[int(k) + 1] for k in rng.permutation(len(self.turns) - 1))]
        per_step = {step: good_object_poses(traces, (trace_steps or {}).get(step, step), active, reference,
                                            reference_now=objects[reference],
                                            active_now=objects[active], turns=turns, order=order) for step in steps}
        reference_frame = _state_pose(objects[reference])
        count = min(self.max_candidates, *(len(c) for c in per_step.values()))
        origins = [(_current_q(world), grasp), *((q, g) for q, g in starts if q is not None)]
        fallback = None
        for index in range(count):
            if time.perf_counter() > deadline:
                limits.append({"step": steps[0], "kind": None, "search_stopped": f"{self.max_check_seconds} s spent"})
                break
            chain = []
            for step in steps:
                candidate = per_step[step][index]
                relative = _rounded(np.linalg.inv(reference_frame) @ candidate.object_pose)
                pose = gripper_pose_for(reference_frame @ relative, grasp)  # as the world grounds the symbol now
                chain.append((step, pose, {"step": step, "trace": candidate.trace,
                                           "turn_deg": round(math.degrees(candidate.turn), 1),
                                           "target": [round(v, 4) for v in matrix_to_pose(pose)],
                                           "relative": [round(v, 4) for v in matrix_to_pose(relative)]}))
            problem = None
            for number, (origin, held_as) in enumerate(origins):
                moves = chain if held_as is grasp else [
                    (step, gripper_pose_for(reference_frame @ pose_to_matrix(where["relative"]), held_as), where)
                    for step, _, where in chain]
                problem = self._check_chain(world, arm, moves, origin, after, active)
                if problem is not None:
                    if number:
                        problem["from"] = "the configuration a replay of the repaired plan starts from"
                        fallback = fallback or chain
                    limits.append(problem)
                    break
            if problem is None:
                return chain, True
        return fallback, False

    def _check_chain(self, world: Any, arm: str, chain: list[tuple[int, np.ndarray, dict[str, Any]]],
                     q: np.ndarray | None, after: tuple[int, np.ndarray] | None, active: str) -> dict[str, Any] | None:
        """The first problem (evidence with ``kind``) of running ``chain`` from configuration ``q``, then ``after``
        with the part let go; ``None`` when it is free."""
        seed = int(getattr(world, "seed", self.seed))
        for _, pose, where in chain:
            problem, q = _check_motion(world, arm, pose, q, seed=seed)
            if problem is not None:
                return {**where, **problem}
        if after is None:
            return None
        step, pose = after
        problem, _ = _check_motion(world, arm, pose, q, seed=seed, released=active)
        if problem is None:
            return None
        return {"step": step, "after_candidate": chain[-1][2], "target": [round(v, 4) for v in matrix_to_pose(pose)],
                **problem}

    def _next_move(self, world: Any, arm: str, plan: list[dict[str, Any]], last: int
                   ) -> tuple[int, np.ndarray] | None:
        """The first pose-setting step after ``last`` in the plan and its gripper pose as the world grounds it now
        (``world.ground_pose``), or ``None``."""
        ground = getattr(world, "ground_pose", None)
        for record in plan:
            if int(record["step"]) <= last or record["action"] not in self.pose_actions:
                continue
            if ground is None or len(record["args"]) != 1:
                return None
            try:
                return int(record["step"]), np.asarray(ground(str(record["args"][0]), arm), dtype=float)
            except Exception:  # a pose the world cannot ground now: not checked
                return None
        return None

    def _symbol(self, world: Any, pose: np.ndarray, relative_to: str | None = None,
                relative: Sequence[float] | None = None) -> str | None:
        """The held part's pose relative to ``relative_to`` when the world grounds such symbols, else the gripper's
        absolute ``pose``; registered with the world (``None`` when it cannot ground either)."""
        from bt_meta.world.simulation.sim_world import held_pose_symbol, pose_symbol

        register = getattr(world, "register_pose", None)
        if register is None:
            return None
        symbols = [pose_symbol(matrix_to_pose(pose))]
        if relative_to is not None and relative is not None:
            symbols.insert(0, held_pose_symbol(relative_to, relative))
        for symbol in symbols:
            if register(symbol):
                return symbol
        log.info("pose backtracking: the world cannot ground the pose symbols %s", symbols)
        return None

    def _reference_symbol(self, world: Any, reference: str) -> str | None:
        """The task-file symbol of the reference (the root task's second argument; it follows a rebinding), or its
        world name when the task does not name it."""
        tasks = getattr(getattr(getattr(self, "_run", None), "problem", None), "tasks", None) or []
        to_world = getattr(world, "object_name", None)
        if tasks and len(tasks[0]) >= 3 and to_world is not None:
            symbol = str(tasks[0][2])
            try:
                if str(to_world(symbol)) == reference:
                    return symbol
            except Exception:  # a symbol the world does not ground: use the object's name
                pass
        return reference if ":" not in reference else None

    def _agreement(self, rows: list[StepRelation], steps: list[int]) -> float:
        """How consistent the traces are (0..1) about the steps whose poses they supply: 1 when every trace had
        the same relation there (the sampled pose is as good as any of them)."""
        position = self.position_tolerance or 0.01
        angle = self.angle_tolerance or math.radians(15.0)
        spread = [row.spread_p / position + row.spread_n / angle for row in rows if row.step in steps]
        if not spread:
            return 0.5
        return math.exp(-float(np.mean(spread)))

    def _limit(self, limits: list[dict[str, Any]], window: list[int], evidence: dict[str, Any]) -> Failure:
        """The motion limit that blocks every sampled pose: collision when any candidate collided (the paper's
        gripper covering the attachment point), reachability otherwise."""
        checked = [item for item in limits if item.get("kind") is not None]
        collided = [item for item in checked if item.get("kind") == FailureKind.COLLISION.value]
        kind = FailureKind.COLLISION if collided else FailureKind.REACHABILITY
        counts = Counter(tuple(item["pair"]) for item in collided if item.get("pair"))
        common = counts.most_common(1)[0][0] if counts else None
        worst = next((item for item in collided if tuple(item.get("pair") or ()) == common), None) \
            or (checked or [{}])[0]
        detail = dict(worst)
        detail.update(evidence)
        detail.update(candidates_checked=len(checked), pose_steps=window,
                      contacts=[{"pair": list(pair), "candidates": n} for pair, n in counts.most_common()])
        if len(checked) < len(limits):
            detail["search_stopped"] = f"after {self.max_check_seconds} s"
        if kind is FailureKind.COLLISION:
            message = (f"every known-good pose of {evidence['active']} sampled from the traces collides once held "
                       f"as it is now ({len(checked)} candidate(s); most often {' / '.join(worst.get('pair') or [])})")
        else:
            message = (f"no known-good pose of {evidence['active']} sampled from the traces is reachable as it is "
                       f"held now ({len(checked)} candidate(s))")
        return Failure(kind=kind, message=message, step=worst.get("step"), action="MoveTo", evidence=detail)


def _current_q(world: Any) -> np.ndarray | None:
    current = getattr(world, "current_q", None)
    return None if current is None else current()


def _rounded(pose: np.ndarray) -> np.ndarray:
    """``pose`` as the world will ground its symbol (rounded as :func:`pose_symbol` rounds)."""
    from bt_meta.world.simulation.sim_world import parse_pose_symbol, pose_symbol

    values = parse_pose_symbol(pose_symbol(matrix_to_pose(pose)))
    assert values is not None
    return pose_to_matrix(values)


def _check_motion(world: Any, arm: str, target: np.ndarray, q_start: np.ndarray | None, *, seed: int,
                  released: str | None = None) -> tuple[dict[str, Any] | None, np.ndarray | None]:
    """IK (collision-aware) for ``target`` from ``q_start`` and a collision check of the joint-space path, as the
    MoveTo skill will run it (same solver, same seed: the world's). ``released`` names the held part when the move
    comes after it was let go: the path's contacts of that part (which the checker still carries with the hand)
    do not count. Returns (problem evidence with ``kind``, None) or (None, the goal configuration);
    a world without IK is not checked."""
    ik = getattr(world, "ik", None)
    if ik is None or q_start is None:
        return None, q_start
    import pinocchio as pin

    sync = getattr(world, "sync_collision", None)
    if sync is not None:
        sync()
    result = ik.solve(arm, pin.SE3(target[:3, :3], target[:3, 3]), q_start, seed=seed)
    if not result.success:
        evidence = {key: value for key, value in dict(result.evidence).items() if _jsonable(value)}
        evidence["kind"] = result.kind or FailureKind.REACHABILITY.value
        evidence["ik"] = result.message
        if "pair" in evidence and hasattr(world, "contact_object"):
            evidence["objects"] = [world.contact_object(name) for name in evidence["pair"]]
        return evidence, None
    assert result.q is not None
    collision = getattr(world, "collision", None)
    indices = world.kin.arm_indices(arm)
    start, goal = q_start[indices], result.q[indices]
    max_step = float(getattr(world, "joint_speed", 1.5)) * float(getattr(world, "tick_seconds", 0.05))
    count = max(1, math.ceil(float(np.max(np.abs(goal - start))) / max_step))
    for k in range(1, count):
        q = q_start.copy()
        q[indices] = start + (goal - start) * (k / count)
        if collision is None:
            contact = None
        elif released is None:
            contact = collision.check(q, arm=arm)
        else:
            owner = getattr(world, "contact_object", lambda name: name)
            contact = next((c for c in collision.all_contacts(q)
                            if released not in (owner(c.pair[0]), owner(c.pair[1]))), None)
        if contact is not None:
            pair = [str(n) for n in contact.pair]
            return {"kind": FailureKind.COLLISION.value, "pair": pair,
                    "collision_kind": contact.kind,
                    "objects": [world.contact_object(n) for n in pair] if hasattr(world, "contact_object") else pair,
                    "waypoint": k, "waypoints": count, "ik": "path collides"}, None
    return None, result.q


def _jsonable(value: Any) -> bool:
    return isinstance(value, (str, int, float, bool, type(None), list, tuple, dict))


plugin = ConfiguredPlugin(PoseBacktracking)
configure = plugin.configure


@hookimpl
def bt_meta_observe(world: Any, context: Any) -> dict[str, Any] | None:
    return plugin.current.bt_meta_observe(world, context)


@hookimpl
def bt_meta_propose_repairs(failure: Failure, context: Any) -> list[Any] | None:
    return plugin.current.bt_meta_propose_repairs(failure, context)
