"""Keypoint expectations (paper, section 7.4): R_p and R_n of the attached objects, as in the last N traces.

For a monitored step the episodic memory gives the object states after the same step in the last N successful
traces (:mod:`bt_meta.perception.recall`). For each (active, reference) pair the expectation is the mean of
``R_p = |AP(active) - AP(reference)|`` and ``R_n = arccos(AN(active) . AN(reference))`` over those traces
(:mod:`bt_meta.perception.keypoints`); the observation is the same relation of the observed object states
(``observations["objects"]``, from ground-truth perception). A relation further than its tolerance from its mean
is a mismatch (suggested kind ``unexpected_configuration``: known objects in an unseen configuration).

Which pairs: the ``pairs`` setting when given; else, when the remembered states hold exactly two objects, that
pair (R_p and R_n are symmetric, so the order does not matter); else the first two arguments of the problem's
root task, mapped to world object names through ``world.object_name`` when the world has it.

Only informative relations are checked (section 7.4: R_p at the end of the attach, R_n for gross pose changes).
R_p is checked where the traces bring the attachment points together -- mean plus spread within
``contact_distance`` (3 cm) -- because before the parts meet R_p only measures where they happen to lie on the
table: a part or board shifted a few centimetres would be a false alarm. R_n is checked where the traces agree
on it (spread within ``angle_tolerance``); both relations are invariant to moving or turning the scene as a whole.
An expectation with neither relation informative is not made. ``data["checked"]`` names the relations checked.

``check="task_end"`` (default) checks only after the last primitive of each task (the task's bubbled-up
expectation, section 6.2), which is where the paper compares; ``check="all"`` checks after every step the memory
knows. Not the default because a variant pose differs from the traces from step 0 on, before any pose-setting step
ran that pose backtracking (section 7.4) could go back to.

Every object a step moved in the traces (carried, lifted, turned, knocked: :func:`~bt_meta.memory.recorder.
moved_objects`), named by the step or not, gets an orientation expectation too (``data["check"] ==
"orientation"``, after every step, not only at a task's end): which way its base faces (its z axis) and, for a
shape whose heading shows (:func:`~bt_meta.world.symmetry.heading_matters`), its heading about the vertical, up to
its yaw period, must be as a remembered trace left them -- either where that trace's step left them, or changed
as that trace's step changed them (from where the world says the object was when the step started,
``world.step_start_poses``): a part lifted where it lay keeps its own heading, a part carried to an absolute
pose takes the demonstrated one. A part that twisted in the fingers, landed on another face, or went missing
fails both; the suggested kind is ``unexpected_configuration``.

Offers:

* :class:`KeypointExpectations` -- the plugin as an object (memory, N, pairs, tolerances, check)
* :func:`bt_meta_expectations`, :func:`bt_meta_compare` -- the module-level plugin (see :func:`configure`)
* :data:`KIND` -- ``"keypoint"``
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bt_meta.bt.expectations import Comparison, Expectation
from bt_meta.bt.failures import FailureKind
from bt_meta.memory.recorder import moved_objects
from bt_meta.perception.keypoints import (
    CONTACT_DISTANCE,
    KeypointError,
    KeypointExpectation,
    expected_relation,
    informative,
    judge,
    pairs_from_states,
    relation,
)
from bt_meta.perception.recall import memory_for, remember, root_task
from bt_meta.plugins import ConfiguredPlugin, hookimpl
from bt_meta.world.symmetry import yaw_period

KIND = "keypoint"
CHECKS = ("all", "task_end")


class KeypointExpectations:
    """R_p/R_n expectations from the last ``n`` successful traces.

    ``position_tolerance`` (m) and ``angle_tolerance`` (rad) bound ``|R - mean|``; ``None`` switches a relation
    off. Defaults: the simulator's attach rule, 1 cm and 15 degrees. ``contact_distance`` (m): R_p is checked only
    where the traces' R_p (mean plus spread) is within it; ``None`` checks it everywhere.
    """

    def __init__(
        self,
        memory: Any = None,
        *,
        n: int = 5,
        pairs: Sequence[tuple[str, str]] | None = None,
        position_tolerance: float | None = 0.01,
        angle_tolerance: float | None = math.radians(15.0),
        check: str = "task_end",
        contact_distance: float | None = CONTACT_DISTANCE,
        watch_moved: bool = True,
        face_tolerance: float = math.radians(30.0),
        heading_tolerance: float = math.radians(20.0),
    ) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        if check not in CHECKS:
            raise ValueError(f"check must be one of {', '.join(CHECKS)}, got {check!r}")
        for name, value in (("position_tolerance", position_tolerance), ("angle_tolerance", angle_tolerance),
                            ("contact_distance", contact_distance)):
            if value is not None and value < 0:
                raise ValueError(f"{name} must be >= 0 or None, got {value}")
        self.memory = memory
        self.n = n
        self.pairs = None if pairs is None else [tuple(p) for p in pairs]
        self.position_tolerance = position_tolerance
        self.angle_tolerance = angle_tolerance
        self.check = check
        self.contact_distance = contact_distance
        self.watch_moved = watch_moved
        """Orientation expectations for every object a step moved (see the module docstring)."""
        self.face_tolerance = face_tolerance
        self.heading_tolerance = heading_tolerance

    def informative(self, expected: KeypointExpectation) -> tuple[float | None, float | None]:
        """The (position, angle) tolerances to check for ``expected`` (see ``keypoints.informative``)."""
        return informative(expected, position_tolerance=self.position_tolerance,
                           angle_tolerance=self.angle_tolerance, contact_distance=self.contact_distance)

    def _pairs(self, context: Any, states: list[Any]) -> list[tuple[str, str]]:
        if self.pairs is not None:
            return self.pairs  # type: ignore[return-value]
        names = {tuple(sorted(o.name for o in state.objects)) for state in states}
        if len(names) == 1:
            only = next(iter(names))
            if len(only) == 2:
                return [(only[0], only[1])]
        run = getattr(context, "run", None)
        tasks = getattr(getattr(run, "problem", None), "tasks", None) or []
        world = getattr(context, "world", None)
        to_world = getattr(world, "object_name", None)
        pairs = []
        for task in tasks[:1]:
            if len(task) >= 3:
                a, r = str(task[1]), str(task[2])
                if to_world is not None:
                    with contextlib.suppress(Exception):  # a symbol the world does not ground: keep it
                        a, r = to_world(a), to_world(r)
                pairs.append((a, r))
        return pairs

    @hookimpl
    def bt_meta_expectations(self, context: Any) -> list[Expectation] | None:
        memory = memory_for(context, self.memory)
        if memory is None:
            return None
        call = f"{context.action}({', '.join(str(a) for a in context.args)})"
        expectations = self._orientations(memory, context, call) if self.watch_moved else []
        remembered = remember(memory, context, self.n)
        if remembered is None or (self.check == "task_end" and not remembered.task_end):
            return expectations or None
        states = remembered.states
        for active, reference in self._pairs(context, states):
            pairs = pairs_from_states(states, active, reference)
            if not pairs:
                continue
            expected = expected_relation(pairs)
            position_tolerance, angle_tolerance = self.informative(expected)
            if position_tolerance is None and angle_tolerance is None:
                continue
            expectations.append(Expectation(
                kind=KIND,
                description=f"R_p/R_n of {active} and {reference} after {call} "
                            f"(means over {expected.n} trace(s))",
                data={
                    "active": active,
                    "reference": reference,
                    "expected": expected.as_dict(),
                    "position_tolerance": position_tolerance,
                    "angle_tolerance": angle_tolerance,
                    "checked": [r for r, t in (("r_p", position_tolerance), ("r_n", angle_tolerance))
                                if t is not None],
                    "parent_task": remembered.parent_task,
                    "task_end": remembered.task_end,
                    "matched_by": remembered.key,
                },
                failure_kind=FailureKind.UNEXPECTED_CONFIGURATION,
            ))
        return expectations or None

    def _orientations(self, memory: Any, context: Any, call: str) -> list[Expectation]:
        """One orientation expectation per object every remembered trace's step moved (module docstring)."""
        action, args = context.action, [str(a) for a in context.args]
        task, step = root_task(context), getattr(context, "step", None)
        records = []
        if task is not None and step is not None:
            records = [r for r in memory.expected_states(task, step, last=self.n, with_before=True)
                       if r.step.action == action and list(r.step.args) == args]
        if not records:
            records = memory.successful_states(action, args=args, last=self.n)
        records = [r for r in records if r.before is not None]
        if not records:
            return []
        moved = set.intersection(*(set(moved_objects(r.before.objects, r.step.state.objects)) for r in records))
        world = getattr(context, "world", None)
        sim = getattr(world, "sim", None)
        started = getattr(world, "step_start_poses", None) or {}
        out = []
        for name in sorted(moved):
            traces = []
            for record in records:
                before = {o.name: o.pose for o in record.before.objects}[name]
                after = {o.name: o.pose for o in record.step.state.objects}[name]
                traces.append({"episode": record.episode_id, "before": list(before), "after": list(after)})
            period = 2.0 * math.pi
            if sim is not None and name in sim.object_names():
                period = yaw_period(sim.object_model(name))
            out.append(Expectation(
                kind=KIND,
                description=f"orientation of {name} after {call} as in {len(traces)} remembered trace(s)",
                data={"check": "orientation", "object": name, "traces": traces, "period": period,
                      "started": None if name not in started else list(started[name]),
                      "face_tolerance": self.face_tolerance, "heading_tolerance": self.heading_tolerance},
                failure_kind=FailureKind.UNEXPECTED_CONFIGURATION,
            ))
        return out

    @hookimpl
    def bt_meta_observation_needs(self, context: Any) -> list[str] | None:
        """The object states (the keypoints are computed from them)."""
        return ["objects"]

    @hookimpl
    def bt_meta_compare(self, expectation: Expectation, observations: dict[str, Any], context: Any
                        ) -> Comparison | None:
        return compare(expectation, observations)


def _rotation(rpy: Sequence[float]) -> np.ndarray:
    from bt_meta.world.poses import pose_to_matrix

    return pose_to_matrix((0.0, 0.0, 0.0, *(float(v) for v in rpy)))[:3, :3]


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, float(a @ b))))


def _yaw(rotation: np.ndarray) -> float:
    return math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))


def _off(angle: float, period: float) -> float:
    """|angle| folded into the period (the smallest turn equivalent to it)."""
    return abs(angle - period * round(angle / period))


def _upright(rotation: np.ndarray) -> bool:
    return abs(float(rotation[2, 2])) >= math.cos(math.radians(30.0))


def _orientation_verdict(trace: dict[str, Any], seen: np.ndarray, started: np.ndarray | None,
                         data: dict[str, Any]) -> dict[str, Any]:
    """How the observed orientation ``seen`` compares with one trace: face and heading, each as the trace left
    them (absolute) or changed as the trace's step changed them from ``started`` (relative)."""
    after, before = _rotation(trace["after"][3:]), _rotation(trace["before"][3:])
    face = _angle(seen[:, 2], after[:, 2])
    if started is not None:
        face = min(face, _angle(seen[:, 2], (after @ before.T) @ started[:, 2]))
    out: dict[str, Any] = {"episode": trace["episode"], "face_deg": round(math.degrees(face), 1), "heading_deg": None}
    heading_ok = True
    period = float(data["period"])
    if period > 2.0 * float(data["heading_tolerance"]) and _upright(seen) and _upright(after):
        heading = _off(_yaw(seen) - _yaw(after), period)
        if started is not None and _upright(started) and _upright(before):
            heading = min(heading, _off((_yaw(seen) - _yaw(started)) - (_yaw(after) - _yaw(before)), period))
        out["heading_deg"] = round(math.degrees(heading), 1)
        heading_ok = heading <= float(data["heading_tolerance"])
    out["matched"] = face <= float(data["face_tolerance"]) and heading_ok
    return out


def _compare_orientation(expectation: Expectation, objects: dict[str, Any]) -> Comparison:
    data = expectation.data
    name = data["object"]
    state = objects.get(name)
    pose = state.get("pose") if isinstance(state, dict) else getattr(state, "pose", None)
    if pose is None:
        return Comparison(matched=False, message=f"{expectation.description}: {name} not observed",
                          evidence={"missing": [name], "object": name})
    seen = _rotation(pose[3:])
    started = None if data.get("started") is None else _rotation(data["started"][3:])
    verdicts = [_orientation_verdict(trace, seen, started, data) for trace in data["traces"]]
    evidence = {"object": name, "traces": verdicts,
                "face_tolerance_deg": round(math.degrees(data["face_tolerance"]), 1),
                "heading_tolerance_deg": round(math.degrees(data["heading_tolerance"]), 1),
                "period_deg": round(math.degrees(data["period"]), 2), "objects": [name]}
    if any(v["matched"] for v in verdicts):
        return Comparison(matched=True, evidence=evidence)
    best = min(verdicts, key=lambda v: (v["face_deg"], v["heading_deg"] or 0.0))
    parts = [f"its base faces {best['face_deg']:.0f} degrees off"]
    if best["heading_deg"] is not None:
        parts.append(f"its heading is {best['heading_deg']:.0f} degrees off")
    return Comparison(matched=False, evidence=evidence,
                      message=f"{expectation.description}: {', '.join(parts)} (as left, or as changed, by the step "
                              "in the nearest trace)")


def compare(expectation: Expectation, observations: dict[str, Any]) -> Comparison | None:
    """Compare a ``"keypoint"`` expectation with ``observations["objects"]`` (``None`` without object states)."""
    if expectation.kind != KIND:
        return None
    objects = observations.get("objects")
    if objects is None:
        return None
    if expectation.data.get("check") == "orientation":
        return _compare_orientation(expectation, objects)
    data = expectation.data
    active, reference = data["active"], data["reference"]
    missing = [name for name in (active, reference) if name not in objects]
    if missing:
        return Comparison(
            matched=False,
            message=f"{expectation.description}: {', '.join(missing)} not observed",
            evidence={"missing": missing},
        )
    try:
        observed = relation(objects[active], objects[reference])
    except KeypointError as error:
        return Comparison(matched=False, message=f"{expectation.description}: {error}",
                          evidence={"error": str(error)})
    expected = KeypointExpectation.from_dict(data["expected"])
    verdict = judge(observed, expected, position_tolerance=data["position_tolerance"],
                    angle_tolerance=data["angle_tolerance"])
    evidence = {**verdict.as_dict(), "active": active, "reference": reference,
                "position_tolerance": data["position_tolerance"], "angle_tolerance": data["angle_tolerance"],
                "parent_task": data["parent_task"], "task_end": data["task_end"]}
    if verdict.matched:
        return Comparison(matched=True, evidence=evidence)
    parts = []
    if "r_p" in verdict.failed:
        offset = (f"; the attachment points {verdict.delta_offset * 1000:.1f} mm from where they were, in the "
                  "reference's frame" if verdict.delta_offset is not None else "")
        parts.append(f"R_p {observed.r_p * 1000:.1f} mm, expected {expected.r_p * 1000:.1f} mm{offset}")
    if "r_n" in verdict.failed:
        parts.append(f"R_n {math.degrees(observed.r_n):.1f} deg, expected {math.degrees(expected.r_n):.1f} deg")
    return Comparison(matched=False, message=f"{expectation.description}: {'; '.join(parts)}", evidence=evidence)


plugin = ConfiguredPlugin(KeypointExpectations)
configure = plugin.configure


@hookimpl
def bt_meta_expectations(context: Any) -> list[Expectation] | None:
    return plugin.current.bt_meta_expectations(context)


@hookimpl
def bt_meta_observation_needs(context: Any) -> list[str] | None:
    return plugin.current.bt_meta_observation_needs(context)


@hookimpl
def bt_meta_compare(expectation: Expectation, observations: dict[str, Any], context: Any) -> Comparison | None:
    return compare(expectation, observations)
