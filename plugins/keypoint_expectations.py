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

from bt_meta.bt.expectations import Comparison, Expectation
from bt_meta.bt.failures import FailureKind
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
from bt_meta.perception.recall import memory_for, remember
from bt_meta.plugins import ConfiguredPlugin, hookimpl

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
        remembered = remember(memory, context, self.n)
        if remembered is None or (self.check == "task_end" and not remembered.task_end):
            return None
        states = remembered.states
        expectations = []
        call = f"{context.action}({', '.join(str(a) for a in context.args)})"
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

    @hookimpl
    def bt_meta_compare(self, expectation: Expectation, observations: dict[str, Any], context: Any
                        ) -> Comparison | None:
        return compare(expectation, observations)


def compare(expectation: Expectation, observations: dict[str, Any]) -> Comparison | None:
    """Compare a ``"keypoint"`` expectation with ``observations["objects"]`` (``None`` without object states)."""
    if expectation.kind != KIND:
        return None
    objects = observations.get("objects")
    if objects is None:
        return None
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
def bt_meta_compare(expectation: Expectation, observations: dict[str, Any], context: Any) -> Comparison | None:
    return compare(expectation, observations)
