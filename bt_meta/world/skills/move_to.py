"""MoveTo(pose): inverse kinematics for a gripper pose, then a joint-space trajectory executed over several ticks.

The first tick solves IK (mink, the current configuration as the first seed, collision-aware against the scene
mirrored from the simulator) and checks every waypoint of the straight joint-space path for collisions -- where
one collides, the gripper's straight line, a lift first, then a path planned around
(:mod:`~bt_meta.world.kinematics.path_planning`) are tried in that order (``info["path"]`` says which); each
tick then drives the arm one waypoint further (``world.steps_per_tick`` physics steps) and the skill stays
RUNNING until the gripper is within tolerance of the target. Failures are classified, never raised:

* ``reachability`` -- IK found no solution (evidence: target, best residual; for a pose symbol ``above`` an object,
  the object as ``out_of_reach``: it cannot be picked up where it lies);
* ``collision`` -- every IK solution collides, or every way there does (evidence: the colliding pair of the
  joint-space line, the planner's cost);
* ``physical`` -- the arm did not arrive (blocked), or the held object slipped out of the grasp.
* ``verification`` -- at a pose with ``verify_lifted`` (section 7.3's staging), a listed part stayed on the table,
  or came along without being joined to what is held, directly or through other joins (it rests on it).

Offers:

* :class:`MoveTo` -- the skill; ``start([symbol])`` grounds a pose symbol through the world, ``begin(pose)``
  takes a 4x4 gripper pose in the robot base frame
"""

from __future__ import annotations

import itertools
import math
import time
from typing import Any

import numpy as np
import pinocchio as pin

from bt_meta.bt.failures import FailureKind
from bt_meta.world.base import RUNNING, SUCCESS
from bt_meta.world.kinematics.path_planning import PlanningStats, plan_path
from bt_meta.world.poses import matrix_to_pose, pose_to_matrix
from bt_meta.world.skills.base import SimSkill, SkillAbort, rounded

__all__ = ["MoveTo"]


class MoveTo(SimSkill):
    """Move the arm's gripper frame to a pose (robot base frame)."""

    name = "move_to"

    def __init__(self, world: Any, arm: str | None = None, *, position_tolerance: float = 0.003,
                 orientation_tolerance: float = 0.05, settle_ticks: int = 12, require_arrival: bool = True,
                 check_path: bool = True, check_held: bool = True, carried_clearance: float = 0.0,
                 speed: float = 1.0, straight: bool = False) -> None:
        super().__init__(world, arm)
        self._straight_asked = straight
        self.straight = straight
        """Move the gripper frame along the straight line (an insertion), where IK follows it; else joint space."""
        if not 0.0 < speed <= 1.0:
            raise ValueError(f"move_to speed must be in (0, 1] of the world's joint speed, got {speed}")
        self.speed = speed
        """Fraction of the world's joint speed the waypoints are cut for."""
        self.carried_clearance = carried_clearance
        """A held object keeps this much (m) from every other object on the way (not from the table); negative, it
        may press that far into one, at the goal too (a block set down snug beside others)."""
        self.position_tolerance = position_tolerance
        self.orientation_tolerance = orientation_tolerance
        self.settle_ticks = settle_ticks
        self.require_arrival = require_arrival
        self.check_path = check_path
        self.check_held = check_held
        self.target: np.ndarray | None = None
        self.label = ""
        self._waypoints: list[np.ndarray] = []
        self._next = 0
        self._settling = 0
        self._held_rel: np.ndarray | None = None
        self.verify: list[str] = []
        """Objects that must hang above the table on arrival (the paper's staging-pose verification)."""

    # -- grounding ----------------------------------------------------------------------------------------------

    def ground(self, args: tuple[str, ...]) -> None:
        if len(args) == 6:
            try:
                pose = pose_to_matrix([float(a) for a in args])
            except ValueError:
                raise SkillAbort(FailureKind.INTERNAL, f"move_to: six arguments must be numbers, got {args}") from None
            self.begin(pose, "(" + ", ".join(args) + ")")
            return
        if len(args) != 1:
            raise SkillAbort(FailureKind.INTERNAL, f"move_to takes a pose symbol (or 6 numbers), got {list(args)}")
        spec = self.world.pose_spec(args[0])
        # what a following grasp is meant to close on (the grasp skill tells an obstacle on top of it apart)
        self.world.grasp_target = self.world.object_name(str(spec["above"])) if "above" in spec else None
        self.straight = self._straight_asked
        if spec.get("touch") and "above" in spec:
            # A grasp pose: the fingers may touch the object they are about to close on.
            target = self.world.object_name(str(spec["above"]))
            self.world.allow_hand(target, self.arm)
            # A friction grasp's open fingers go down around the part with millimetres to spare (a housing's 7 cm
            # flange in the Panda's 8 cm): along the straight line, where the joint-space line swung them 13 mm
            # sideways into the flange and turned the part before they closed.
            self.straight = self.straight or self.world.sim.grasps_by_friction(target, self.arm)
        self.begin(self.world.ground_pose(args[0], self.arm), args[0])
        # a pose over an object where it lies: no IK solution there means the object is out of reach
        self.reached = self.world.grasp_target
        self.verify = [self.world.object_name(str(o)) for o in spec.get("verify_lifted", ())]

    def begin(self, pose: np.ndarray, label: str = "") -> MoveTo:
        self.begin_ground()
        self.target = np.asarray(pose, dtype=float)
        self.label = label
        self.reached: str | None = None
        self._waypoints = []
        self._next = 0
        self._settling = 0
        held = self.world.sim.held(self.arm)
        self._held_rel = None if held is None or not self.check_held else self.world.held_relative(self.arm)
        self.info = {"target": rounded(matrix_to_pose(self.target)), "label": label}
        return self

    # -- ticking ------------------------------------------------------------------------------------------------

    def step(self) -> str:
        world = self.world
        if not self._waypoints:
            self._plan()
        if self._next < len(self._waypoints):
            world.drive_arm(self.arm, self._waypoints[self._next])
            self._next += 1
            world.advance()
            return RUNNING if self._next < len(self._waypoints) or not self._arrived() else self._finish()
        world.advance()
        if self._arrived():
            return self._finish()
        self._settling += 1
        if self._settling >= self.settle_ticks:
            if not self.require_arrival:
                return self._finish()
            position, rotation = self._error()
            contacts = world.robot_contacts(self.arm)
            raise SkillAbort(
                FailureKind.COLLISION if contacts else FailureKind.PHYSICAL,
                f"move_to {self.label}: the gripper stopped {position * 1000:.1f} mm / {rotation:.3f} rad short of the "
                "target" + (f"; the arm touches {', '.join(contacts)}" if contacts else ""),
                {"target": self.info["target"], "position_error": position, "orientation_error": rotation,
                 "contacts": contacts, "pair": [f"{self.arm}_arm", contacts[0]] if contacts else None},
            )
        return RUNNING

    def _max_step(self) -> float:
        """The largest joint change (rad) between waypoints: one tick at :attr:`speed` of the joint speed."""
        return self.world.joint_speed * self.speed * self.world.tick_seconds

    def _plan(self) -> None:
        world = self.world
        assert self.target is not None
        world.sync_collision()
        q_now = world.current_q()
        started = time.perf_counter()
        result = world.ik.solve(self.arm, pin.SE3(self.target[:3, :3], self.target[:3, 3]), q_now, seed=world.seed,
                                carried_clearance=min(self.carried_clearance, 0.0))
        self.info["ik_time_ms"] = round((time.perf_counter() - started) * 1000.0, 3)
        self.info["ik_attempts"] = result.attempts
        if not result.success:
            kind = result.kind or FailureKind.REACHABILITY.value
            evidence = dict(result.evidence)
            evidence["label"] = self.label
            if "pair" in evidence:  # geometry names -> object names ("board~2" is a part of "board")
                evidence["objects"] = [world.contact_object(name) for name in evidence["pair"]]
            if kind == FailureKind.REACHABILITY.value and self.reached:
                evidence["out_of_reach"] = self.reached  # object substitution takes another one
            raise SkillAbort(kind, f"move_to {self.label}: {result.message}", evidence)
        assert result.q is not None
        indices = world.kin.arm_indices(self.arm)
        start, goal = q_now[indices], result.q[indices]
        max_step = self._max_step()
        count = max(1, math.ceil(float(np.max(np.abs(goal - start))) / max_step))
        waypoints = (self._straight_line(q_now, count) if self.straight else None) or []
        for k in range(1, count + 1) if not waypoints else ():
            q = q_now.copy()
            q[indices] = start + (goal - start) * (k / count)
            waypoints.append(q)
        if self.check_path:
            collision = self._first_collision(waypoints)
            if collision is not None:
                around = self._around(q_now, result.q, count)
                if around is None:
                    k, contact = collision
                    raise SkillAbort(
                        FailureKind.COLLISION,
                        f"move_to {self.label}: the joint-space path collides at {100 * (k + 1) // count}%: {contact}",
                        {"pair": list(contact.pair), "objects": [world.contact_object(n) for n in contact.pair],
                         "collision_kind": contact.kind, "penetration": contact.penetration,
                         "waypoint": k + 1, "waypoints": count, "target": self.info["target"],
                         "planner": self.info.get("planner")},
                    )
                waypoints, self.info["path"] = around
        self._waypoints = [q[indices] for q in waypoints]
        self.info["waypoints"] = len(waypoints)
        self.info["q_goal"] = rounded(goal)

    def _around(self, q_now: np.ndarray, q_goal: np.ndarray, count: int) -> tuple[list[np.ndarray], str] | None:
        """Waypoints that do not collide where the joint-space line does, and which way they go: the straight
        Cartesian line, a lift before the line, else a path planned around (:func:`plan_path`, to the same IK
        solution); ``None`` when none is free."""
        straight = self._straight_line(q_now, count)
        if straight is not None and self._first_collision(straight) is None:
            return straight, "cartesian"
        lifted = self._lift_first(q_now)
        if lifted is not None and self._first_collision(lifted) is None:
            return lifted, "lift_first"
        planned = self._planned(q_now, q_goal)
        return None if planned is None else (planned, "planned")

    def _planned(self, q_now: np.ndarray, q_goal: np.ndarray) -> list[np.ndarray] | None:
        """A path around what the straight lines hit, planned in the arm's joints (the other joints stay), then
        cut into waypoints one tick of joint speed apart."""
        world = self.world
        indices = world.kin.arm_indices(self.arm)

        def free(arm_q: np.ndarray) -> bool:
            q = q_now.copy()
            q[indices] = arm_q
            return self.world.collision.check(q, arm=self.arm, carried_clearance=self.carried_clearance) is None

        stats = PlanningStats()
        path = plan_path(free, q_now[indices], q_goal[indices], world.kin.lower[indices], world.kin.upper[indices],
                         seed=world.seed, stats=stats)
        self.info["planner"] = {"found": stats.found, "iterations": stats.iterations, "checks": stats.checks,
                                "nodes": stats.nodes}
        if path is None:
            return None
        max_step = self._max_step()
        out = []
        for a, b in itertools.pairwise(path):
            steps = max(1, math.ceil(float(np.max(np.abs(b - a))) / max_step))
            for k in range(1, steps + 1):
                q = q_now.copy()
                q[indices] = a + (b - a) * (k / steps)
                out.append(q)
        return out

    def _first_collision(self, waypoints: list[np.ndarray]) -> tuple[int, Any] | None:
        for k, q in enumerate(waypoints[:-1]):
            contact = self.world.collision.check(q, arm=self.arm, carried_clearance=self.carried_clearance)
            if contact is not None:
                return k, contact
        return None

    def _lift_first(self, q_now: np.ndarray, clearance: float = 0.06) -> list[np.ndarray] | None:
        """Waypoints rising straight up with the gripper's orientation kept (by ``clearance``, or to the target's
        height when that is higher), then along the joint-space line to the target: the second fallback, for a
        hand that would sweep its fingers through what it just let go of when it turns on the spot. ``None`` when
        the lift or the target has no IK solution."""
        world = self.world
        assert self.target is not None
        start = world.sim.link_transform(world.end_effector(self.arm))
        height = max(clearance, float(self.target[2, 3] - start[2, 3]))
        indices = world.kin.arm_indices(self.arm)
        out, q = [], q_now.copy()
        steps = max(1, math.ceil(height / 0.01))
        for k in range(1, steps + 1):
            pose = pin.SE3(start[:3, :3], start[:3, 3] + np.array([0.0, 0.0, height * k / steps]))
            result = world.ik.solve(self.arm, pose, q, seed=world.seed, check_collisions=False)
            if not result.success or result.q is None or float(np.max(np.abs(result.q[indices] - q[indices]))) > 0.5:
                return None
            q = result.q
            out.append(q.copy())
        result = world.ik.solve(self.arm, pin.SE3(self.target[:3, :3], self.target[:3, 3]), q, seed=world.seed)
        if not result.success or result.q is None:
            return None
        start_q, goal = q[indices], result.q[indices]
        count = max(1, math.ceil(float(np.max(np.abs(goal - start_q))) / self._max_step()))
        for k in range(1, count + 1):
            step = q.copy()
            step[indices] = start_q + (goal - start_q) * (k / count)
            out.append(step)
        return out

    def _straight_line(self, q_now: np.ndarray, count: int) -> list[np.ndarray] | None:
        """Waypoints moving the gripper frame along the straight line (and the shortest rotation) to the target,
        each solved by IK from the one before: the fallback when the joint-space path sweeps into something (an
        arm whose joint-space straight line bends sideways while a block goes down between two others). ``None``
        when a waypoint has no solution. Each waypoint is solved collision-aware: from the one before, the nearest
        solution may fold the arm into itself (the Panda over the re-orientation's set-down spot, link1 3.5 mm into
        link5 one centimetre down), which the path check rejects, and the fallback's planned path swept the open
        fingers 8 cm sideways through the part they were going down around."""
        world = self.world
        assert self.target is not None
        start = world.sim.link_transform(world.end_effector(self.arm))
        rotation = pin.log3(start[:3, :3].T @ self.target[:3, :3])
        steps = max(count, math.ceil(float(np.linalg.norm(self.target[:3, 3] - start[:3, 3])) / 0.01))
        indices = world.kin.arm_indices(self.arm)
        out, q = [], q_now.copy()
        for k in range(1, steps + 1):
            fraction = k / steps
            pose = pin.SE3(start[:3, :3] @ pin.exp3(rotation * fraction),
                           start[:3, 3] + (self.target[:3, 3] - start[:3, 3]) * fraction)
            result = world.ik.solve(self.arm, pose, q, seed=world.seed)
            if not result.success or result.q is None:
                return None
            if float(np.max(np.abs(result.q[indices] - q[indices]))) > 0.5:  # jumped to another arm configuration
                return None
            q = result.q
            out.append(q.copy())
        return out

    def _error(self) -> tuple[float, float]:
        assert self.target is not None
        current = self.world.sim.link_transform(self.world.end_effector(self.arm))
        position = float(np.linalg.norm(current[:3, 3] - self.target[:3, 3]))
        rotation = float(np.linalg.norm(pin.log3(self.target[:3, :3].T @ current[:3, :3])))
        return position, rotation

    def _arrived(self) -> bool:
        position, rotation = self._error()
        return position <= self.position_tolerance and rotation <= self.orientation_tolerance

    def _finish(self) -> str:
        world = self.world
        position, rotation = self._error()
        self.info["position_error"] = rounded(position, 5)
        self.info["orientation_error"] = rounded(rotation, 5)
        self.info["final_gripper"] = rounded(world.sim.gripper_pose(self.arm))
        if self._held_rel is not None:
            held = world.sim.held(self.arm)
            drift = math.inf if held is None else float(
                np.linalg.norm(world.held_relative(self.arm)[:3, 3] - self._held_rel[:3, 3]))
            grasped = None if held is None else getattr(world.sim, "grasped_relative", lambda _arm: None)(self.arm)
            if grasped is not None:  # pressed out of place at the start (a failed insertion), back in the grasp now
                drift = min(drift, float(np.linalg.norm(world.held_relative(self.arm)[:3, 3] - grasped[:3, 3])))
            if drift > 0.01:
                raise SkillAbort(FailureKind.PHYSICAL, f"move_to {self.label}: the held object was lost on the way",
                                 {"held": held, "drift": None if math.isinf(drift) else drift})
        if self.verify:
            self._verify()
        return SUCCESS

    def _verify(self, margin: float = 0.01) -> None:
        """Section 7.3: the subassembly moved to the staging pose must have left the table, every part of it."""
        sim = self.world.sim
        heights = {name: float(self.world.object_lowest(name) - sim.table.top_z) for name in self.verify}
        left = sorted(name for name, h in heights.items() if h < margin)
        # A part lifted only because it rests on (or leans in) what is held came along without being joined: the
        # subassembly is what the gripper holds and what is joined to it, transitively.
        held = sim.held(self.arm)
        assembly = _joined_to(held, sim.attachments()) if held is not None else set()
        loose = sorted(name for name in self.verify if name not in left and held is not None and name not in assembly)
        evidence: dict[str, Any] = {
            "lifted": {name: rounded(h, 4) for name, h in heights.items()},
            "left_on_table": left,
            "not_joined": loose,
            "attachments": [list(p) for p in sim.attachments()],
            "held": held,
        }
        roles = [n for n in self.verify if sim.object_model(n).role is not None]
        if len(roles) >= 2:
            relation = sim.attachment_relation(roles[0], roles[1])
            evidence["R_p"] = rounded(relation.distance, 5)
            evidence["R_n"] = rounded(relation.angle, 4)
        self.info["verification"] = evidence
        if left:
            raise SkillAbort(FailureKind.VERIFICATION,
                             f"move_to {self.label}: verification failed -- {', '.join(left)} stayed on the table "
                             "instead of coming along with the subassembly", evidence)
        if loose:
            raise SkillAbort(FailureKind.VERIFICATION,
                             f"move_to {self.label}: verification failed -- {', '.join(loose)} came along without "
                             f"being joined to the held {held} (it rests on the subassembly)", evidence)


def _joined_to(name: str, pairs: Any) -> set[str]:
    """``name`` and every object joined to it through ``pairs`` (magnetic attachments), transitively."""
    found, frontier = {name}, [name]
    links = [tuple(p) for p in pairs]
    while frontier:
        current = frontier.pop()
        for a, b in links:
            other = b if a == current else a if b == current else None
            if other is not None and other not in found:
                found.add(other)
                frontier.append(other)
    return found
