"""Ground truth of a variant run, read from the simulator -- not from what the run believed.

A run can end ``success`` for the executor while the task is not done: with symbolic expectations only, A's bar
placed as one red 1x1 block satisfies ``at(b5, 1.5, 1)`` but leaves two holes in the letter. The demo and the
ablation therefore also ask the simulator:

* **letters** -- every unit cell of the demonstrated letter (the last remembered successful trace of the task:
  its placed blocks' final poses and shapes) is covered by a block unit in the final world, within 0.3 lb;
* **magnetic** -- the root task's two parts (as the world grounds them at the end: a spare may stand in) are
  joined by the magnets;
* **housing** -- the housing is inserted (the insert skill's own geometric check set ``inserted``).

Offers:

* :func:`achieved` -- ``(bool, reason)`` for a family, a finished world and the memory
* :func:`unit_centres` -- the (x, y) centres of a block's 1x1 units from its pose and shape
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from bt_meta.world.simulation.objects import LB

__all__ = ["achieved", "unit_centres"]

COVER_RADIUS = 0.3 * LB


def unit_centres(pose: Sequence[float], shape: str | None) -> list[tuple[float, float]]:
    """The centres of a Mega Blok's units in the base frame (its long axis is the object's x axis)."""
    units = 2 if shape == "1x2" else 1
    x, y, pitch, yaw = float(pose[0]), float(pose[1]), float(pose[4]), float(pose[5])
    # the object's x axis projected on the table (R = Rz(yaw) Ry(pitch) Rx(roll): first column)
    ax, ay = math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch)
    norm = math.hypot(ax, ay) or 1.0
    ax, ay = ax / norm, ay / norm
    return [(x + (i - (units - 1) / 2.0) * LB * ax, y + (i - (units - 1) / 2.0) * LB * ay) for i in range(units)]


def _letter_reference(memory: Any, task: str) -> list[tuple[float, float]] | None:
    traces = memory.last_traces(task, 1)
    if not traces or not traces[0].steps:
        return None
    trace = traces[0]
    final = trace.steps[-1].state
    shapes = {f[1]: f[2] for f in (*trace.initial.facts, *final.facts) if len(f) == 3 and f[0] == "shape"}
    placed = {f[1] for f in final.facts if f and f[0] == "at" and len(f) == 4}
    centres = []
    for state in final.objects:
        if state.name in placed:
            centres += unit_centres(state.pose, shapes.get(state.name))
    return centres or None


def _task_parts(world: Any, problem: Any) -> tuple[str, str]:
    """The world objects the root task's two parts are grounded as now (a spare may stand in for one: the world's
    grounding was rebound); ``active`` and ``reference`` when the task does not name two."""
    tasks = list(getattr(problem, "tasks", None) or [])
    to_world = getattr(world, "object_name", None)
    if not tasks or len(tasks[0]) < 3 or to_world is None:
        return "active", "reference"
    names = []
    for symbol in tasks[0][1:3]:
        try:
            names.append(str(to_world(str(symbol))))
        except Exception:  # a symbol the world cannot ground (its object is gone): it is not joined
            names.append(str(symbol))
    return names[0], names[1]


def achieved(family: str, world: Any, memory: Any, problem: Any) -> tuple[bool | None, str]:
    """Whether the variant's task is really done in ``world`` (``None`` when nothing can tell)."""
    sim = getattr(world, "sim", None)
    if sim is None:
        return None, "no simulator to ask"
    if family == "letters":
        from bt_meta.memory.recorder import root_task_name

        reference = _letter_reference(memory, root_task_name(problem))
        if reference is None:
            return None, "no demonstrated letter in memory"
        units = [c for s in sim.object_states().values() if s.shape for c in unit_centres(s.pose, s.shape)]
        holes = [r for r in reference if not any(math.hypot(r[0] - u[0], r[1] - u[1]) <= COVER_RADIUS for u in units)]
        if holes:
            return False, f"{len(holes)} of {len(reference)} cells of the demonstrated letter are not covered"
        return True, f"all {len(reference)} cells of the demonstrated letter are covered"
    if family == "magnetic":
        joined = {tuple(sorted(pair)) for pair in sim.attachments()}
        first, second = _task_parts(world, problem)
        if tuple(sorted((first, second))) in joined:
            return True, f"{first} and {second} are joined"
        return False, f"{first} and {second} are not joined"
    if family == "housing":
        state = world.symbolic_state()
        done = any(atom[0] == "inserted" for atom in state)
        return done, "the housing is inserted" if done else "the housing is not inserted"
    return None, f"no ground truth for family {family!r}"
