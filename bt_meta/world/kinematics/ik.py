"""Inverse kinematics for one arm with mink, restarts, and collision-aware acceptance.

Offers:

* :class:`InverseKinematics` -- ``solve(arm, target, q_start=None, seed=None)`` -> :class:`IKResult`
* :class:`IKResult` -- success, full configuration, failure kind (``reachability`` or ``collision``), message,
  evidence, iterations, attempts, time
* :data:`REACHABILITY`, :data:`COLLISION` -- the failure kinds, named as in the failure taxonomy

How a solve goes: a frame task on the arm's end effector (or another frame the arm moves) and the joint limits
are handed to mink on a MuJoCo model of that arm; each step is one damped Gauss-Newton step (``dt = 1``). An
attempt stops when the pose is within tolerance, when the error stalls, or after ``max_iterations``. Attempts
start from ``q_start``, then from the home pose, then from seeded random configurations (the best of
``restart_samples`` draws, nearest the target). A converged solution is checked for collisions (robot against
itself and the scene, other joints as in ``q_start``): a colliding one is rejected and the search restarts; once
restarts have found ``escape_after`` colliding solutions, a colliding solution whose colliding link is not
carried rigidly by the hand is walked along the arm's self-motion (null space) to a collision-free one. Failure
is classified: ``collision`` if solutions were found but every one collided (naming the pair), ``reachability``
otherwise (with the target and the best residual reached).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import daqp
import mink
import mujoco
import numpy as np
import pinocchio as pin

from bt_meta.errors import KinematicsError
from bt_meta.world.kinematics.collision import CollisionChecker, Contact, Pose, as_se3
from bt_meta.world.kinematics.forward import Kinematics
from bt_meta.world.kinematics.mujoco_model import MujocoModel, build_mujoco_model
from bt_meta.world.robot.description import IKSettings

__all__ = ["COLLISION", "REACHABILITY", "IKResult", "InverseKinematics"]

_SOLVE_DAMPING = 1e-12  # mink.solve_ik's default Tikhonov term: keeps H positive definite

REACHABILITY = "reachability"
COLLISION = "collision"


@dataclass
class IKResult:
    success: bool
    q: np.ndarray | None
    """The full configuration (Pinocchio order): the arm's joints solved, the others as in ``q_start``."""
    kind: str | None
    """None on success; ``reachability`` or ``collision`` on failure."""
    message: str
    evidence: dict[str, Any] = field(default_factory=dict)
    iterations: int = 0
    attempts: int = 0
    time: float = 0.0
    """Wall-clock seconds spent in :meth:`InverseKinematics.solve`."""
    position_error: float = float("inf")
    orientation_error: float = float("inf")


@dataclass
class _ArmSolver:
    """The per-arm mink state, built once and reused for every solve."""

    mj: MujocoModel
    configuration: mink.Configuration
    limits: list[mink.ConfigurationLimit]
    lower: np.ndarray
    upper: np.ndarray
    tasks: dict[str, tuple[mink.FrameTask, int]]
    reach: dict[str, tuple[np.ndarray, float]]
    damping: np.ndarray
    """``_SOLVE_DAMPING`` times the identity."""
    no_constraints: np.ndarray
    sense: np.ndarray
    gain: float
    upper_step: np.ndarray
    lower_step: np.ndarray


class InverseKinematics:
    """IK for any arm of a robot; collision-aware when given a :class:`CollisionChecker`."""

    def __init__(
        self,
        kinematics: Kinematics,
        collision: CollisionChecker | None = None,
        settings: IKSettings | None = None,
    ) -> None:
        self.kinematics = kinematics
        self.collision = collision
        self.settings = settings or kinematics.robot.ik
        self._arms: dict[str, _ArmSolver] = {}
        self._rigid: dict[tuple[str, str], frozenset[str]] = {}

    def _arm(self, arm: str) -> _ArmSolver:
        solver = self._arms.get(arm)
        if solver is None:
            mj = build_mujoco_model(self.kinematics, arm)
            configuration = mink.Configuration(mj.model)
            limits = [mink.ConfigurationLimit(mj.model)]
            idx = mj.pin_indices
            n = mj.model.nv
            solver = _ArmSolver(
                mj,
                configuration,
                limits,
                self.kinematics.lower[idx],
                self.kinematics.upper[idx],
                {},
                {},
                _SOLVE_DAMPING * np.eye(n),
                np.zeros((0, n)),
                np.zeros(n, dtype=np.intc),
                limits[0].gain,
                np.zeros(n),
                np.zeros(n),
            )
            self._arms[arm] = solver
        return solver

    def _task(self, solver: _ArmSolver, arm: str, frame: str) -> tuple[mink.FrameTask, int]:
        """The frame task for ``frame`` and its MuJoCo body (made once per frame)."""
        entry = solver.tasks.get(frame)
        if entry is None:
            self.kinematics.frame_id(frame)  # unknown frames fail here with the usual message
            body = mujoco.mj_name2id(solver.mj.model, mujoco.mjtObj.mjOBJ_BODY, frame)
            if body < 0:
                raise KinematicsError(f"frame {frame!r} is not a link; IK targets must be links")
            if not _moved_by(solver.mj.model, body):
                raise KinematicsError(f"frame {frame!r} is not moved by arm {arm!r}")
            task = mink.FrameTask(
                frame,
                "body",
                position_cost=1.0,
                orientation_cost=self.settings.orientation_cost,
                gain=1.0,
                lm_damping=self.settings.lm_damping,
            )
            entry = (task, body)
            solver.tasks[frame] = entry
            solver.reach[frame] = self._reach(arm, frame)
        return entry

    def _rigid_links(self, arm: str, frame: str) -> frozenset[str]:
        key = (arm, frame)
        links = self._rigid.get(key)
        if links is None:
            links = _links_moving_with(self.kinematics, frame, self.kinematics.robot.arm(arm).joints)
            self._rigid[key] = links
        return links

    def _reach(self, arm: str, frame: str) -> tuple[np.ndarray, float]:
        """(position of the arm's first joint, an upper bound on its distance to ``frame``).

        The bound is the sum of the link offsets along the chain; a target farther than that is out of reach
        whatever the joints do, so it is reported at once instead of after every restart.
        """
        kin = self.kinematics
        model = kin.model
        first = model.getJointId(kin.robot.arm(arm).joints[0])
        fid = kin.frame_id(frame)
        reach = float(np.linalg.norm(model.frames[fid].placement.translation))
        joint = model.frames[fid].parentJoint
        while joint != first and joint > 0:
            reach += float(np.linalg.norm(model.jointPlacements[joint].translation))
            joint = model.parents[joint]
        data = model.createData()
        pin.forwardKinematics(model, data, kin.home)
        return np.array(data.oMi[first].translation), reach

    def _step(self, solver: _ArmSolver, task: mink.FrameTask) -> np.ndarray | None:
        """One IK step: the same QP as ``mink.solve_ik(configuration, [task], dt=1, limits=[ConfigurationLimit])``.

        mink's frame task gives the objective (error, Jacobian, Levenberg-Marquardt damping); the configuration
        limit of every (hinge or slide) joint is a box on the step, ``gain * (limit - q)``, which DAQP takes as
        simple bounds. Calling DAQP directly skips qpsolvers' problem conversion: ~25 us per step instead of ~90.
        """
        H, c = task.compute_qp_objective(solver.configuration)
        H += solver.damping  # a fresh array from mink: safe to change in place
        q = solver.configuration.data.qpos
        upper = np.subtract(solver.upper, q, out=solver.upper_step)
        upper *= solver.gain
        lower = np.subtract(solver.lower, q, out=solver.lower_step)
        lower *= solver.gain
        x, _, exitflag, _ = daqp.solve(H, c, solver.no_constraints, upper, lower, solver.sense)
        if exitflag <= 0:
            return None
        return np.asarray(x)

    def _random_start(
        self,
        solver: _ArmSolver,
        body: int,
        target: pin.SE3,
        rng: np.random.Generator,
        collision_free_in: np.ndarray | None = None,
    ) -> None:
        """Put the configuration at the best of ``restart_samples`` uniform draws: the one nearest the target.

        Scoring a draw is one forward kinematics pass (a few microseconds), far cheaper than the IK steps a bad
        start wastes before it stalls. After solutions were rejected for collisions, ``collision_free_in`` (the
        full configuration the arm joints go into) makes the best collision-free draw win instead: IK tends to
        converge to a solution near its start, and the nearest draws had led into collisions.
        """
        configuration = solver.configuration
        data = configuration.data
        model = configuration.model
        count = self.settings.restart_samples
        samples = rng.uniform(solver.lower, solver.upper, size=(count, len(solver.lower)))
        positions = np.empty((count, 3))
        rotations = np.empty((count, 9))
        for i, sample in enumerate(samples):
            data.qpos[:] = sample
            mujoco.mj_kinematics(model, data)
            positions[i] = data.xpos[body]
            rotations[i] = data.xmat[body]
        cosines = np.clip((rotations @ target.rotation.ravel() - 1.0) / 2.0, -1.0, 1.0)
        offsets = positions - target.translation
        scores = np.sqrt(np.einsum("ij,ij->i", offsets, offsets)) + self.settings.orientation_cost * np.arccos(cosines)
        order = np.argsort(scores, kind="stable")
        best = samples[order[0]]
        if collision_free_in is not None and self.collision is not None:
            for i in order:
                if self.collision.check(solver.mj.to_pinocchio(samples[i], collision_free_in)) is None:
                    best = samples[i]
                    break
        configuration.update(best)

    def mink_step(self, arm: str, frame: str | None = None) -> np.ndarray:
        """The step ``mink.solve_ik`` computes at the arm's current configuration (to check :meth:`_step`)."""
        solver = self._arm(arm)
        task, _ = self._task(solver, arm, frame or self.kinematics.end_effector(arm))
        return mink.solve_ik(solver.configuration, [task], 1.0, "daqp", damping=_SOLVE_DAMPING, limits=solver.limits)

    def solve(
        self,
        arm: str,
        target: Pose,
        q_start: np.ndarray | None = None,
        *,
        seed: int | None = None,
        frame: str | None = None,
        check_collisions: bool = True,
        carried_clearance: float = 0.0,
    ) -> IKResult:
        """Joint values putting ``frame`` (default the arm's end effector) at ``target`` in the base frame; its
        collision check keeps a carried object ``carried_clearance`` from other objects
        (:meth:`~bt_meta.world.kinematics.collision.CollisionChecker.check`)."""
        started = time.perf_counter()
        kin = self.kinematics
        frame = frame or kin.end_effector(arm)
        solver = self._arm(arm)
        task, body = self._task(solver, arm, frame)
        base = kin.home.copy() if q_start is None else kin.check_q(q_start).copy()
        run = _Run(self, arm, solver, task, body, frame, as_se3(target), base, seed, check_collisions,
                   carried_clearance)
        result = run.solve()
        result.time = time.perf_counter() - started
        return result


class _Run:
    """One IK solve: attempts from several starts, each converged solution checked, failures classified."""

    def __init__(
        self,
        ik: InverseKinematics,
        arm: str,
        solver: _ArmSolver,
        task: mink.FrameTask,
        body: int,
        frame: str,
        target: pin.SE3,
        base: np.ndarray,
        seed: int | None,
        check_collisions: bool,
        carried_clearance: float = 0.0,
    ) -> None:
        self.ik = ik
        self.carried_clearance = carried_clearance
        self.arm = arm
        self.settings = ik.settings
        self.solver = solver
        self.task = task
        self.body = body
        self.frame = frame
        self.target = target
        self.target_frame = ik.kinematics.robot.base_frame
        """The frame the target is given in: the robot's base frame (failures say so)."""
        self.base = base
        self.seed = ik.settings.seed if seed is None else seed
        self.collision = ik.collision if check_collisions else None
        quaternion = pin.Quaternion(target.rotation)
        task.set_target(
            mink.SE3(np.array([quaternion.w, quaternion.x, quaternion.y, quaternion.z, *target.translation]))
        )
        self.target_rotation_t = target.rotation.T
        self.target_position = target.translation.copy()
        self.data = solver.configuration.data
        self.iterations = 0
        self.best: tuple[float, float, float, np.ndarray | None] = (np.inf, np.inf, np.inf, None)
        self.colliding: list[tuple[Contact, np.ndarray]] = []
        self.escapes_tried = 0
        self.rigid_links = ik._rigid_links(arm, frame)

    def residual(self) -> tuple[float, float]:
        """(position error, orientation error) of the frame at the current configuration."""
        offset = self.data.xpos[self.body] - self.target_position
        axis = pin.log3(self.target_rotation_t @ self.data.xmat[self.body].reshape(3, 3))
        return math.sqrt(offset @ offset), math.sqrt(axis @ axis)

    def converge(self, max_steps: int, stall: bool) -> bool:
        """Iterate from the current configuration until within tolerance (True), a stall, or ``max_steps``."""
        settings = self.settings
        tol_p, tol_r = settings.position_tolerance, settings.orientation_tolerance
        history: list[float] = []
        window = settings.stall_iterations
        for step in range(max_steps + 1):
            position, rotation = self.residual()
            score = max(position / tol_p, rotation / tol_r)
            if score < self.best[0]:
                self.best = (score, position, rotation, self.data.qpos.copy())
            if position <= tol_p and rotation <= tol_r:
                return True
            if step == max_steps:
                return False
            history.append(score)
            if stall and len(history) > window and history[-1] > settings.stall_ratio * history[-1 - window]:
                return False
            delta = self.ik._step(self.solver, self.task)
            if delta is None:
                return False
            self.solver.configuration.integrate_inplace(delta, 1.0)
            self.iterations += 1
        return False  # pragma: no cover - the loop returns at step == max_steps

    def check(self) -> tuple[np.ndarray, Contact | None]:
        """The full configuration of the current (converged) arm configuration, and its first collision."""
        q = self.solver.mj.to_pinocchio(self.data.qpos, self.base)
        return q, (self.collision.check(q, carried_clearance=self.carried_clearance)
                   if self.collision is not None else None)

    def escape(self, contact: Contact) -> np.ndarray | None:
        """Slide along the arm's self-motion (the null space of the frame's Jacobian) out of a collision.

        A 7-joint arm reaching a 6-D pose keeps one degree of freedom: the elbow can swing while the hand stays.
        When the colliding link is not carried rigidly with the hand, walking that way (re-converging on the
        target after each step) often finds a collision-free solution that random restarts keep missing (e.g.
        an elbow in the head's collision sphere for targets just in front of the face).
        """
        settings = self.settings
        if contact.first in self.rigid_links or contact.second in self.rigid_links:
            return None
        if len(self.colliding) < settings.escape_after or self.escapes_tried >= settings.escape_tries:
            return None  # restarts first: they usually find a collision-free solution faster
        self.escapes_tried += 1
        configuration = self.solver.configuration
        start = self.data.qpos.copy()
        for direction in (1.0, -1.0):
            configuration.update(start)
            previous: np.ndarray | None = None
            for _ in range(settings.escape_steps):
                jacobian = configuration.get_frame_jacobian(self.frame, "body")
                null = np.linalg.svd(jacobian)[2][-1]
                if previous is None:
                    null = direction * null
                elif null @ previous < 0:
                    null = -null
                previous = null
                moved = np.clip(self.data.qpos + settings.escape_step_size * null, self.solver.lower, self.solver.upper)
                configuration.update(moved)
                if not self.converge(settings.escape_converge_steps, stall=False):
                    break  # left the self-motion manifold (a joint limit or a singularity)
                q, found = self.check()
                if found is None:
                    return q
        return None

    def solve(self) -> IKResult:
        settings = self.settings
        kin = self.ik.kinematics
        solver = self.solver
        mj = solver.mj
        shoulder, reach = solver.reach[self.frame]
        distance = float(np.linalg.norm(self.target.translation - shoulder))
        if distance > reach + settings.position_tolerance:
            return self.out_of_reach(distance, reach)
        starts = [np.clip(mj.to_mujoco(self.base), solver.lower, solver.upper)]
        home = np.clip(mj.to_mujoco(kin.home), solver.lower, solver.upper)
        if not np.array_equal(home, starts[0]):
            starts.append(home)
        rng: np.random.Generator | None = None  # made on the first random restart: most solves never need it
        attempt = 0
        for attempt in range(1, settings.max_attempts + 1):
            if attempt <= len(starts):
                solver.configuration.update(starts[attempt - 1])
            else:
                if rng is None:
                    rng = np.random.default_rng(self.seed)
                avoid = self.base if self.colliding else None
                self.ik._random_start(solver, self.body, self.target, rng, avoid)
            if not self.converge(settings.max_iterations, stall=True):
                continue
            q, contact = self.check()
            escaped = False
            if contact is not None:
                self.colliding.append((contact, q))
                free = self.escape(contact)
                if free is None:
                    if len(self.colliding) >= settings.max_colliding_solutions:
                        break
                    continue
                q, escaped = free, True
            position, rotation = self.residual()
            return IKResult(
                True,
                q,
                None,
                f"solved {self.arm} arm IK for {self.frame} in {attempt} attempt(s)",
                {
                    "frame": self.frame,
                    "attempt": attempt,
                    "rejected_colliding": len(self.colliding) - int(escaped),
                    "escaped_collision": escaped,
                },
                self.iterations,
                attempt,
                0.0,
                position,
                rotation,
            )
        return self.failure(attempt)

    def out_of_reach(self, distance: float, reach: float) -> IKResult:
        target_xyz = [round(float(v), 6) for v in self.target.translation]
        return IKResult(
            False,
            None,
            REACHABILITY,
            f"no IK solution for {self.frame} at {target_xyz} (base frame {self.target_frame}): {distance:.3f} m "
            f"from the {self.arm} arm's first "
            f"joint, beyond its reach of {reach:.3f} m",
            {
                "frame": self.frame,
                "target_xyz": target_xyz,
                "target_frame": self.target_frame,
                "target_rpy": [round(float(v), 6) for v in pin.rpy.matrixToRpy(self.target.rotation)],
                "distance": distance,
                "reach": reach,
                "best_position_error": distance - reach,
                "tolerance": [self.settings.position_tolerance, self.settings.orientation_tolerance],
            },
            0,
            0,
            0.0,
            distance - reach,
        )

    def failure(self, attempts: int) -> IKResult:
        target_xyz = [round(float(v), 6) for v in self.target.translation]
        target_rpy = [round(float(v), 6) for v in pin.rpy.matrixToRpy(self.target.rotation)]
        frame = self.frame
        if self.colliding:
            contact, q = self.colliding[0]
            return IKResult(
                False,
                None,
                COLLISION,
                f"every IK solution for {frame} at {target_xyz} (base frame {self.target_frame}) collides: {contact}",
                {
                    "frame": frame,
                    "target_xyz": target_xyz,
                "target_frame": self.target_frame,
                    "target_rpy": target_rpy,
                    "pair": list(contact.pair),
                    "collision_kind": contact.kind,
                    "penetration": contact.penetration,
                    "colliding_solutions": len(self.colliding),
                    "escapes_tried": self.escapes_tried,
                    "pairs": sorted({" <-> ".join(c.pair) for c, _ in self.colliding}),
                    "q": [float(v) for v in q],
                },
                self.iterations,
                attempts,
            )
        _, position, rotation, qpos = self.best
        return IKResult(
            False,
            None,
            REACHABILITY,
            f"no IK solution for {frame} at {target_xyz} rpy {target_rpy} (base frame {self.target_frame}) after "
            f"{attempts} attempts; "
            f"best residual {position * 1000:.2f} mm, {rotation:.4f} rad",
            {
                "frame": frame,
                "target_xyz": target_xyz,
                "target_frame": self.target_frame,
                "target_rpy": target_rpy,
                "best_position_error": position,
                "best_orientation_error": rotation,
                "best_q": [float(v) for v in self.solver.mj.to_pinocchio(qpos, self.base)]
                if qpos is not None
                else None,
                "tolerance": [self.settings.position_tolerance, self.settings.orientation_tolerance],
            },
            self.iterations,
            attempts,
            0.0,
            position,
            rotation,
        )


def _links_moving_with(kinematics: Kinematics, frame: str, arm_joints: tuple[str, ...]) -> frozenset[str]:
    """Links that move rigidly with ``frame`` whatever the arm's joints do (hand, gripper base, fingers).

    No self-motion can take them out of a collision, so an escape is not tried for them.
    """
    model = kinematics.model
    joint = model.frames[kinematics.frame_id(frame)].parentJoint
    arm_ids = {model.getJointId(name) for name in arm_joints}
    rigid = set()
    for j in range(model.njoints):
        support = list(model.supports[j])
        if joint in support and not set(support[support.index(joint) + 1 :]) & arm_ids:
            rigid.add(j)
    return frozenset(f.name for f in model.frames if f.parentJoint in rigid)


def _moved_by(model: mujoco.MjModel, body: int) -> bool:
    """Whether any joint of the (arm) model lies between the world and ``body``."""
    while body > 0:
        if model.body_jntnum[body] > 0:
            return True
        body = model.body_parentid[body]
    return False
