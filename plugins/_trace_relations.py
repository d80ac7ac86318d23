"""The current execution against the successful traces, step by step (paper, section 7.4, steps 1-2 of pose
backtracking): R_p / R_n now and their means in the traces, where they deviate, and which steps moved a part.

Offers:

* :class:`StepRelation` -- one step's relations, current and expected, and whether they deviate
* :func:`step_relations` -- every comparable step (only the relations informative there are judged)
* :func:`align_steps` -- which trace step each step of the current plan plays (a repair that spliced steps in moves
  the plan's indices away from the traces')
* :func:`moved`, :func:`moved_in_trace` -- did an object's pose change during a step (here, or in a trace)
* :data:`MOVED_POSITION`, :data:`MOVED_ANGLE` -- what counts as moved
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from bt_meta_plugins._good_poses import state_pose as _state_pose

from bt_meta.perception.keypoints import (
    CONTACT_DISTANCE,
    KeypointError,
    expected_relation,
    informative,
    judge,
    relation,
)

__all__ = ["MOVED_ANGLE", "MOVED_POSITION", "StepRelation", "align_steps", "moved", "moved_in_trace",
           "step_relations"]

MOVED_POSITION = 0.005
"""Metres: an object that moved more than this (or turned more than :data:`MOVED_ANGLE`) during a step had its
pose set by it."""
MOVED_ANGLE = 0.05


@dataclass(frozen=True)
class StepRelation:
    """R_p / R_n after one step: now, and the traces' mean; ``deviates`` when outside the tolerances."""

    step: int
    action: str
    r_p: float
    r_n: float
    expected_p: float
    expected_n: float
    traces: int
    deviates: bool
    spread_p: float = 0.0
    spread_n: float = 0.0
    """Standard deviations of R_p and R_n over the traces: how much the traces agree at this step."""

    def as_dict(self) -> dict[str, Any]:
        return {"step": self.step, "action": self.action, "R_p": round(self.r_p, 5), "R_n": round(self.r_n, 4),
                "expected_R_p": round(self.expected_p, 5), "expected_R_n": round(self.expected_n, 4),
                "traces": self.traces, "deviates": self.deviates, "spread_R_p": round(self.spread_p, 5),
                "spread_R_n": round(self.spread_n, 4)}


def step_relations(
    current: Mapping[int, Mapping[str, Any]],
    traces: Sequence[Any],
    active: str,
    reference: str,
    actions: Mapping[int, str],
    *,
    position_tolerance: float | None = 0.01,
    angle_tolerance: float | None = math.radians(15.0),
    contact_distance: float | None = CONTACT_DISTANCE,
    alignment: Mapping[int, int] | None = None,
) -> list[StepRelation]:
    """For every step of ``current`` (step -> object states) whose action (``actions``) the traces ran at the same
    index (or at the index ``alignment`` gives: :func:`align_steps`; steps it leaves out are not compared): the
    current R_p / R_n, the traces' means, and whether they deviate (:func:`judge`) in the relations informative
    there (:func:`~bt_meta.perception.keypoints.informative`: a part merely lying elsewhere does not deviate)."""
    rows = []
    for step in sorted(current):
        objects = current[step]
        if active not in objects or reference not in objects:
            continue
        if alignment is not None and step not in alignment:
            continue
        index = alignment[step] if alignment is not None else step
        pairs = []
        for trace in traces:
            if index < len(trace.steps) and trace.steps[index].action == actions.get(step):
                state = trace.steps[index].state
                try:
                    pairs.append((state.object(active), state.object(reference)))
                except KeyError:
                    continue
        if not pairs:
            continue
        expected = expected_relation(pairs)
        observed = relation(objects[active], objects[reference])
        position, angle = informative(expected, position_tolerance=position_tolerance,
                                      angle_tolerance=angle_tolerance, contact_distance=contact_distance)
        verdict = judge(observed, expected, position_tolerance=position, angle_tolerance=angle)
        rows.append(StepRelation(step, actions.get(step, ""), observed.r_p, observed.r_n, expected.r_p, expected.r_n,
                                 expected.n, not verdict.matched, expected.r_p_std, expected.r_n_std))
    return rows


def align_steps(plan: Sequence[Mapping[str, Any]], trace: Any, failed: int) -> dict[int, int]:
    """Current plan step -> the step of ``trace`` that plays its part, for the run of steps around ``failed``.

    A repair that spliced steps in (a re-orientation before the task runs again) leaves the plan's indices apart from
    the traces': the task's second run is at steps 40..52 where the traces ran it at 0..12. Every step up to the
    failed one matching the trace's at its own index (no splice before it), the indices are kept. Otherwise the steps
    are matched backwards from the failed one (and forwards after it) while action and arguments agree (an argument
    a repair rewrote -- a pose symbol such as ``held:...``, in the plan or in a trace of a repaired run -- plays the
    part of the one it replaced); of the trace steps the failed one can be, the longest match wins. Empty when the
    failed step is not in the trace (a step of the repair itself)."""
    records = {int(r["step"]): r for r in plan}
    steps = list(getattr(trace, "steps", ()))

    def same(step: int, index: int) -> bool:
        record = records.get(step)
        if record is None or not 0 <= index < len(steps) or str(record["action"]) != steps[index].action:
            return False
        ours, theirs = [str(a) for a in record.get("args") or ()], [str(a) for a in steps[index].args]
        return len(ours) == len(theirs) and all(a == b or ":" in a or ":" in b
                                                for a, b in zip(ours, theirs, strict=True))

    def run_from(start: int) -> dict[int, int]:
        """The failed step as trace step ``start``: the steps matching backwards from there, then forwards."""
        mapping: dict[int, int] = {}
        k = 0
        while same(failed - k, start - k):
            mapping[failed - k] = start - k
            k += 1
        if mapping:
            k = 1
            while same(failed + k, start + k):
                mapping[failed + k] = start + k
                k += 1
        return mapping

    kept = run_from(failed)
    if 0 in kept:  # every step up to the failed one at its own index: nothing spliced before it
        return kept
    best: dict[int, int] = {}
    for start in range(len(steps) - 1, -1, -1):
        mapping = run_from(start)
        if len(mapping) > len(best):
            best = mapping
    return best


def _moved(before: Any, after: Any) -> bool:
    a, b = _state_pose(before), _state_pose(after)
    turned = math.acos(max(-1.0, min(1.0, (float(np.trace(a[:3, :3].T @ b[:3, :3])) - 1.0) / 2.0)))
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])) > MOVED_POSITION or turned > MOVED_ANGLE


def _moved_in_trace(trace: Any, step: int, active: str) -> bool:
    if not 0 < step < len(trace.steps):
        return False
    try:
        return _moved(trace.steps[step - 1].state.object(active), trace.steps[step].state.object(active))
    except (KeyError, KeypointError):
        return False


moved = _moved
moved_in_trace = _moved_in_trace
