"""Grid-map expectations (paper, section 6): after a step, the blocks it moved should look as they did in memory.

For a monitored step the episodic memory gives the states after the same step in the last N successful traces
(:mod:`bt_meta.perception.recall`). Their grid-maps of the objects the step names (e.g. ``place(b5, 1.5, 1)``:
b5's map), and of every other object the step moved, whatever its type, are the expectation. A step that puts
an object at numbers of a frame (``place``) is checked where memory had the object; every other object (carried
to a pose symbol, lifted, inserted, knocked) is checked as it looks where it is observed now
(``observations["objects"]``), not where it is: its window is centred on it -- except while the robot carries
it (held, or joined to what is held: the keypoint plugin watches its orientation there). The
observation is the top view of camera perception (``observations["image"]``): for each remembered map the block
seen nearest its centroid (within ``recentre_radius``, default a quarter block) is cropped centred on its own
centroid, as the paper crops blobs; when no single block is there (nothing, or blocks touching each other merged
into one blob) the remembered window itself is cropped. A trace matches when every one of its maps
differs from the observation by at most ``max_cells`` cells; the step matches when any of the N traces does
(nearest neighbour). Observed blobs that share no cell with the remembered map are left out of the count
(another object in the window, e.g. a distractor a few centimetres off, is not what the step did; blobs are
taken one colour at a time, so a distractor of another colour touching the block is left out too). What is
compared is what the step could have changed: a blob that meets only other cells memory expected (a leg below,
a block remembered in the window's corner) and none the step's block can cover (within half its longest side of
the window's centre) counts only on those cells, so a distractor lying against a neighbour and out into the
corner is not counted either; nor is the part of a neighbour merged into the step's blob that reaches beyond
the cells memory expected it on (a 1x2 a repair laid against the leg); a block one cell off, or a neighbour
knocked away, still differs. With
``symbol_colours`` (``BT_META_GRIDMAP_COLOURS=symbols``), colour matters where the task's symbols say it does: a
block the step moves with a ``colour(b, c)`` fact must cover its cells in colour ``c`` -- each cell of another
colour differs (the blue bar the symbols name, seen green); for the other blocks, and by default for all,
occupancy is colour presence, as in the paper (whose letter A with a red bar counts as drawn). A mismatch
suggests ``unknown_entity`` when a block is seen there with another shape than the one remembered (the 1x2
replaced by a 1x1) or another colour than its symbols give it (the substitution plugins then look for a stand-in
of the right colour), else ``unexpected_configuration``.

An expectation made at the last primitive of a task is also that task's expectation (bubbled up, section 6.2):
``data["task_end"]`` and ``data["parent_task"]`` say so.

Offers:

* :class:`GridMapExpectations` -- the plugin as an object (memory, N, tolerance in cells, colour, rotations)
* :func:`bt_meta_expectations`, :func:`bt_meta_compare` -- the module-level plugin (see :func:`configure`)
* :func:`symbol_colours` -- the colours the task's symbols give a step's arguments
* :func:`colours_from_environment` -- the ``symbol_colours`` default, from :data:`ENV_COLOURS`
* :data:`KIND` -- ``"gridmap"``; :data:`ENV_COLOURS` -- ``"BT_META_GRIDMAP_COLOURS"``
"""

from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

import numpy as np

from bt_meta.bt.expectations import Comparison, Expectation
from bt_meta.bt.failures import FailureKind
from bt_meta.errors import ConfigError
from bt_meta.perception.gridmap import DEFAULT_SPEC, grid_difference, render
from bt_meta.perception.recall import memory_for, remember
from bt_meta.plugins import ConfiguredPlugin, hookimpl
from bt_meta.world.simulation.objects import LB

KIND = "gridmap"
ENV_COLOURS = "BT_META_GRIDMAP_COLOURS"


class GridMapExpectations:
    """Per-step grid-map expectations from the last ``n`` successful traces.

    ``max_cells``: cells that may differ; ``compare_colour``: a cell of another colour than remembered differs too
    (off by default: the paper's occupancy is colour presence); ``symbol_colours``: a block the step moves whose
    colour the task's symbols name must show that colour (default: ``$BT_META_GRIDMAP_COLOURS``, off unless it says
    ``symbols`` -- the paper's demo counts letter A with a red bar as drawn); ``rotations``: the best quarter turn
    counts (off: the same step should put the block the same way); ``memory``: an
    :class:`~bt_meta.memory.EpisodicMemory` (default: the run's, else the ``--memory`` file).
    """

    def __init__(self, memory: Any = None, *, n: int = 5, max_cells: int = 2, compare_colour: bool = False,
                 rotations: bool = False, recentre_radius: float = 0.25 * LB, symbol_colours: bool | None = None
                 ) -> None:
        if n < 1 or max_cells < 0 or recentre_radius < 0:
            raise ValueError("n must be >= 1, max_cells and recentre_radius >= 0")
        self.memory = memory
        self.n = n
        self.max_cells = max_cells
        self.compare_colour = compare_colour
        self.rotations = rotations
        self.recentre_radius = recentre_radius
        self.symbol_colours = colours_from_environment() if symbol_colours is None else symbol_colours
        self._view: tuple[int, Any] | None = None  # (id of the run, the top view its last compared step left)

    @hookimpl
    def bt_meta_expectations(self, context: Any) -> list[Expectation] | None:
        memory = memory_for(context, self.memory)
        if memory is None:
            return None
        remembered = remember(memory, context, self.n)
        if remembered is None:
            return None
        names, at_numbers = _named(context)
        # the maps of a part a spare now stands in for (a rebinding) watch the spare
        stand_ins = dict(getattr(context.world, "stand_ins", None) or {})
        traces = []
        for record in remembered.records:
            chosen = [replace(m, object_name=stand_ins[str(m.object_name)]) if str(m.object_name) in stand_ins else m
                      for m in record.step.state.grid_maps]
            if chosen:
                traces.append({"episode": record.episode_id, "maps": chosen})
        if not traces:
            return None
        # where the step put it by numbers of a frame (place(b5, 1.5, 1)): there; anything else it names or moved
        # (carried to a pose symbol, inserted into another part, lifted where it lay): as it looks where it is
        relative = sorted({str(m.object_name) for t in traces for m in t["maps"]
                           if not (at_numbers and str(m.object_name) in names)})
        colours = symbol_colours(context) if self.symbol_colours else {}
        call = f"{context.action}({', '.join(str(a) for a in context.args)})"
        return [Expectation(
            kind=KIND,
            description=f"grid-maps after {call} as in {len(traces)} remembered trace(s)",
            data={
                "traces": traces,
                "max_cells": self.max_cells,
                "compare_colour": self.compare_colour,
                "rotations": self.rotations,
                "recentre_radius": self.recentre_radius,
                "colours": colours,
                "relative": relative,
                "parent_task": remembered.parent_task,
                "task_end": remembered.task_end,
                "matched_by": remembered.key,
            },
            failure_kind=FailureKind.UNEXPECTED_CONFIGURATION,
        )]

    @hookimpl
    def bt_meta_observation_needs(self, context: Any) -> list[str] | None:
        """The top view and the object states whenever the run has a memory to expect grid-maps from: every
        step's view, compared or not, is the ``before`` of the next compared step (and the start's of the first)."""
        return ["image", "objects"] if memory_for(context, self.memory) is not None else []

    @hookimpl
    def bt_meta_compare(self, expectation: Expectation, observations: dict[str, Any], context: Any
                        ) -> Comparison | None:
        run = getattr(context, "run", None)
        before = self._view[1] if run is not None and self._view is not None and self._view[0] == id(run) else None
        if before is None and run is not None:  # the run's first step: the world as the run found it
            before = (getattr(run, "start_observations", None) or {}).get("image")
        result = compare(expectation, observations, before=before, carried=_carried(context))
        if run is not None and observations.get("image") is not None:
            self._view = (id(run), observations["image"])
        return result


def _named(context: Any) -> tuple[set[str], bool]:
    """(world objects the step's arguments name, whether its other arguments are all numbers -- a point of a
    frame the step puts the object at)."""
    world = getattr(context, "world", None)
    to_world = getattr(world, "object_name", None)
    names, numbers, counted = set(), True, False
    for arg in (str(a) for a in getattr(context, "args", ())):
        try:
            float(arg)
            counted = True
            continue
        except ValueError:
            pass
        name = None
        if to_world is not None:
            try:
                name = str(to_world(arg))
            except Exception:  # not an object of the world: a pose symbol, a feature
                name = None
        if name is None and world is None:
            name = arg
        if name is None:
            numbers = False
        else:
            names.add(name)
    return names, numbers and counted and bool(names)


def _carried(context: Any) -> set[str]:
    """The objects the robot carries now: held, or joined to a held one (magnetically, transitively). Their
    orientation is the keypoint plugin's to watch; seen from above in the air, a subassembly hides its parts."""
    sim = getattr(getattr(context, "world", None), "sim", None)
    if sim is None or not hasattr(sim, "held"):
        return set()
    found = {sim.held(arm) for arm in sim.robot.arms} - {None}
    pairs = [tuple(p) for p in sim.attachments()] if hasattr(sim, "attachments") else []
    frontier = list(found)
    while frontier:
        current = frontier.pop()
        for a, b in pairs:
            other = b if a == current else a if b == current else None
            if other is not None and other not in found:
                found.add(other)
                frontier.append(other)
    return {str(n) for n in found}


def _located(name: str, observations: dict[str, Any], view: Any) -> Any:
    """Where (x, y) object ``name`` is observed now: its observed state, else the camera's block named after it;
    ``None`` when it is not seen."""
    state = (observations.get("objects") or {}).get(name)
    pose = state.get("pose") if isinstance(state, dict) else getattr(state, "pose", None)
    if pose is not None:
        return (float(pose[0]), float(pose[1]))
    for block in getattr(view, "blocks", ()) or ():
        if hasattr(view, "name_of") and view.name_of(block) == name:
            return tuple(block.centroid)
    return None


def _blobs(grid: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected blobs of a coded grid, one colour at a time: two blocks of different colours that touch are two
    blobs (a block is one colour), two of the same colour one."""
    from scipy import ndimage

    labels = np.zeros(grid.shape, dtype=int)
    count = 0
    for code in (int(c) for c in np.unique(grid) if c != 0):
        part, n = ndimage.label(grid == code, structure=np.ones((3, 3), dtype=int))
        labels[part != 0] = part[part != 0] + count
        count += n
    return labels, count


def _centre_blobs(labels: np.ndarray) -> np.ndarray:
    """Cells of the blobs over the window's centre: the step's block (the crop is centred on it), with whatever of
    its colour touches it."""
    rows, columns = labels.shape
    centre = labels[rows // 2 - 1:rows // 2 + 1, columns // 2 - 1:columns // 2 + 1]
    return np.isin(labels, [k for k in np.unique(centre) if k != 0])


def _reach(expected: Any) -> np.ndarray:
    """Cells the step's block can cover in its own window, which is centred on it: those within half its longest
    side of the centre, however it is turned (``AxB`` in block units; the whole window for another shape). Leg
    blocks of its colour that memory saw merged with it are outside."""
    cells = np.asarray(expected.occupancy).shape
    inside = np.ones(cells, dtype=bool)
    try:
        longest = max(float(side) for side in str(expected.shape).split("x"))
    except ValueError:
        return inside
    reach = int(np.ceil(longest * LB / DEFAULT_SPEC.cell_size / 2.0))
    rows, columns = np.indices(cells)
    return ((np.abs(rows - (cells[0] - 1) / 2.0) < reach) & (np.abs(columns - (cells[1] - 1) / 2.0) < reach))


def _touching(expected: Any, observed: Any) -> Any:
    """``observed`` reduced to what the step could have changed. Blobs that share no cell with what memory expected
    are left out: another object in the window (a distractor a few centimetres from the cell, or touching the
    placed block but of another colour) is not what the step did. A blob that meets only the *other* cells memory
    expected (a neighbour block, or a corner of the window) and not the step's block keeps only those cells: a
    distractor lying against the leg below and out into the window's corner is not the step's doing either, while
    the neighbour's cells are still compared (one knocked away is still missed). A block that landed elsewhere still
    differs: the cells expected occupied are then empty, and a blob over the step's block counts whole."""
    seen = np.asarray(observed.occupancy)
    labels, count = _blobs(seen)
    if count == 0:
        return observed
    wanted = np.asarray(expected.occupancy) != 0
    step = wanted & _centre_blobs(_blobs(np.asarray(expected.occupancy))[0]) & _reach(expected)
    if not step.any():
        step = wanted  # nothing remembered over the centre: every expected cell may be the step's
    kept = np.zeros(seen.shape, dtype=bool)
    near = _beside(_reach(expected))
    for k in range(1, count + 1):
        blob = labels == k
        if np.any(step & blob):
            kept |= _without_neighbours_reach(blob, near, wanted)
        elif np.any(wanted & blob):
            kept |= blob & wanted
    if np.all(kept == (seen != 0)):
        return observed
    return replace(observed, occupancy=np.where(kept, seen, 0).astype(np.uint8))


def _without_neighbours_reach(blob: np.ndarray, near: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The cells of the blob over the step's block that count: beyond ``near`` (where that block can show), a part
    of the blob that holds cells memory expected occupied is a neighbour merged with it, and only those cells count
    (a 1x2 a repair laid against the leg reaches out along it: not the step's doing); a part that holds none
    counts whole (something of its colour against the block)."""
    from scipy import ndimage

    kept = blob & near
    parts, count = ndimage.label(blob & ~near)
    for k in range(1, count + 1):
        part = parts == k
        kept |= (part & wanted) if np.any(part & wanted) else part
    return kept


def _without_earlier(expected: Any, observed: Any, earlier: Any) -> Any:
    """``observed`` without the cells memory expected empty that ``earlier`` (the same window before the step)
    already showed occupied: a block an earlier step of this run put there (a repair may place the blocks in
    another order than the demonstrations: H's bar-right cell covered before the bar-left block comes)."""
    seen = np.asarray(observed.occupancy)
    old = np.asarray(earlier.occupancy)
    if old.shape != seen.shape:
        return observed
    stale = (old != 0) & (seen != 0) & (np.asarray(expected.occupancy) == 0)
    if not stale.any():
        return observed
    return replace(observed, occupancy=np.where(stale, 0, seen).astype(np.uint8))


def _beside(zone: np.ndarray) -> np.ndarray:
    """``zone`` and the cells sharing a side with it: where the step's block can show, however it landed a little
    off."""
    from scipy import ndimage

    return ndimage.binary_dilation(zone, structure=ndimage.generate_binary_structure(2, 1))


def _distance(expected: Any, observed: Any, colour: bool, rotations: bool) -> int:
    if not rotations:
        observed = _touching(expected, observed)
    cells = grid_difference(expected, observed, rotations=rotations)
    if colour and not rotations:
        a, b = np.asarray(expected.occupancy), np.asarray(observed.occupancy)
        cells += int(np.count_nonzero((a != 0) & (b != 0) & (a != b)))
    return cells


def _off_colour(expected: Any, observed: Any, code: int) -> int:
    """Cells of the block the step moved -- the blob over the window's centre, where the crop is centred on it --
    that memory expected occupied and that show another colour than ``code``, the one the task's symbols give the
    block. The other blocks in the window (the legs below a bar) keep whatever colour they have."""
    seen = np.asarray(observed.occupancy)
    moved = _centre_blobs(_blobs(seen)[0])
    wanted = np.asarray(expected.occupancy) != 0
    return int(np.count_nonzero(moved & wanted & (seen != code)))


def _detail(expected: Any, observed: Any, block: Any, off_colour: int, cells: int, wanted: str | None = None
            ) -> dict[str, Any]:
    return {
        "object": expected.object_name,
        "cells": cells,
        "off_colour": off_colour,
        "symbol_colour": wanted,
        "expected": {"colour": expected.colour, "shape": expected.shape,
                     "centroid": list(expected.centroid), "grid": render(expected)},
        "observed": {"colour": observed.colour, "shape": observed.shape,
                     "centroid": list(observed.centroid), "grid": render(observed),
                     "block_seen": block is not None},
    }


def colours_from_environment() -> bool:
    """``$BT_META_GRIDMAP_COLOURS``: ``symbols`` (colour matters where the task's symbols name it) or ``occupancy``
    (the paper's colour presence; also when unset)."""
    value = os.environ.get(ENV_COLOURS, "").strip().lower()
    if value not in ("", "occupancy", "symbols"):
        raise ConfigError(f"${ENV_COLOURS} must be 'symbols' or 'occupancy', got {value!r}")
    return value == "symbols"


def symbol_colours(context: Any) -> dict[str, str]:
    """``{object: colour}`` for the step's arguments whose colour the task's symbols name (``colour(b5, blue)`` in
    the belief the step started from, else in the problem's initial facts): where colour matters to the task."""
    names = {str(a) for a in getattr(context, "args", ())}
    facts: Any = None
    state = getattr(context, "state_before", None)
    if state is not None and hasattr(state, "atoms_of"):
        facts = list(state.atoms_of("colour"))
    if not facts:
        problem = getattr(getattr(context, "run", None), "problem", None)
        facts = getattr(problem, "init", None) or getattr(problem, "state", None) or ()
    return {str(f[1]): str(f[2]) for f in facts
            if len(f) == 3 and f[0] == "colour" and str(f[1]) in names}


def compare(expectation: Expectation, observations: dict[str, Any], before: Any = None,
            carried: set[str] | frozenset[str] = frozenset()) -> Comparison | None:
    """Compare a ``"gridmap"`` expectation with the top view in ``observations["image"]`` (``None`` without);
    ``carried``: objects the robot holds now (with what is joined to them), whose as-it-looks maps are left out;
    ``before``, the top view the previous step left (for the run's first step, the one it started with:
    ``RunContext.start_observations``), when known: a cell memory expected empty that was occupied
    then and still is holds a block an earlier step put there, not the step's doing."""
    if expectation.kind != KIND:
        return None
    view = observations.get("image")
    if view is None or not hasattr(view, "grid_map_at"):
        return None
    data = expectation.data
    best: dict[str, Any] | None = None
    relative = set(data.get("relative") or ())
    for trace in data["traces"]:
        details = []
        for expected in trace["maps"]:
            centre = expected.centroid
            if expected.object_name in relative and expected.object_name in carried:
                continue  # in the robot's hand: watched by its orientation, not from above
            if expected.object_name in relative:  # as it looks where it is now
                centre = _located(str(expected.object_name), observations, view)
                if centre is None:
                    centre = expected.centroid if "objects" not in observations else None
            if centre is None:  # gone from the world: every cell memory expected occupied differs
                details.append(_detail(expected, view.grid_map_at(expected.centroid), None, 0,
                                       int(np.count_nonzero(np.asarray(expected.occupancy)))))
                continue
            if expected.object_name in relative:
                # cropped as the recorder cropped it: centred on the object itself, on the height of what is seen
                # there (not recentred on another blob: a part resting on it is not it)
                block = None
                seen = view.block_near(centre, 0.5 * LB)
                top = None if seen is None else seen.top_z
                observed = view.grid_map_at(centre, z=top)
            else:
                block = view.block_near(centre, data["recentre_radius"])
                if block is not None and block.shape == "unknown":
                    block = None  # blocks merged into one blob: its centroid is nobody's
                top = None if block is None else block.top_z
                if block is not None:
                    observed = view.grid_map_at(block.centroid, z=top, colour=block.colour, shape=block.shape)
                else:
                    observed = view.grid_map_at(centre)
            if before is not None and hasattr(before, "grid_map_at") and not data["rotations"]:
                observed = _without_earlier(expected, observed, before.grid_map_at(observed.centroid, z=top))
            cells = _distance(expected, observed, data["compare_colour"], data["rotations"])
            wanted = (data.get("colours") or {}).get(str(expected.object_name))
            off_colour = 0
            if wanted is not None and wanted in getattr(getattr(view, "thresholds", None), "names", ()):
                off_colour = _off_colour(expected, observed, view.thresholds.code(wanted))
            details.append(_detail(expected, observed, block, off_colour, cells + off_colour, wanted))
        worst = max((d["cells"] for d in details), default=0)
        if best is None or worst < best["cells"]:
            best = {"episode": trace["episode"], "cells": worst, "maps": details}
    assert best is not None
    evidence = {"nearest_episode": best["episode"], "cells": best["cells"], "max_cells": data["max_cells"],
                "maps": best["maps"], "parent_task": data["parent_task"], "task_end": data["task_end"]}
    if best["cells"] <= data["max_cells"]:
        return Comparison(matched=True, evidence=evidence)
    off = [d for d in best["maps"] if d["cells"] > data["max_cells"]]
    other_shape = any(d["observed"]["block_seen"] and d["observed"]["shape"] != d["expected"]["shape"] for d in off)
    other_colour = any(d["off_colour"] for d in off)
    kind = FailureKind.UNKNOWN_ENTITY if other_shape or other_colour else FailureKind.UNEXPECTED_CONFIGURATION
    shown = "; ".join(
        f"{d['object']}: {d['cells']} cells differ (expected {d['symbol_colour'] or d['expected']['colour']} "
        f"{d['expected']['shape']}, seen {d['observed']['colour'] or 'nothing'} {d['observed']['shape'] or ''}"
        .rstrip() + (f"; {d['off_colour']} of another colour than its symbols say" if d["off_colour"] else "") + ")"
        for d in off
    )
    evidence["suggested_kind"] = kind.value
    return Comparison(
        matched=False,
        message=f"{expectation.description}: {shown}",
        evidence=evidence,
        expectation=replace(expectation, failure_kind=kind),
    )


plugin = ConfiguredPlugin(GridMapExpectations)
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
