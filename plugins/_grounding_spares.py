"""Spares for a part the plan names only through the grounding: rebind the symbol, not the plan's arguments.

The magnetic attach plan moves to poses (``MoveTo(active_above)``); the part enters only through the grounding
file -- ``active_above: {above: active_part}`` and ``objects: {active_part: active}``. When the world has no
``active`` but another object of the same type stands unused on the table (a spare), renaming plan arguments (what
:mod:`bt_meta_plugins._spares` does) has nothing to rename. The repair here rebinds the grounding symbol
(``active_part -> spare_active``): every pose derived from it follows, and so do the monitors and plugins that ask
the world for the symbol's object.

Which symbols are entities: the problem's objects that are not poses and not features of the grounding (as the
simulator itself checks a nominal scene). One is *missing* when the world does not report the object it grounds
to, or a failure of the run found that object out of reach where it lies (``out_of_reach``), and a step still to
run uses it -- as an argument, or through the pose or feature an argument names. An object out of reach is no
spare.

A spare fits when it is reported by the world, no entity symbol grounds to it, no step of the plan names it, it is
not held, and its type is the type the missing object has in the nominal part of the world's scene (a variant
removes the object from what is built, not from the scene's nominal list). Colour
counts only when the problem's facts give the symbol one (``colour(sym, c)``); the magnetic and housing task
files give none, so a spare of another colour fits.

Offers:

* :func:`entity_symbols` -- task-file symbol -> world object, for the entity symbols of a problem
* :func:`demonstrated_types` -- world object -> type in the nominal part of the world's scene
* :func:`rebind_proposals` -- ``rebind`` proposals for a failure (best first)
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from bt_meta_plugins._mismatch import out_of_reach

from bt_meta.bt.failures import RepairProposal
from bt_meta.meta.proposals import REBIND

SCORE = 0.86
"""Just above the plan-argument spares (0.85): when a symbol can be rebound, nothing needs renaming."""

__all__ = ["demonstrated_types", "entity_symbols", "rebind_proposals"]


def entity_symbols(world: Any, problem: Any) -> dict[str, str]:
    """Task-file symbol -> world object for the problem's objects that are not poses or grounding features."""
    grounding = getattr(world, "grounding", None)
    objects = getattr(problem, "objects", None) or {}
    if grounding is None or not isinstance(objects, Mapping):
        return {}
    features = getattr(grounding, "features", None) or {}
    names = getattr(grounding, "objects", None) or {}
    return {str(s): str(names.get(s, s)) for kind, group in objects.items() if kind != "pose"
            for s in group if s not in features}


def demonstrated_types(world: Any) -> dict[str, str]:
    """Object name -> type in the nominal part of the world's scene (what a variant removes is still listed there:
    the scene the task was demonstrated on); ``{}`` for a world without a scene."""
    objects = getattr(getattr(world, "scene", None), "objects", None) or ()
    return {str(o.name): str(o.type) for o in objects if getattr(o, "type", None)}


def _used_symbols(world: Any, step: Mapping[str, Any]) -> set[str]:
    """The symbols a step uses: its arguments and what the poses and features among them are defined by."""
    used = {str(a) for a in step.get("args") or []}
    pose_spec = getattr(world, "pose_spec", None)
    grounding = getattr(world, "grounding", None)
    poses = getattr(grounding, "poses", None) or {}
    features = getattr(grounding, "features", None) or {}
    for arg in list(used):
        spec = poses.get(arg) if pose_spec is not None else None
        for key in ("above", "object"):
            if isinstance(spec, Mapping) and spec.get(key) is not None:
                used.add(str(spec[key]))
        if isinstance(spec, Mapping) and spec.get("above_feature") in features:
            used.add(str(features[spec["above_feature"]].get("object")))
        if arg in features:
            used.add(str(features[arg].get("object")))
    return used


def _colour_of(problem: Any, symbol: str) -> str | None:
    facts = getattr(problem, "init", None) or getattr(problem, "state", None) or ()
    return next((str(f[2]) for f in facts if len(f) == 3 and f[0] == "colour" and str(f[1]) == symbol), None)


def frame_supports(world: Any) -> set[str]:
    """The objects the grounding's frames name as ``support:`` (a tray, the block parts are stacked on): where
    parts are put, so never a spare standing in for one (placed onto itself, the stacking "succeeded")."""
    frames = getattr(getattr(world, "grounding", None), "frames", None) or {}
    return {str(spec["support"]) for spec in frames.values() if spec.get("support")}


def rebind_proposals(failure: Any, context: Any, limit: int = 3, *, failed_step_only: bool = False
                     ) -> list[RepairProposal]:
    """``rebind`` proposals: each missing entity symbol a step still to run uses -- with ``failed_step_only``, the
    failed step itself (a motion failure of a step that does not use the missing part is not its doing: rebinding
    then leaves the failed step as it was and runs it again) -- bound to a fitting spare."""
    world = getattr(context, "world", None)
    run = getattr(context, "run", None)
    problem = getattr(run, "problem", None)
    observe = getattr(world, "observe", None)
    if world is None or problem is None or observe is None or getattr(world, "rebind_object", None) is None:
        return []
    evidence = getattr(failure, "evidence", None) or {}
    plan = list(evidence.get("plan") or [])
    seen = {str(k): dict(v) for k, v in ((observe() or {}).get("objects") or {}).items() if isinstance(v, Mapping)}
    symbols = entity_symbols(world, problem)
    todo = [p for p in plan if not p.get("done")]
    uses = {int(p["step"]): _used_symbols(world, p) for p in todo}
    unusable = out_of_reach(failure, context)
    localisation = evidence.get("localisation") or {}
    failed = localisation.get("step", getattr(failure, "step", None))
    if failed_step_only and failed is not None:
        uses_failed = uses.get(int(failed), set())
        wanted_uses = [uses_failed]
    else:
        wanted_uses = list(uses.values())
    missing = {s: o for s, o in symbols.items() if (o not in seen or o in unusable)
               and any(s in u for u in wanted_uses)}
    if not missing:
        return []
    named = {str(a) for p in plan for a in p.get("args") or []}
    bound = set(symbols.values()) | named
    held = {str(v) for v in ((observe() or {}).get("held") or {}).values() if v}
    spares = sorted(n for n in seen if n not in bound and n not in held and n not in unusable
                    and n not in frame_supports(world))
    types = demonstrated_types(world)
    out: list[RepairProposal] = []
    for symbol, obj in sorted(missing.items()):
        wanted = types.get(obj)
        if wanted is None:  # what the missing object was is unknown: no spare can be said to fit
            continue
        colour = _colour_of(problem, symbol)
        fitting = [n for n in spares if seen[n].get("type") == wanted
                   and (colour is None or str(seen[n].get("colour")) == colour)]
        first = min(step for step, u in uses.items() if symbol in u)
        from_step = first if failed is None else min(first, int(failed))
        for rank, spare in enumerate(fitting[:limit]):
            out.append(RepairProposal(
                REBIND, round(SCORE - 0.01 * rank, 4),
                f"rebind {symbol} -> {spare}: {obj} is "
                f"{'out of reach where it lies' if obj in unusable else 'not on the table'}; {spare} is on the table, "
                f"unused, of the same type "
                f"({wanted})" + (f" and colour ({colour})" if colour else ""),
                changes={"symbols": {symbol: spare}, "from_step": from_step},
                evidence={"matcher": "grounding_spares", "missing": {symbol: obj}, "type": wanted,
                          "colour_required": colour, "spares": fitting}))
    return out
