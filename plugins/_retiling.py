"""Re-tiling a drawing whose remaining cells no tiling covers: blocks already placed are moved.

A tiling (:mod:`bt_meta_plugins._tilings`) covers the cells the steps still to run need with the blocks left on the
table. When none exists, the drawing can still be finished when the blocks already in it count: the block planned
for the top of A's second leg is a 1x2 and a foot is gone, so the cells left (a foot, a leg top, the bar, the apex)
want three 1x1 blocks where only one is left -- but two 1x2 laid across the leg tops and the bar cells, with 1x1
blocks at the feet and the apex, draw the letter, once the 1x1 already on the first leg's top is moved to a foot.

So the whole drawing's cells (the placements run and those still to run) are tiled anew with every block on the
table and in the drawing. A placed block whose footprint is a tile stays; the tiling that moves the fewest blocks
is taken (the search's order breaks ties). Every other tile gets a block -- the blocks lying on the drawing's cells
first, since they must leave them anyway (a placed block the new tiling moves, the block the failed step put down),
then the plan's, then the rest -- and the tiles are put in an order where no block is put down on a cell another
block still lies on. A binding whose order would need a cycle (b1 must leave the cell b2 goes to, and b2 the one b1
goes to) is replaced by the next. A block of the plan lying on the drawing that no tile is left for (more blocks
than the new tiling uses: the apex found out of reach only once the letter was drawn, and a 1x2 stand-in for it
makes two 1x2 across the leg tops, so one drawn 1x1 is one too many -- generated letters_A s1 0106) is set aside
first: at the nearest grid point of the drawing's frame with a free cell between it and the drawing, clear of every
other object, where the world says it can be put down (``world.put_down_problem``: clear of static obstacles and
reachable). A block the plan does not name (a distractor) lying there that no tile takes leaves no proposal: what
the task does not name is not moved off the drawing.

The proposal is a ``splice`` of the remaining steps with these placements, scored :data:`SCORE` (below a tiling of
the remaining cells alone, which moves nothing drawn). Its ``facts`` undo, when it is applied, the executed
placements of the blocks it moves (they are on the table again, not drawn where they were: their ``place``
preconditions hold again); its ``evidence["replay_plan"]`` is the new tiling drawn from the start, so a kept
refinement draws the letter so at once, without the detour.

Offers:

* :func:`retiling_proposals` -- the ``splice`` proposal for a failure, or ``[]``
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from bt_meta_plugins._tilings import (
    OTHER_COLOUR,
    Cell,
    Drawing,
    cells_in_the_way,
    coordinate_text,
    footprint,
    frame_inverse,
    read_drawing,
    tile,
    tilings,
    unit_centres,
)

from bt_meta.bt.failures import RepairProposal
from bt_meta.errors import BtMetaError
from bt_meta.meta.proposals import SPLICE

__all__ = ["SCORE", "retiling_proposals"]

SCORE = 0.55
"""Below a tiling of the remaining cells (0.6): moving blocks already drawn is the larger change."""

MAX_TILINGS = 200
"""Tilings of the whole drawing compared for the fewest moves (a letter has a handful)."""

MAX_BINDINGS = 2000
"""Bindings of blocks to the tiles that move tried for an order without a cycle, per tiling."""

ASIDE_RANGE = 4
"""Cells around the drawing searched for a spot to set a block aside."""

ASIDE_CHECKS = 12
"""Nearest spots the world is asked about (each an IK solve or two) before giving up."""

Tile = tuple[str, Cell, list[Cell]]
"""(shape, centre, cells)."""

Found = tuple[dict[str, Tile], list[str], dict[str, Cell]]
"""(block -> its tile, the order of the blocks that move onto tiles, block -> where it is set aside)."""


def retiling_proposals(vector: Any, failure: Any, context: Any, colours: str = "prefer") -> list[RepairProposal]:
    """The ``splice`` that finishes the drawing by tiling all its cells again, moving placed blocks (see the module
    docstring); ``[]`` when nothing is drawn yet, the world does not ground the drawing's frame, or no tiling of
    the whole drawing can be reached."""
    drawing = read_drawing(vector, failure, context)
    if drawing is None or not drawing.done or drawing.frame is None:
        return []
    if _remaining_tile(drawing, colours):
        return []  # the cells still to fill have a tiling of their own: nothing drawn needs to move
    placements = sorted(drawing.done + drawing.todo)
    cells = [c for p in placements for c in p[2]]
    if len(set(cells)) != len(cells):
        return []  # the drawing's placements overlap: not a tiling problem
    seen = drawing.seen
    lying = cells_in_the_way(drawing.world, drawing.frame, seen, cells)
    plan_blocks = [p[1] for p in placements]
    for wanted in dict.fromkeys([drawing.colour, None] if colours == "prefer" else [drawing.colour]):
        candidates = drawing.on_hand(wanted, seen, plan_blocks)
        found = _best(drawing, placements, candidates, lying, set(plan_blocks))
        if found is not None:
            relaxed = drawing.colour if wanted is None and drawing.colour is not None else None
            return [_proposal(drawing, placements, found, lying, relaxed, context, vector)]
    return []


def _remaining_tile(drawing: Drawing, colours: str) -> bool:
    """Whether the cells the steps still to run fill have a tiling with the blocks not yet placed."""
    plan_blocks = [p[1] for p in drawing.todo]
    for wanted in dict.fromkeys([drawing.colour, None] if colours == "prefer" else [drawing.colour]):
        free = drawing.on_hand(wanted, (n for n in drawing.seen if n not in drawing.placed), plan_blocks)
        if tile(drawing.cells, _counts(drawing, free)) is not None:
            return True
    return False


def _counts(drawing: Drawing, names: Sequence[str]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for name in names:
        shape = str(drawing.seen[name]["shape"])
        counts[shape] = counts.get(shape, 0) + 1
    return counts


def _best(drawing: Drawing, placements: Sequence[tuple[int, str, list[Cell]]], candidates: list[str],
          lying: Mapping[str, set[Cell]], asidable: set[str]) -> Found | None:
    """(block -> its tile, the order of the blocks that move, block -> where it is set aside) for the tiling that
    moves the fewest blocks and has a binding in an order without a cycle; ``None`` when none has."""
    seen = drawing.seen
    counts = _counts(drawing, candidates)
    # a placed block still covering just its own cells may stay; the search tries its shape there first
    stays = {block: frozenset(cs) for _, block, cs in drawing.done
             if block in candidates and lying.get(block) == set(cs)}
    prefer = {c: drawing.assumed.get(block) for _, block, cs in placements for c in cs}
    found = []
    for tiles in itertools.islice(tilings([c for p in placements for c in p[2]], counts, prefer), MAX_TILINGS):
        covers = [(shape, centre, footprint(shape, *centre) or []) for shape, centre in tiles]
        kept = {block: index for index, (shape, _, cs) in enumerate(covers) for block, own in stays.items()
                if frozenset(cs) == own and str(seen[block]["shape"]) == shape}
        found.append((len(covers) - len(kept), len(found), covers, kept))
    step_of = {c: step for step, _, cs in placements for c in cs}
    cells = [c for p in placements for c in p[2]]

    def spot(block: str, taken: Sequence[Cell]) -> Cell | None:
        return _aside_spot(drawing, block, cells, taken)

    owner = {c: block for _, block, cs in placements for c in cs}
    for _, _, covers, kept in sorted(found, key=lambda f: (f[0], f[1])):
        bound = _bind(covers, kept, candidates, lying, seen, step_of, owner, asidable, spot)
        if bound is not None:
            return bound
    return None


def _bind(covers: list[Tile], kept: Mapping[str, int], candidates: list[str], lying: Mapping[str, set[Cell]],
          seen: Mapping[str, Mapping[str, Any]], step_of: Mapping[Cell, int], owner: Mapping[Cell, str],
          asidable: set[str], spot: Callable[[str, Sequence[Cell]], Cell | None]) -> Found | None:
    """Blocks for the tiles no placed block keeps, in an order where none lands on a block still to move; a block
    of the plan lying on the drawing that no tile of its shape is left for is set aside first, at a ``spot``."""
    taken = set(kept.values())
    moving = [i for i in range(len(covers)) if i not in taken]
    movers = sorted(b for b in lying if b not in kept)
    if any(b not in candidates for b in movers):
        return None  # a block on the drawing no tile may take (its colour, out of reach): it would stay there
    others = [b for b in candidates if b not in kept and b not in movers]
    by_shape: dict[str, list[int]] = {}
    for i in moving:
        by_shape.setdefault(covers[i][0], []).append(i)
    per_shape = []
    for shape in {*by_shape, *(str(seen[b]["shape"]) for b in movers)}:
        tiles = by_shape.get(shape, [])
        mine = [b for b in movers if str(seen[b]["shape"]) == shape]
        rest = [b for b in others if str(seen[b]["shape"]) == shape]
        if len(mine) + len(rest) < len(tiles):
            return None
        options = _shape_bindings(tiles, mine, rest, covers, step_of, owner, asidable)
        if not options:
            return None  # more blocks of this shape on the drawing than tiles, and one the plan does not name
        per_shape.append(options)
    for tried, combination in enumerate(itertools.product(*per_shape)):
        if tried >= MAX_BINDINGS:
            return None
        binding = {block: covers[i] for part, _ in combination for i, block in part.items()}
        aside = [block for _, blocks in combination for block in blocks]
        order = acyclic_order(binding, {b: c for b, c in lying.items() if b not in aside}, step_of)
        if order is None:
            continue
        spots: dict[str, Cell] = {}
        for block in aside:
            where = spot(block, list(spots.values()))
            if where is None:
                break
            spots[block] = where
        else:
            return {**binding, **{block: covers[i] for block, i in kept.items()}}, order, spots
    return None


def _shape_bindings(tiles: list[int], movers: list[str], rest: list[str], covers: list[Tile],
                    step_of: Mapping[Cell, int], owner: Mapping[Cell, str], asidable: set[str]
                    ) -> list[tuple[dict[int, str], list[str]]]:
    """Every way to give ``tiles`` (of one shape) the ``movers``, the other tiles blocks of ``rest`` (in their
    order; a tile the plan meant one of them for takes that one): (tile index -> block, the movers set aside --
    when there are more than tiles, only blocks of ``asidable``)."""
    out: list[tuple[dict[int, str], list[str]]] = []
    if len(movers) > len(tiles):
        for chosen in itertools.permutations(movers, len(tiles)):
            aside = [b for b in movers if b not in chosen]
            if all(b in asidable for b in aside):
                out.append((dict(zip(tiles, chosen, strict=True)), aside))
            if len(out) >= MAX_BINDINGS:
                break
        return out
    for placed in itertools.permutations(tiles, len(movers)):
        binding = dict(zip(placed, movers, strict=True))
        left = list(rest)
        for i in sorted((i for i in tiles if i not in binding), key=lambda i: min(step_of[c] for c in covers[i][2])):
            planned = [b for b in left if b in {owner.get(c) for c in covers[i][2]}]
            block = (planned or left)[0]
            left.remove(block)
            binding[i] = block
        out.append((binding, []))
        if len(out) >= MAX_BINDINGS:
            break
    return out


def _aside_spot(drawing: Drawing, block: str, cells: Sequence[Cell], taken: Sequence[Cell]) -> Cell | None:
    """Where to set ``block`` aside, in the drawing's frame: the nearest grid point to where it lies whose
    footprint keeps a free cell between it and the drawing and a cell from every other object and spot ``taken``,
    where the world says it can be put down (``world.put_down_problem``: clear of static obstacles, reachable);
    ``None`` when no point within :data:`ASIDE_RANGE` cells of the drawing is."""
    world, frame = drawing.world, str(drawing.frame)
    to_frame = frame_inverse(world, frame)
    state = drawing.seen.get(block) or {}
    pose = state.get("pose") or []
    shape = str(state.get("shape"))
    unit_cells = footprint(shape, 0.0, 0.0)
    if to_frame is None or len(pose) < 2 or unit_cells is None:
        return None
    here = to_frame(float(pose[0]), float(pose[1]))
    units = [u for name, other in drawing.seen.items() if name != block for u in unit_centres(other, to_frame)]
    width = len(unit_cells)
    xs, ys = [c[0] for c in cells], [c[1] for c in cells]
    points = []
    for cy in range(math.floor(min(ys)) - ASIDE_RANGE, math.ceil(max(ys)) + ASIDE_RANGE + 1):
        for cx in range(math.floor(min(xs)) - ASIDE_RANGE, math.ceil(max(xs)) + ASIDE_RANGE + 1):
            centre = (cx + (width - 1) / 2.0, float(cy))
            covered = footprint(shape, *centre) or []
            if any(_chebyshev(f, c) < 2.0 for f in covered for c in cells):
                continue  # on the drawing or right beside it
            if any(_chebyshev(f, u) < 1.2 for f in covered for u in [*units, *taken]):
                continue
            points.append((math.hypot(centre[0] - here[0], centre[1] - here[1]), centre))
    check = getattr(world, "put_down_problem", None)
    for _, centre in sorted(points)[:ASIDE_CHECKS]:
        if check is None or check(block, frame, centre[0], centre[1]) is None:
            return centre
    return None


def _chebyshev(a: Cell, b: Cell) -> float:
    return max(abs(a[0] - b[0]), abs(a[1] - b[1]))


def acyclic_order(binding: Mapping[str, Tile], lying: Mapping[str, set[Cell]], step_of: Mapping[Cell, int]
                  ) -> list[str] | None:
    """The blocks of ``binding`` in an order where each is put down after every other block lying on its tile's
    cells has moved (ties: the plan's step order of the cells); ``None`` when that needs a cycle."""
    after = {block: {other for other in binding if other != block and lying.get(other, set()) & set(tile[2])}
             for block, tile in binding.items()}
    order: list[str] = []
    left = set(binding)
    while left:
        ready = [b for b in left if not after[b] & left]
        if not ready:
            return None
        first = min(ready, key=lambda b: (min(step_of.get(c, 0) for c in binding[b][2]), b))
        order.append(first)
        left.remove(first)
    return order


def _proposal(drawing: Drawing, placements: Sequence[tuple[int, str, list[Cell]]], found: Found,
              lying: Mapping[str, set[Cell]], relaxed: str | None, context: Any, vector: Any) -> RepairProposal:
    binding, moves, aside = found
    step_of = {c: step for step, _, cs in placements for c in cs}
    done = {block for _, block, _ in drawing.done}
    actions = [_place(drawing, b, aside[b]) for b in aside] + [_place(drawing, b, binding[b][1]) for b in moves]
    moved = sorted(b for b in [*aside, *moves] if b in done)
    start, end = drawing.todo[0][0], drawing.todo[-1][0] + 1
    planned = {p[1] for p in placements}
    other = sorted(b for b in binding if relaxed is not None and b not in planned
                   and drawing.seen[b].get("colour") != relaxed)
    shown = "; ".join(f"{a[0]}({', '.join(a[1:])})" for a in actions)
    note = f" ({', '.join(other)} not {relaxed}: no {relaxed} block can stand in)" if other else ""
    evidence: dict[str, Any] = {
        "matcher": "tiling", "retiling": True, "vector": vector.to_dict() if hasattr(vector, "to_dict") else None,
        "cells": [list(c) for p in placements for c in p[2]], "moved": moved,
        "kept": sorted(b for b in binding if b not in moves),
        "set_aside": {b: list(where) for b, where in aside.items()},
        "in_the_way": {n: sorted(list(c) for c in v) for n, v in lying.items()},
        "colour_required": drawing.colour, "other_colour": other}
    replay = _replay_plan(drawing, binding, step_of, context)
    if replay is not None:
        evidence["replay_plan"] = replay
    else:
        evidence["keep"] = False  # the repaired plan places a block twice: it does not replay from the start
    return RepairProposal(
        SPLICE, round(SCORE - (OTHER_COLOUR if other else 0.0), 4),
        f"the drawing's {len(step_of)} cells tiled anew, moving {', '.join(moved) or 'no'} placed block(s)"
        + (f", setting {', '.join(aside)} aside" if aside else "") + f": {shown}{note}",
        changes={"start": start, "end": end, "actions": actions, "facts": _undone(drawing, moved, context)},
        evidence=evidence)


def _undone(drawing: Drawing, moved: Sequence[str], context: Any) -> dict[str, list[list[str]]]:
    """The facts that undo the executed placements of ``moved`` (their add effects deleted, their deletes added)."""
    domain = getattr(getattr(context, "run", None), "domain", None)
    primitive = getattr(domain, "primitives", {}).get(drawing.action)
    add: list[list[str]] = []
    delete: list[list[str]] = []
    if primitive is None:
        return {"add": add, "delete": delete}
    for record in drawing.records:
        args = [str(a) for a in record.get("args") or []]
        if not record.get("done") or str(record.get("action")) != drawing.action or not args or args[0] not in moved:
            continue
        try:
            added, deleted = primitive.effects(primitive.ground(args).bindings)
        except (BtMetaError, KeyError, TypeError, ValueError):  # effects that need the state: left as they are
            continue
        delete += [list(map(str, f)) for f in added]
        add += [list(map(str, f)) for f in deleted]
    return {"add": add, "delete": delete}


def _replay_plan(drawing: Drawing, binding: Mapping[str, Tile], step_of: Mapping[Cell, int], context: Any
                 ) -> list[list[str]] | None:
    """The new tiling drawn from the problem's start: every tile in an order where no block lands on one lying
    there when the run started; ``None`` when an executed step is not one of the drawing's placements (a turn the
    replay would miss) or no such order exists."""
    if any(r.get("done") and str(r.get("action")) != drawing.action for r in drawing.records):
        return None
    start = getattr(getattr(context, "run", None), "start_objects", None) or {}
    shaped = {str(n): dict(v) for n, v in start.items() if isinstance(v, Mapping) and v.get("shape")}
    cells = [c for tile in binding.values() for c in tile[2]]
    lying = cells_in_the_way(drawing.world, str(drawing.frame), shaped, cells)
    order = acyclic_order(binding, lying, step_of)
    if order is None:
        return None
    return [_place(drawing, b, binding[b][1]) for b in order]


def _place(drawing: Drawing, block: str, centre: Cell) -> list[str]:
    """The drawing's placement of ``block`` with its centroid at ``centre``, as a plan step."""
    return [drawing.action, block, coordinate_text(centre[0]), coordinate_text(centre[1])]
