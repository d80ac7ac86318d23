"""The sub-symbolic precondition of learned refinements: ``pose_within`` and ``seen`` as external predicates.

``pose_within(obj, x, y, z, roll, pitch, yaw, pos_tol, ang_tol)`` holds when the world of the current run reports
``obj`` within ``pos_tol`` metres of ``(x, y, z)`` and every angle within ``ang_tol`` radians (wrapped to
[-pi, pi]) of ``(roll, pitch, yaw)``. Object poses come from ``world.observe()["objects"]`` of the run installed on
the blackboard (the executor installs its run before planning); without a run, or for an object the world does
not report, the predicate is false -- a refinement whose starting poses cannot be confirmed is not used.

``seen(obj, attribute, value)`` holds when the same world reports ``obj`` with ``attribute`` equal to ``value``
(``seen(b6, colour, red)``): the perceived entity facts a refinement's repair relied on (object substitution's
anchoring) must be perceived again for it to apply.

Offers:

* :func:`pose_within` -- the test itself, on a pose and the predicate's arguments
* :func:`bt_meta_external_predicate` -- the hook: answers ``pose_within`` and ``seen``, ``None`` for other
  predicates
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from bt_meta.bt.context import current_run
from bt_meta.errors import PluginError
from bt_meta.meta.refinements import POSE_ARITY, POSE_PREDICATE, SEEN_ARITY, SEEN_PREDICATE, pose_of, seen_holds
from bt_meta.plugins import hookimpl


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def pose_within(pose: Sequence[float], args: Sequence[str]) -> bool:
    """Whether ``pose`` (6 floats) is within the tolerances of the predicate arguments ``args[1:]``."""
    try:
        target = [float(a) for a in args[1:7]]
        position_tol, angle_tol = float(args[7]), float(args[8])
    except (ValueError, IndexError):
        raise PluginError(
            f"{POSE_PREDICATE}{tuple(args)}: expected an object, 6 pose numbers and 2 tolerances") from None
    if math.dist(pose[:3], target[:3]) > position_tol:
        return False
    return all(abs(_wrap(a - b)) <= angle_tol for a, b in zip(pose[3:], target[3:], strict=True))


def _objects() -> dict[str, Any] | None:
    """The objects the installed run's world reports, or ``None`` without a run or an observing world."""
    run = current_run()
    world = None if run is None else run.world
    observe = getattr(world, "observe", None)
    if observe is None:
        return None
    objects = (observe() or {}).get("objects")
    return dict(objects) if objects else {}


@hookimpl
def bt_meta_external_predicate(name: str, args: tuple[str, ...], state: Any) -> bool | None:
    if name == SEEN_PREDICATE:
        if len(args) != SEEN_ARITY:
            raise PluginError(f"{SEEN_PREDICATE} takes {SEEN_ARITY} arguments (object, attribute, value), "
                              f"got {len(args)}")
        objects = _objects()
        return objects is not None and seen_holds(objects, str(args[0]), str(args[1]), str(args[2]))
    if name != POSE_PREDICATE:
        return None
    if len(args) != POSE_ARITY:
        raise PluginError(f"{POSE_PREDICATE} takes {POSE_ARITY} arguments, got {len(args)}")
    objects = _objects()
    state_of = None if objects is None else objects.get(args[0])
    pose = None if state_of is None else pose_of(state_of)
    return False if pose is None else pose_within(pose, args)
