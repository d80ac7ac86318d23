"""What every simulated skill shares: tick counting, failures with a taxonomy kind, records for traces.

Offers:

* :class:`SimSkill` -- base class of the skills in this package: ``start(args, ctx)`` grounds the arguments and
  calls :meth:`SimSkill.begin`; ``tick()`` counts, calls :meth:`SimSkill.step` and turns a :class:`SkillAbort`
  into a FAILURE with its kind (a skill never raises out of ``tick`` for a physical or motion failure)
* :class:`PhasedSkill` -- a skill made of sub-skills run in order (a small state machine)
* :class:`SkillAbort` -- raised inside a skill to fail it with a kind, a message and evidence
* :class:`SkillWorld` -- the protocol of the world skills act on
* :func:`rounded` -- numbers rounded for records (JSON-able, short)
* :func:`holdings` -- what each arm holds and where (the evidence of every skill failure)
* :func:`off_workspace` -- the objects off the table's top (fallen off it, or out past its edges)

A skill started for a primitive (``start``) notes which objects are on the table when it starts; when it ends, an
object that was there and is not any more fails it as ``physical`` naming the object and where it went: the step
that threw a part off the table is the one that fails, not a later one that cannot reach it. Every failure's
evidence says what the robot still holds and where (``holding``).

Why the split between ``start`` and ``begin``: HTN primitives pass symbols (``b0``, ``1.5``, ``attach_pose``); a
skill used by another skill (Place uses MoveTo and Grasp) passes numbers. ``start`` grounds symbols through the
world, ``begin`` takes the ground values.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, Protocol

import numpy as np

from bt_meta.bt.failures import FailureKind
from bt_meta.errors import BtMetaError
from bt_meta.world.base import FAILURE, RUNNING, SUCCESS, SkillFailure

__all__ = ["PhasedSkill", "SimSkill", "SkillAbort", "SkillWorld", "rounded"]


class SkillWorld(Protocol):
    """What the skills use of the world they act on (the
    :class:`~bt_meta.world.simulation.sim_world.SimWorld` implements it): skills depend on this, not on the
    SimWorld module, which imports the skills' registry."""

    sim: Any
    kin: Any
    ik: Any
    collision: Any
    seed: int
    joint_speed: float
    tick_seconds: float
    steps_per_tick: int

    def end_effector(self, arm: str) -> str: ...
    def current_q(self) -> np.ndarray: ...
    def drive_arm(self, arm: str, values: np.ndarray) -> None: ...
    def advance(self, ticks: int = 1) -> None: ...
    def held_relative(self, arm: str) -> np.ndarray: ...
    def grasp(self, name: str, arm: str, reach: float) -> bool: ...
    def release(self, arm: str) -> str | None: ...
    def allow_hand(self, name: str, arm: str, allowed: bool = True, preshape: bool = True) -> None: ...
    def grasp_xy(self, name: str) -> tuple[float, float]: ...
    def grasp_height(self, name: str, arm: str, clearance: float) -> float: ...
    def allow_objects(self, name: str, others: Iterable[str]) -> None: ...
    def robot_contacts(self, arm: str) -> list[str]: ...
    def object_lowest(self, name: str) -> float: ...
    def object_top(self, name: str) -> float: ...
    def contact_object(self, name: str) -> str: ...
    def object_name(self, symbol: str) -> str: ...
    def feature_of(self, symbol: str) -> tuple[str, str | None]: ...
    def pose_spec(self, symbol: str) -> dict[str, Any]: ...
    def ground_pose(self, symbol: str, arm: str | None = None) -> np.ndarray: ...
    def ground_cell(self, frame: str, x: str, y: str) -> tuple[float, float, float]: ...
    def sync_collision(self) -> None: ...


class SkillAbort(BtMetaError):
    """Fail the running skill with a taxonomy ``kind``; caught by :meth:`SimSkill.tick`."""

    def __init__(self, kind: str | FailureKind, message: str, evidence: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.kind = FailureKind(kind).value
        self.message = message
        self.evidence = evidence or {}


WORKSPACE_DROP = 0.02
"""m: an object whose lowest point is this far below the table top has fallen off the table."""


def holdings(world: Any) -> dict[str, dict[str, Any]]:
    """``{arm: {"object": name, "pose": [x, y, z, roll, pitch, yaw]}}`` (base frame) of every arm holding something."""
    sim = getattr(world, "sim", None)
    if sim is None:
        return {}
    out = {}
    for arm in sim.robot.arms:
        name = sim.held(arm)
        if name is not None:
            out[arm] = {"object": name, "pose": rounded(sim.object_pose(name))}
    return out


def off_workspace(world: Any, names: Iterable[str] | None = None) -> dict[str, list[float]]:
    """``{object: position}`` of the objects (of ``names``, default all) not held and not on the table's top: their
    centre beyond its edges, or their lowest point :data:`WORKSPACE_DROP` below it."""
    sim = getattr(world, "sim", None)
    table = getattr(sim, "table", None)
    if sim is None or table is None:
        return {}
    (x0, x1), (y0, y1) = table.bounds
    held = {sim.held(arm) for arm in sim.robot.arms}
    out = {}
    for name in sim.object_names() if names is None else names:
        if name in held or name not in sim.object_names():
            continue
        t = sim.object_transform(name)
        x, y = float(t[0, 3]), float(t[1, 3])
        lowest = float((sim.object_model(name).points() @ t[:3, :3].T + t[:3, 3])[:, 2].min())
        if not (x0 <= x <= x1 and y0 <= y <= y1) or lowest < table.top_z - WORKSPACE_DROP:
            out[name] = rounded(t[:3, 3])
    return out


def rounded(values: Iterable[float] | float, digits: int = 4) -> Any:
    """Round a number or a sequence of numbers for a record."""
    if isinstance(values, (int, float)):
        return round(float(values), digits)
    return [round(float(v), digits) for v in values]


class SimSkill:
    """One execution of a skill on a :class:`~bt_meta.world.simulation.sim_world.SimWorld`, advanced tick by tick."""

    name = "skill"
    spec: dict[str, Any] = {}
    """The grounding file's entry for the primitive this skill runs (options such as ``frame`` or ``mode``)."""

    def __init__(self, world: SkillWorld, arm: str | None = None) -> None:
        self.world = world
        self.arm = arm or str(world.sim.robot.default_arm)  # none named: the robot's first arm (its YAML)
        self.failure: SkillFailure | None = None
        self.ticks = 0
        self.outcome: str | None = None
        self.args: tuple[str, ...] = ()
        self.info: dict[str, Any] = {}
        self._started = False
        self._watched: list[str] = []
        """Objects on the table when the primitive started (:meth:`start`): one leaving it fails the skill."""

    # -- protocol -----------------------------------------------------------------------------------------------

    def start(self, args: Sequence[str], ctx: Any = None) -> None:
        """Ground the primitive's symbolic arguments and begin."""
        self.args = tuple(str(a) for a in args)
        self._reset()
        sim = getattr(self.world, "sim", None)
        if sim is not None and hasattr(sim, "object_names"):
            away = off_workspace(self.world)
            self._watched = [n for n in sim.object_names() if n not in away]
            # where everything was when the step started: what a monitor compares the step's doing with
            self.world.step_start_poses = {n: [float(v) for v in sim.object_pose(n)] for n in sim.object_names()}
        try:
            self.ground(self.args)
        except SkillAbort as abort:
            self._abort(abort)

    def begin_ground(self) -> None:
        """Mark a skill begun with ground values (by another skill) as started."""
        self._reset()

    def tick(self) -> str:
        if self.outcome in (SUCCESS, FAILURE):
            return self.outcome
        self.ticks += 1
        try:
            status = self.step()
            if status != RUNNING:
                self._check_workspace()
        except SkillAbort as abort:
            try:
                self._check_workspace(abort)
            except SkillAbort as gone:
                abort = gone
            return self._abort(abort)
        if status != RUNNING:
            self.outcome = status
        return status

    def cancel(self) -> None:
        if self.outcome is None:
            self.outcome = "cancelled"

    def record(self) -> dict[str, Any]:
        out: dict[str, Any] = {"skill": self.name, "args": list(self.args), "ticks": self.ticks,
                               "outcome": self.outcome}
        out.update(self.info)
        if self.failure is not None:
            out["failure"] = {"kind": self.failure.kind, "message": self.failure.message}
        return out

    # -- for subclasses -----------------------------------------------------------------------------------------

    def ground(self, args: tuple[str, ...]) -> None:
        """Turn symbolic arguments into numbers and begin; raise :class:`SkillAbort` for bad ones."""
        raise NotImplementedError

    def step(self) -> str:
        """One tick of work: RUNNING, SUCCESS, or raise :class:`SkillAbort`."""
        raise NotImplementedError

    # -- helpers ------------------------------------------------------------------------------------------------

    def _reset(self) -> None:
        self.failure = None
        self.outcome = None
        self.ticks = 0
        self.info = {}

    def _check_workspace(self, abort: SkillAbort | None = None) -> None:
        """Raise ``physical`` when an object on the table at the start has left it (a failure of another kind
        that threw it off becomes ``physical``, the first failure kept in the evidence)."""
        if not self._watched or (abort is not None and abort.kind == FailureKind.PHYSICAL.value
                                 and "left_workspace" in abort.evidence):
            return
        gone = off_workspace(self.world, self._watched)
        if not gone:
            return
        self._watched = []
        evidence: dict[str, Any] = {"left_workspace": gone, "objects": sorted(gone)}
        if abort is not None:
            evidence["during"] = {"kind": abort.kind, "message": abort.message}
        where = "; ".join(f"{n} at {p}" for n, p in gone.items())
        raise SkillAbort(FailureKind.PHYSICAL, f"{self.name}: {', '.join(gone)} left the table ({where})", evidence)

    def _abort(self, abort: SkillAbort) -> str:
        abort.evidence.setdefault("holding", holdings(self.world))
        self.failure = SkillFailure(abort.kind, abort.message, dict(abort.evidence))
        self.outcome = FAILURE
        return FAILURE

    def run_child(self, child: SimSkill) -> str:
        """Tick a sub-skill once; its failure becomes this skill's (same kind, its evidence nested)."""
        status = child.tick()
        if status == FAILURE:
            failure = child.failure
            assert failure is not None
            evidence = dict(failure.evidence)
            evidence.setdefault("phase", child.record())
            raise SkillAbort(failure.kind, failure.message, evidence)
        return status


class PhasedSkill(SimSkill):
    """A skill made of sub-skills run one after another (Place, Insert): a small state machine.

    :meth:`phases` lists ``(name, make)`` pairs; ``make()`` is called when the phase begins (so targets come from
    the world as it is then) and returns a begun sub-skill, or ``None`` for a phase that only acts or checks.
    :meth:`finish` runs after the last phase.

    A ``reachability`` failure in one of :attr:`REACH_PHASES` (the moves to the object where it lies, before it is
    held) names that object in its evidence as ``out_of_reach``: the object cannot be picked up where it is, so a
    repair needs another one in its place (object substitution reads it), not another motion.
    """

    REACH_PHASES: tuple[str, ...] = ("approach", "descend")

    def phases(self) -> list[tuple[str, Any]]:
        raise NotImplementedError

    def reached_object(self) -> str | None:
        """The object the :attr:`REACH_PHASES` go to (the one picked up); ``None`` when there is none."""
        return None

    def finish(self) -> None:
        """Final checks after the last phase; raise :class:`SkillAbort` to fail."""

    def begin_phases(self) -> None:
        self._plan = self.phases()
        self._index = 0
        self._child: SimSkill | None = None
        self.info["phases"] = []

    def step(self) -> str:
        while True:
            if self._child is None:
                if self._index >= len(self._plan):
                    self.finish()
                    return SUCCESS
                name, make = self._plan[self._index]
                self.info["phase"] = name
                child = make()
                if child is None:
                    self.info["phases"].append({"phase": name})
                    self._index += 1
                    continue
                self._child = child
            try:
                status = self.run_child(self._child)
            except SkillAbort as abort:
                phase = self._plan[self._index][0]
                abort.evidence.setdefault("failed_phase", phase)
                if abort.kind == FailureKind.REACHABILITY.value and phase in self.REACH_PHASES \
                        and self.reached_object():
                    abort.evidence.setdefault("out_of_reach", self.reached_object())
                self.info["phases"].append({"phase": self._plan[self._index][0], **self._child.record()})
                raise
            if status == RUNNING:
                return RUNNING
            self.info["phases"].append({"phase": self._plan[self._index][0], **self._child.record()})
            self._child = None
            self._index += 1
            if self._index >= len(self._plan):
                self.finish()
                return SUCCESS
            return RUNNING
