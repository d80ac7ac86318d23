"""Shape substitutions from the task's geometry: cover the cells the plan still has to fill with the blocks on the
table, many-for-one and one-for-many, whatever the demonstrations decomposed.

The plan's placements say which cells the drawing needs: a step ``place(b, x, y)`` whose block the problem gives a
shape ``RxC`` covers C unit cells along x centred on (x, y) (a 1x2 at (1.5, 1) covers (1, 1) and (2, 1); the place
skill lays a block along the drawing's x, so only one-row shapes are tiled). The cells of the steps not yet run are
tiled anew with the blocks the world shows on the table and no executed step placed -- the plan's own blocks with
their *perceived* shapes, spares and unknown blocks -- by a depth-first search over the cells in order (row, then
x): each first uncovered cell gets a block that starts there and covers only needed, uncovered cells. A tile is
bound to a block of its shape, preferring the block the plan put on one of its cells, then the plan's other blocks,
then the others by name; colour counts only where the problem gives the plan's blocks one colour for all (the
methods' symbols then ask for it) and only for blocks the plan does not already use (the plan's own blocks were
bound by its methods; perception does not rebind them: a grid-map compares occupancy, not colour). With
``colours="prefer"`` (the default) a colour the methods name is a preference: when no tiling exists with blocks
of that colour, one with blocks of any colour is proposed, scored :data:`OTHER_COLOUR` lower and saying which
blocks differ -- the drawing is its cells, as the paper's red bar standing in for the blue one is (section 6.4);
``colours="require"`` never does. Blocks a failure of the run found out of reach where they lie
(the vector's ``unusable``) are not used. The result is a ``splice`` of the remaining steps, in the
order the plan would have reached the tiles' cells.

Blocks already lying on cells the tiling fills -- above all the block the failed step itself put down, a 1x2 where
a 1x1 was planned -- are in the way of whatever goes there next: the splice moves each such block before any
block is placed on a cell it covers (read from the world's object poses in the placements' frame), and a tile
takes such a block in preference to one that is not in the way, so nothing is left lying on the letter.

This finds what A's letter needs when one 1x2 stands where two 1x1 blocks that are not side by side were planned:
the two 1x2 blocks laid across the tops of the legs and the bar cells, the 1x1 blocks at the feet and the apex.

Offers:

* :func:`footprint` -- the cells a block of a shape covers when placed at (x, y)
* :func:`planned_shapes` -- the shapes the plan's steps were planned with (the problem's, or what a repair anchored)
* :func:`tile` -- a tiling of cells with blocks of given shapes (``None`` when none exists); :func:`tilings` --
  every one, in the search's order
* :class:`Drawing`, :func:`read_drawing` -- the placements, blocks, shapes and colour a failure's tilings read
* :func:`tiling_proposals` -- the ``splice`` proposal for a failure, when a tiling differs from the plan
* :func:`cells_in_the_way` -- the cells of a frame each object's current pose covers in part
* :func:`coordinate_text` -- a coordinate as a task file writes it
* :func:`frame_inverse`, :func:`unit_centres` -- table points into a frame; where a block's units lie in it
* :func:`lands_on_a_block` -- whether a failed placement run again with stand-ins would put its block on another
* :func:`covers_the_same_cells` -- whether a splice's placements cover the cells of the steps it replaces (a
  remembered decomposition that draws another part of the letter does not)
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bt_meta.bt.failures import RepairProposal
from bt_meta.meta.proposals import SPLICE
from bt_meta.world.poses import rpy_to_matrix

SCORE = 0.6
"""Below the spares (0.85) and the nearest remembered decompositions: the plan the geometry alone gives is tried
when nothing closer to what was demonstrated fits."""

MAX_NODES = 20000
"""Search nodes per tiling: a letter has a handful of cells; a larger drawing without a tiling stops here."""

_SHAPE = re.compile(r"^(\d+)x(\d+)$")
Cell = tuple[float, float]

OTHER_COLOUR = 0.1
"""Taken off the score of a tiling that needs a block of another colour than the methods name."""

IN_THE_WAY = 0.9
"""lb: a block unit whose centre is nearer than this to a cell's centre along both of the frame's axes overlaps the
cell (touching is 1.0; 0.9 leaves 6 mm of the cell covered)."""

__all__ = [
    "Drawing",
    "cells_in_the_way",
    "coordinate_text",
    "covers_the_same_cells",
    "footprint",
    "frame_inverse",
    "lands_on_a_block",
    "read_drawing",
    "tile",
    "tiling_proposals",
    "tilings",
    "unit_centres",
]


def _width(shape: str | None) -> int | None:
    """Units along x of a one-row shape (``1x2`` -> 2), else ``None``."""
    match = _SHAPE.match(str(shape or ""))
    if match is None or int(match.group(1)) != 1 or int(match.group(2)) < 1:
        return None
    return int(match.group(2))


def footprint(shape: str | None, x: float, y: float) -> list[Cell] | None:
    """The unit cells a block of ``shape`` placed with its centroid at (x, y) covers, or ``None`` for a shape that
    is not one row of units."""
    width = _width(shape)
    if width is None:
        return None
    return [(round(x + k - (width - 1) / 2.0, 3), round(float(y), 3)) for k in range(width)]


def tile(cells: Sequence[Cell], counts: Mapping[str, int], prefer: Mapping[Cell, str] | None = None
         ) -> list[tuple[str, Cell]] | None:
    """Cover every cell once with blocks of the shapes in ``counts`` (how many of each are on hand; all needn't
    be used): a list of (shape, centroid), or ``None``. ``prefer`` gives a shape to try first at a cell (what
    the plan assumed there)."""
    return next(tilings(cells, counts, prefer), None)


def tilings(cells: Sequence[Cell], counts: Mapping[str, int], prefer: Mapping[Cell, str] | None = None
            ) -> Iterator[list[tuple[str, Cell]]]:
    """Every tiling :func:`tile` could return, in its search order (the first is :func:`tile`'s), until the search
    has visited :data:`MAX_NODES` nodes."""
    needed = sorted(set(cells), key=lambda c: (c[1], c[0]))
    wanted = set(needed)
    left = dict(counts)
    covered: set[Cell] = set()
    placed: list[tuple[str, Cell]] = []
    budget = [MAX_NODES]
    shapes = sorted((s for s in left if _width(s) is not None), key=lambda s: -int(_width(s) or 0))

    def search() -> Iterator[list[tuple[str, Cell]]]:
        budget[0] -= 1
        if budget[0] < 0:
            return
        first = next((c for c in needed if c not in covered), None)
        if first is None:
            yield list(placed)
            return
        order = sorted(shapes, key=lambda s: (s != (prefer or {}).get(first), -int(_width(s) or 0)))
        for shape in order:
            if left.get(shape, 0) <= 0:
                continue
            width = int(_width(shape) or 0)
            centre = (round(first[0] + (width - 1) / 2.0, 3), first[1])
            cover = footprint(shape, *centre) or []
            if any(c not in wanted or c in covered for c in cover):
                continue
            left[shape] -= 1
            covered.update(cover)
            placed.append((shape, centre))
            yield from search()
            placed.pop()
            covered.difference_update(cover)
            left[shape] += 1

    yield from search()


def _cells(calls: Sequence[Sequence[Any]], shapes: Mapping[str, str | None]) -> list[Cell] | None:
    """The cells placements ``[action, block, x, y]`` cover with blocks of ``shapes``; ``None`` when one is not
    a placement of a one-row block."""
    out: list[Cell] = []
    for call in calls:
        if len(call) != 4:
            return None
        x, y = _number(call[2]), _number(call[3])
        cells = footprint(shapes.get(str(call[1])), x, y) if x is not None and y is not None else None
        if cells is None:
            return None
        out += cells
    return out


def covers_the_same_cells(proposal: RepairProposal, plan: Sequence[Mapping[str, Any]], assumed: Mapping[str, str],
                          perceived: Mapping[str, str]) -> bool | None:
    """Whether a ``splice``'s new placements (blocks with their ``perceived`` shapes, else ``assumed``) cover the
    same cells as the steps it replaces (with the shapes the plan ``assumed``); ``None`` when either are not
    placements of one-row blocks (the geometry cannot tell)."""
    changes = proposal.changes or {}
    start, end = int(changes.get("start", 0)), int(changes.get("end", 0))
    replaced = [[r["action"], *r["args"]] for r in plan if start <= int(r["step"]) < end]
    before = _cells(replaced, assumed)
    after = _cells(changes.get("actions") or [], {**assumed, **perceived})
    if before is None or after is None:
        return None
    return sorted(before) == sorted(after)


def frame_inverse(world: Any, frame: str) -> Callable[[float, float], Cell] | None:
    """Table (X, Y) -> the frame's (x, y), from the world's own mapping of three frame points; ``None`` when the
    world does not ground the frame."""
    ground = getattr(world, "ground_cell", None)
    frames = getattr(getattr(world, "grounding", None), "frames", None) or {}
    if ground is None or frame not in frames:
        return None
    try:
        origin = np.array(ground(frame, "0", "0")[:2], dtype=float)
        ex = np.array(ground(frame, "1", "0")[:2], dtype=float) - origin
        ey = np.array(ground(frame, "0", "1")[:2], dtype=float) - origin
        inverse = np.linalg.inv(np.column_stack([ex, ey]))
    except np.linalg.LinAlgError:  # a degenerate frame (unit 0): nothing is known to be in the way
        return None

    def to_frame(x: float, y: float) -> Cell:
        u, v = inverse @ (np.array([x, y], dtype=float) - origin)
        return float(u), float(v)

    return to_frame


def unit_centres(state: Mapping[str, Any], to_frame: Callable[[float, float], Cell]) -> list[Cell]:
    """The frame coordinates of the unit centres of a one-row block lying with ``state["pose"]``: along its long
    axis as the table sees it (a block standing on its end is one unit over its centre)."""
    pose = [float(v) for v in state.get("pose") or []]
    width = _width(state.get("shape")) or 1
    if len(pose) < 6:
        return []
    axis = np.asarray(rpy_to_matrix(pose[3], pose[4], pose[5]))[:, 0]
    centre = np.array(to_frame(pose[0], pose[1]))
    tip = np.array(to_frame(pose[0] + float(axis[0]), pose[1] + float(axis[1]))) - centre
    length = float(np.hypot(*tip))
    if width == 1 or length < 0.5 * math.hypot(*to_frame(1.0, 0.0)):  # nearly vertical: over its centre
        return [(float(centre[0]), float(centre[1]))]
    step = tip / length
    return [tuple(float(c) for c in centre + (k - (width - 1) / 2.0) * step) for k in range(width)]


def cells_in_the_way(world: Any, frame: str, objects: Mapping[str, Mapping[str, Any]], cells: Sequence[Cell]
                     ) -> dict[str, set[Cell]]:
    """Object name -> the ``cells`` (of ``frame``) its current pose covers in part; objects held or covering
    none are left out."""
    to_frame = frame_inverse(world, frame)
    if to_frame is None:
        return {}
    out: dict[str, set[Cell]] = {}
    for name, state in objects.items():
        if state.get("held_by"):
            continue
        units = unit_centres(state, to_frame)
        hit = {c for c in cells for u in units if abs(u[0] - c[0]) < IN_THE_WAY and abs(u[1] - c[1]) < IN_THE_WAY}
        if hit:
            out[name] = hit
    return out


def _in_order(tiles: list[tuple[int, str, list[Cell]]], in_the_way: Mapping[str, set[Cell]]) -> list[int]:
    """Indices of ``tiles`` (first step, block, cells) in the order to place them: by first step, except that a
    block lying on another tile's cells is moved before that tile (a cycle of such blocks keeps the step order)."""
    after: dict[int, set[int]] = {i: set() for i in range(len(tiles))}
    for i, (_, block, cells) in enumerate(tiles):
        for j, (_, other, _) in enumerate(tiles):
            if j != i and other != block and in_the_way.get(other, set()) & set(cells):
                after[i].add(j)
    order: list[int] = []
    left = set(after)
    while left:
        ready = [i for i in left if not after[i] & left] or list(left)  # a cycle: fall back to the step order
        first = min(ready, key=lambda i: (tiles[i][0], i))
        order.append(first)
        left.remove(first)
    return order


def _number(value: Any) -> float | None:
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def planned_shapes(problem: Any, world: Any) -> dict[str, str]:
    """Block -> the shape the plan's steps were planned with: the problem's ``shape`` facts, overridden by the
    world's belief (``symbolic_state()``), where a repair anchored a block's perceived shape -- the steps a tiling
    planned lay b1 seen as a 1x2 at x = 2.5, and read with the problem's 1x1 they would need the half cell 2.5."""
    facts = list(getattr(problem, "init", None) or getattr(problem, "state", None) or ())
    shapes = {str(f[1]): str(f[2]) for f in facts if len(f) == 3 and f[0] == "shape"}
    symbolic = getattr(world, "symbolic_state", None)
    if callable(symbolic):
        shapes.update({str(f[1]): str(f[2]) for f in symbolic() if len(f) == 3 and f[0] == "shape"})
    return shapes


@dataclass
class Drawing:
    """What the tilings read off a failure: the placements of the plan (the steps still to run and those run),
    the blocks the world shows, the shapes the steps were planned with and the colour the methods ask for."""

    world: Any
    action: str
    frame: str | None
    todo: list[tuple[int, str, list[Cell]]]
    """(step, block, cells) of each placement still to run, in plan order."""
    done: list[tuple[int, str, list[Cell]]]
    """The same for the placements of the same action already run."""
    seen: dict[str, dict[str, Any]]
    assumed: dict[str, str]
    unusable: set[str]
    """Blocks a failure of the run found out of reach where they lie."""
    colour: str | None
    """The colour the methods ask the plan's blocks for (every block of the steps to run has it), else ``None``."""
    records: list[Mapping[str, Any]]

    @property
    def cells(self) -> list[Cell]:
        return [c for p in self.todo for c in p[2]]

    @property
    def placed(self) -> set[str]:
        """The blocks a placement already run put down (not a block an executed ``turn_over`` turned)."""
        return {str((r.get("args") or [""])[0]) for r in self.records
                if r.get("done") and str(r.get("action")) == self.action}

    def on_hand(self, wanted: str | None, candidates: Iterable[str], plan_blocks: Sequence[str]) -> list[str]:
        """The blocks of ``candidates`` a tile may take, with the colour ``wanted`` (or any), the plan's blocks
        first (in plan order), then those of the methods' colour, then by name."""
        return sorted((n for n in candidates if n not in self.unusable and _width(self.seen[n].get("shape")) is not None
                       and (wanted is None or n in plan_blocks or self.seen[n].get("colour") == wanted)),
                      key=lambda n: (n not in plan_blocks, plan_blocks.index(n) if n in plan_blocks else 0,
                                     self.colour is not None and self.seen[n].get("colour") != self.colour, n))


def read_drawing(vector: Any, failure: Any, context: Any) -> Drawing | None:
    """The :class:`Drawing` of a failure, or ``None`` when the steps still to run are not placements of shaped
    blocks by one action (the geometry does not say what they need) or their cells overlap."""
    evidence = getattr(failure, "evidence", None) or {}
    plan = list(evidence.get("plan") or [])
    world = getattr(context, "world", None)
    problem = getattr(getattr(context, "run", None), "problem", None)
    if not plan or getattr(world, "observe", None) is None or problem is None:
        return None
    facts = list(getattr(problem, "init", None) or getattr(problem, "state", None) or ())
    assumed = planned_shapes(problem, world)
    colours = {str(f[1]): str(f[2]) for f in facts if len(f) == 3 and f[0] == "colour"}
    seen = {name: state for name, state in _seen(world).items() if state.get("shape")}
    for name, state in seen.items():  # a stand-in the problem does not describe (a spare) is planned as it is seen
        assumed.setdefault(name, str(state["shape"]))
        if state.get("colour"):
            colours.setdefault(name, str(state["colour"]))

    def placement(record: Mapping[str, Any]) -> tuple[int, str, list[Cell]] | None:
        args = [str(a) for a in record.get("args") or []]
        x, y = (_number(args[1]), _number(args[2])) if len(args) == 3 else (None, None)
        cells = footprint(assumed.get(args[0]), x, y) if args and x is not None and y is not None else None
        return None if cells is None else (int(record["step"]), args[0], cells)

    todo: list[tuple[int, str, list[Cell]]] = []
    for record in (p for p in plan if not p.get("done")):
        found = placement(record)
        if found is None:
            return None  # a step that is not a placement of a shaped block: the geometry does not say what it needs
        todo.append(found)
    actions = {str(r["action"]) for r in plan if not r.get("done")}
    if not todo or len(actions) != 1:
        return None
    action = actions.pop()
    done = [found for r in plan if r.get("done") and str(r["action"]) == action
            if (found := placement(r)) is not None]
    cells = [c for p in todo for c in p[2]]
    if len(set(cells)) != len(cells):
        return None  # the plan's own placements overlap: not a tiling problem
    colour = None
    planned_colours = {colours.get(p[1]) for p in todo}
    if len(planned_colours) == 1 and None not in planned_colours:
        colour = planned_colours.pop()  # the methods' symbols ask the plan's blocks for one colour
    return Drawing(world=world, action=action, frame=_action_frame(world, action), todo=todo, done=done, seen=seen,
                   assumed=assumed, unusable=set(getattr(vector, "unusable", ()) or ()), colour=colour, records=plan)


def tiling_proposals(vector: Any, failure: Any, context: Any, colours: str = "prefer") -> list[RepairProposal]:
    """The ``splice`` of the remaining placements as a tiling of their cells with the blocks on the table, when it
    differs from the plan; ``[]`` when the plan's steps are not placements of shaped blocks or no tiling exists."""
    drawing = read_drawing(vector, failure, context)
    if drawing is None:
        return []
    world, action, seen, colour = drawing.world, drawing.action, drawing.seen, drawing.colour
    placements, cells = drawing.todo, drawing.cells
    plan_blocks = [p[1] for p in placements]
    owner = {c: p[1] for p in placements for c in p[2]}
    step_of = {c: p[0] for p in placements for c in p[2]}
    prefer = {c: drawing.assumed.get(owner[c]) for c in cells}
    relaxed = None
    tiles = None
    for wanted in dict.fromkeys([colour, None] if colours == "prefer" else [colour]):
        on_hand = drawing.on_hand(wanted, (n for n in seen if n not in drawing.placed), plan_blocks)
        counts: dict[str, int] = {}
        for name in on_hand:
            counts[str(seen[name]["shape"])] = counts.get(str(seen[name]["shape"]), 0) + 1
        tiles = tile(cells, counts, prefer)
        if tiles is not None:
            relaxed = colour if wanted is None and colour is not None else None
            break
    if tiles is None:
        return []
    frame = drawing.frame
    in_the_way = cells_in_the_way(world, frame, {n: seen[n] for n in on_hand}, cells) if frame else {}
    free = list(on_hand)
    bound: list[tuple[int, str, list[Cell]]] = []
    centres: dict[str, Cell] = {}
    for shape, centre in sorted(tiles, key=lambda t: min(step_of[c] for c in footprint(t[0], *t[1]) or [])):
        cover = footprint(shape, *centre) or []
        fitting = [n for n in free if str(seen[n]["shape"]) == shape]
        mine = [n for n in fitting if n in {owner[c] for c in cover}]
        lying = [n for n in fitting if n in in_the_way]  # to be moved anyway, or it stays in the way
        block = (mine or lying or fitting)[0]
        free.remove(block)
        bound.append((min(step_of[c] for c in cover), block, cover))
        centres[block] = centre
    actions = [[action, block, coordinate_text(centres[block][0]), coordinate_text(centres[block][1])]
               for block in (bound[i][1] for i in _in_order(bound, in_the_way))]
    old = [[str(r["action"]), *map(str, r["args"])] for r in drawing.records if not r.get("done")]
    if actions == old:
        return []
    start, end = placements[0][0], placements[-1][0] + 1
    shown = "; ".join(f"{a[0]}({', '.join(a[1:])})" for a in actions)
    other = sorted(b for b in centres if relaxed is not None and b not in plan_blocks
                   and seen[b].get("colour") != relaxed)
    note = f" ({', '.join(other)} not {relaxed}: no {relaxed} block can stand in)" if other else ""
    return [RepairProposal(
        SPLICE, round(SCORE - (OTHER_COLOUR if other else 0.0), 4), f"steps {start}..{end - 1} as a tiling of their "
        f"{len(cells)} cell(s) with the blocks on the table: {shown}{note}",
        changes={"start": start, "end": end, "actions": actions},
        evidence={"matcher": "tiling", "vector": vector.to_dict() if hasattr(vector, "to_dict") else None,
                  "cells": [list(c) for c in cells], "blocks": {n: seen[n].get("shape") for n in on_hand},
                  "in_the_way": {n: sorted(list(c) for c in v) for n, v in in_the_way.items()},
                  "colour_required": colour, "other_colour": other})]


def lands_on_a_block(failure: Any, mapping: Mapping[str, str], context: Any) -> bool:
    """Whether the failed placement, run again with ``mapping``'s stand-ins, would put its block down on cells
    another block lies on (the 1x2 the failed step left across the cell a 1x1 was planned on)."""
    args = [str(a) for a in getattr(failure, "args", ()) or ()]
    world = getattr(context, "world", None)
    observe = getattr(world, "observe", None)
    action = getattr(failure, "action", None)
    if len(args) != 3 or observe is None or action is None:
        return False
    x, y = _number(args[1]), _number(args[2])
    frame = _action_frame(world, str(action))
    seen = _seen(world)
    block = str(mapping.get(args[0], args[0]))
    cells = footprint((seen.get(block) or {}).get("shape"), x, y) if x is not None and y is not None else None
    if not cells or frame is None:
        return False
    return bool(cells_in_the_way(world, frame, {n: v for n, v in seen.items() if n != block}, cells))


def _seen(world: Any) -> dict[str, dict[str, Any]]:
    """The objects the world shows (``observe()["objects"]``), by name."""
    objects = (world.observe() or {}).get("objects") or {}
    return {str(k): dict(v) for k, v in objects.items() if isinstance(v, Mapping)}


def _action_frame(world: Any, action: str) -> str | None:
    """The task frame the world grounds ``action``'s coordinates in (the grounding's ``frame:`` of its skill)."""
    skills = getattr(getattr(world, "grounding", None), "skills", None) or {}
    spec = skills.get(action) or {}
    return str(spec["frame"]) if isinstance(spec, Mapping) and spec.get("frame") else None


def coordinate_text(value: float) -> str:
    """A coordinate as the task file writes it (``1``, ``1.5``)."""
    return str(int(value)) if float(value).is_integer() else f"{value:g}"
