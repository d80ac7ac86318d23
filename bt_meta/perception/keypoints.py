"""Keypoint relations between an active and a reference object (paper, section 7.4), and their expectations.

For step i of trace j, with attachment points AP and normals AN of both objects in the robot base frame:

* ``R_p(i, j) = |AP(active) - AP(reference)|`` (metres)
* ``R_n(i, j) = arccos(AN(active) . AN(reference))`` (radians)

and the expectation of step i is their mean over the N past traces. Beside the paper's scalar R_p, a relation keeps
its **offset**: ``AP(active) - AP(reference)`` in the reference's frame. Two joined parts hold their attachment
points about a centimetre apart, straight along the normal; a part put down 1.2 cm beside the reference (which had
moved from where the instructor's absolute poses expect it) holds them as far apart, sideways, and is not joined.
The magnitudes agree, the offsets do not (generated magnetic s1 0031): where R_p is checked the offset is checked
with the same tolerance. An observation is judged against the mean
with a tolerance per relation (a relation can be switched off by giving no tolerance).

Object states come in three forms and :func:`keypoints_of` reads all of them: the memory's
:class:`~bt_meta.memory.ObjectState` (AN in the object frame, turned into the base frame by its pose), the
simulator's :class:`~bt_meta.world.simulation.sim.SimObjectState` (``an`` in the base frame) and the dict the
simulator's
``observe()`` gives (``SimObjectState.as_dict()``: ``an`` in the base frame; ``an_object`` when present wins and
is turned by the pose).

Offers:

* :func:`keypoints_of` -- (AP, AN) of an object state in the base frame
* :class:`Relation` / :func:`relation` -- R_p and R_n of two object states
* :class:`KeypointExpectation` / :func:`expected_relation` -- means (and spreads) over past states
* :class:`KeypointVerdict` / :func:`judge` -- does an observed relation match an expectation
* :func:`informative` -- which relations an expectation can hold an observation to (R_p once the parts meet,
  R_n where the traces agree), :data:`CONTACT_DISTANCE`
* :func:`pairs_from_states` -- the (active, reference) object states of stored states
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bt_meta.errors import BtMetaError
from bt_meta.world.simulation.objects import rpy_to_matrix

__all__ = [
    "CONTACT_DISTANCE",
    "KeypointError",
    "KeypointExpectation",
    "KeypointVerdict",
    "Relation",
    "expected_relation",
    "informative",
    "judge",
    "keypoints_of",
    "pairs_from_states",
    "relation",
]


class KeypointError(BtMetaError):
    """An object state without attachment point or normal, or an expectation over no traces."""


def _vector(value: Any, what: str) -> np.ndarray:
    array = np.asarray(value, dtype=float).reshape(-1)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise KeypointError(f"{what} must be 3 finite numbers, got {value!r}")
    return array


def keypoints_of(state: Any) -> tuple[np.ndarray, np.ndarray]:
    """(AP, unit AN) of one object state, both in the robot base frame (see the module docstring)."""
    if isinstance(state, Mapping):
        name = state.get("name", "object")
        if "ap" not in state:
            raise KeypointError(f"object state of {name!r} has no attachment point 'ap'")
        ap = _vector(state["ap"], f"{name}: AP")
        if state.get("an_object") is not None:
            pose = state.get("pose")
            if pose is None or len(pose) != 6:
                raise KeypointError(f"object state of {name!r} gives 'an_object' without a 6-number pose")
            an = rpy_to_matrix(*pose[3:]) @ _vector(state["an_object"], f"{name}: AN")
        elif "an" in state:
            an = _vector(state["an"], f"{name}: AN")
        else:
            raise KeypointError(f"object state of {name!r} has no attachment normal 'an'")
    else:
        name = getattr(state, "name", "object")
        if not hasattr(state, "ap"):
            raise KeypointError(f"object state {state!r} has no attachment point")
        ap = _vector(state.ap, f"{name}: AP")
        base = getattr(state, "an_base", None)  # memory ObjectState: AN in the object frame
        if base is not None and hasattr(state, "rotation"):
            an = _vector(base, f"{name}: AN")
        elif hasattr(state, "an"):
            an = _vector(state.an, f"{name}: AN")  # SimObjectState: AN in the base frame
        else:
            raise KeypointError(f"object state {state!r} has no attachment normal")
    norm = float(np.linalg.norm(an))
    if norm < 1e-12:
        raise KeypointError(f"object state of {name!r} has a zero attachment normal")
    return ap, an / norm


@dataclass(frozen=True)
class Relation:
    """R_p (m) and R_n (rad) of an active and a reference object at one moment, and the offset (m, the
    reference's frame; ``None`` when the reference's orientation is not known)."""

    r_p: float
    r_n: float
    offset: tuple[float, float, float] | None = None

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"r_p": self.r_p, "r_n": self.r_n}
        if self.offset is not None:
            out["offset"] = list(self.offset)
        return out


def _rotation_of(state: Any) -> np.ndarray | None:
    """The object's orientation (3x3, base frame) from its 6-number pose, or ``None``."""
    pose = state.get("pose") if isinstance(state, Mapping) else getattr(state, "pose", None)
    if pose is None or len(pose) != 6:
        return None
    return np.asarray(rpy_to_matrix(*(float(v) for v in pose[3:])), dtype=float)


def relation(active: Any, reference: Any) -> Relation:
    """The paper's R_p and R_n between two object states (any form :func:`keypoints_of` reads), and the offset."""
    ap_a, an_a = keypoints_of(active)
    ap_r, an_r = keypoints_of(reference)
    r_p = float(np.linalg.norm(ap_a - ap_r))
    r_n = math.acos(max(-1.0, min(1.0, float(an_a @ an_r))))
    rotation = _rotation_of(reference)
    offset = None if rotation is None else tuple(float(v) for v in rotation.T @ (ap_a - ap_r))
    return Relation(r_p, r_n, offset)  # type: ignore[arg-type]


@dataclass(frozen=True)
class KeypointExpectation:
    """Exp_p(i) and Exp_n(i): the means of R_p and R_n over ``n`` traces, with their standard deviations."""

    r_p: float
    r_n: float
    n: int
    r_p_std: float = 0.0
    r_n_std: float = 0.0
    offset: tuple[float, float, float] | None = None
    """The mean offset (every trace gave one), else ``None``."""

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"r_p": self.r_p, "r_n": self.r_n, "n": self.n, "r_p_std": self.r_p_std,
                               "r_n_std": self.r_n_std}
        if self.offset is not None:
            out["offset"] = list(self.offset)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> KeypointExpectation:
        offset = data.get("offset")
        return cls(float(data["r_p"]), float(data["r_n"]), int(data["n"]), float(data.get("r_p_std", 0.0)),
                   float(data.get("r_n_std", 0.0)),
                   None if offset is None else tuple(float(v) for v in offset))  # type: ignore[arg-type]


def expected_relation(pairs: Iterable[tuple[Any, Any]]) -> KeypointExpectation:
    """The expectation over past ``(active, reference)`` object-state pairs, one per trace."""
    relations = [relation(active, reference) for active, reference in pairs]
    if not relations:
        raise KeypointError("a keypoint expectation needs at least one past trace")
    p = np.array([r.r_p for r in relations])
    n = np.array([r.r_n for r in relations])
    offsets = [r.offset for r in relations]
    offset = None if any(o is None for o in offsets) else tuple(
        float(v) for v in np.mean(np.array(offsets, dtype=float), axis=0))
    return KeypointExpectation(float(p.mean()), float(n.mean()), len(relations), float(p.std()), float(n.std()),
                               offset)  # type: ignore[arg-type]


@dataclass(frozen=True)
class KeypointVerdict:
    """Whether an observed relation matches its expectation, and by how much each relation is off."""

    matched: bool
    observed: Relation
    expected: KeypointExpectation
    delta_p: float
    delta_n: float
    failed: tuple[str, ...]
    """Which relations are outside their tolerance: ``"r_p"`` (R_p or the offset), ``"r_n"``."""
    delta_offset: float | None = None
    """|offset - expected offset| (m), when both are known."""

    def as_dict(self) -> dict[str, Any]:
        return {
            "matched": self.matched,
            "observed": self.observed.as_dict(),
            "expected": self.expected.as_dict(),
            "delta_p": self.delta_p,
            "delta_n": self.delta_n,
            "delta_offset": self.delta_offset,
            "failed": list(self.failed),
        }


def judge(
    observed: Relation,
    expected: KeypointExpectation,
    *,
    position_tolerance: float | None = 0.01,
    angle_tolerance: float | None = math.radians(15.0),
) -> KeypointVerdict:
    """Match when ``|R_p - Exp_p| <= position_tolerance`` -- and, where both are known, the offset within the same
    distance of the expected one -- and ``|R_n - Exp_n| <= angle_tolerance``; a tolerance of ``None`` leaves that
    relation unchecked. The defaults are the simulator's attach rule (1 cm, 15 degrees)."""
    delta_p = abs(observed.r_p - expected.r_p)
    delta_n = abs(observed.r_n - expected.r_n)
    delta_offset = None
    if observed.offset is not None and expected.offset is not None:
        delta_offset = float(np.linalg.norm(np.subtract(observed.offset, expected.offset)))
    failed: list[str] = []
    if position_tolerance is not None and (delta_p > position_tolerance
                                           or (delta_offset is not None and delta_offset > position_tolerance)):
        failed.append("r_p")
    if angle_tolerance is not None and delta_n > angle_tolerance:
        failed.append("r_n")
    return KeypointVerdict(not failed, observed, expected, delta_p, delta_n, tuple(failed), delta_offset)


CONTACT_DISTANCE = 0.03
"""Metres: R_p is informative where the traces' attachment points are this close (mean plus spread): the parts
meet. Further apart it measures where the parts happen to lie on the table, which a shifted scene changes."""


def informative(
    expected: KeypointExpectation,
    *,
    position_tolerance: float | None,
    angle_tolerance: float | None,
    contact_distance: float | None = CONTACT_DISTANCE,
) -> tuple[float | None, float | None]:
    """The (position, angle) tolerances worth checking against ``expected`` (section 7.4: R_p at the end of the
    attach, R_n for gross pose changes); ``None`` for a relation the traces say is not informative there: R_p
    before the parts meet (unless ``contact_distance`` is ``None``), R_n where the traces disagree by more than
    the angle tolerance."""
    position = position_tolerance
    if position is not None and contact_distance is not None and expected.r_p + expected.r_p_std > contact_distance:
        position = None
    angle = angle_tolerance
    if angle is not None and expected.r_n_std > angle:
        angle = None
    return position, angle


def pairs_from_states(states: Sequence[Any], active: str, reference: str) -> list[tuple[Any, Any]]:
    """``(active, reference)`` object states of each memory :class:`~bt_meta.memory.State` that has both."""
    pairs = []
    for state in states:
        try:
            pairs.append((state.object(active), state.object(reference)))
        except KeyError:
            continue
    return pairs
