"""Spares: an entity the plan needs is missing and another object on the table can stand in for it, one for one.

No experience is needed: the method that chose the missing entity says what it must be. Its precondition is
checked again with the spare in the missing entity's place, in the state the method started from (the world's
symbolic state with the method's executed steps undone) plus the spare's perceived facts. So the spare must have
the colour only when the method's symbols ask for a colour (``usable(?b, 1x1, blue)``), its shape only when they
ask for a shape; a method that binds the entity without conditions on it takes any free object of its type. A
colour the methods name is a preference (``colours="prefer"``, the default): when no spare has it, the spares
that meet the conditions but for their colour are proposed, scored lower, saying so -- the drawing is its cells,
as the paper's red bar standing in for the blue one is (section 6.4). ``colours="require"`` never does. An object
a failure of the run found out of reach where it lies (the vector's ``unusable``) is no spare. Among spares
that fit alike, one lying on a cell a placement still to run fills is taken first: it must be moved anyway, and as
the stand-in it clears the way (a green 1x1 on the cell of A's b3 when b0 is missing and the other green 1x1 lies
off the drawing: letters_A s0 0101 was repaired only because the names happened to sort that way).

A spare is an object the world reports (``observe()["objects"]`` with a ``shape``) that no step of the plan uses
and that is not itself missing; unknown objects (not in the problem) get the missing entity's unary facts
(type, availability) and their own perceived ``shape`` and ``colour``, as :mod:`object_substitution` anchors them.

Offers:

* :func:`spare_proposals` -- ``substitute`` proposals for a mismatch vector (best first)
* :func:`spare_fits` -- whether one spare meets the conditions of the methods that chose the missing entity
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from bt_meta_plugins._grounding_spares import frame_supports
from bt_meta_plugins._tilings import cells_in_the_way, read_drawing

from bt_meta.bt.failures import RepairProposal
from bt_meta.errors import BtMetaError
from bt_meta.meta.proposals import SUBSTITUTE

SCORE = 0.85
"""Above the memory-based matches' best (0.9 - distance) only when they are far; ranked by name after."""
OTHER_COLOUR = 0.1
"""Taken off the score of a substitution whose spare has another colour than the methods name."""
PARTIAL = 0.3
"""Taken off the score of a substitution that leaves a missing entity a later step names without a stand-in: it
mends the failed step, and the plan still fails at that one, with the spare used up (letters_A 0098: b1 and b3
missing, one spare 1x1; the spare went to b1, and a tiling of the rest with the 1x2 blocks was then out of reach).
Below the tilings' score, which cover every cell still to fill."""

__all__ = ["spare_fits", "spare_proposals"]


def _used(plan: Sequence[Mapping[str, Any]]) -> set[str]:
    return {str(a) for step in plan for a in step.get("args") or []}


def _perceived_facts(name: str, seen: Mapping[str, Any], template: Iterable[str]) -> list[tuple[str, ...]]:
    facts = [(predicate, name) for predicate in template]
    for attribute in ("shape", "colour"):
        if seen.get(attribute) is not None:
            facts.append((attribute, name, str(seen[attribute])))
    return facts


def _undo_steps(state: Any, domain: Any, plan: Sequence[Mapping[str, Any]], steps: Iterable[int]) -> Any:
    """``state`` with the effects of the done ``steps`` undone (latest first): where the method started."""
    by_step = {int(p["step"]): p for p in plan}
    for step in sorted(steps, reverse=True):
        record = by_step.get(step)
        if record is None or not record.get("done"):
            continue
        primitive = domain.primitives.get(record["action"])
        if primitive is None:
            continue
        try:
            add, delete = primitive.effects(dict(zip(primitive.parameters, map(str, record["args"]), strict=False)))
        except (KeyError, TypeError, ValueError):  # effects bound by the precondition: cannot be undone here
            continue
        state = state.apply(add=[tuple(f) for f in delete], delete=[tuple(f) for f in add])
    return state


def _in_the_way(vector: Any, failure: Any, context: Any, spares: Mapping[str, Mapping[str, Any]]) -> set[str]:
    """The ``spares`` lying on a cell a placement still to run fills (none when the steps left are no drawing)."""
    drawing = read_drawing(vector, failure, context)
    if drawing is None or drawing.frame is None:
        return set()
    return set(cells_in_the_way(drawing.world, drawing.frame, spares, drawing.cells))


def spare_fits(spare: str, missing: str, facts: Sequence[tuple[str, ...]], methods: Sequence[Mapping[str, Any]],
               plan: Sequence[Mapping[str, Any]], domain: Any, state: Any, external: Any = None,
               replaced: Mapping[str, str] | None = None, any_colour: bool = False) -> tuple[bool, str]:
    """Whether ``spare`` (perceived as ``facts``) meets every condition the methods that chose ``missing`` put on
    it; ``replaced`` are other substitutions made in the same proposal; ``any_colour``: checked as if it had the
    missing entity's colour. Returns ``(fits, why)``."""
    mapping = {**dict(replaced or {}), missing: spare}
    choosing = [m for m in methods if missing in (m.get("bindings") or {}).values()]
    if not choosing:
        return False, f"no method of the plan chose {missing}: its conditions are unknown"
    by_name = {m.name: m for m in domain.methods}
    present = {tuple(f) for f in state}
    for record in choosing:
        method = by_name.get(record.get("method"))
        if method is None:
            return False, f"method {record.get('method')!r} is not in the domain"
        start = _undo_steps(state, domain, plan, record.get("steps") or [])
        start = start.apply(add=[f for f in facts if f not in present],
                            delete=[f for f in present if f[0] in ("shape", "colour") and f[1] == spare
                                    and f not in facts])
        if any_colour:
            held = [tuple(f) for f in start]
            start = start.apply(add=[("colour", spare, f[2]) for f in held if f[0] == "colour" and f[1] == missing],
                                delete=[f for f in held if f[0] == "colour" and f[1] == spare])
        env = {k: mapping.get(v, v) for k, v in (record.get("bindings") or {}).items()}
        try:
            holds = method.precondition.holds(start, env, external)
        except BtMetaError as error:
            return False, f"method {method.name}: precondition not checkable: {error}"
        if not holds:
            return False, f"method {method.name} needs {method.precondition.source} (with {missing} -> {spare})"
    return True, "meets " + "; ".join(f"{r['method']}" for r in choosing)


def spare_proposals(vector: Any, failure: Any, context: Any, limit: int = 3, colours: str = "prefer"
                    ) -> list[RepairProposal]:
    """``substitute`` proposals: every missing entity a step still to run uses, each given a spare that meets its
    methods' conditions (one proposal with all of them), then the other fitting spares of the first one. With
    ``colours="prefer"``, a missing entity no spare fits gets the spares that would fit in its colour, scored
    :data:`OTHER_COLOUR` lower (``require``: never). One that leaves a missing entity without a spare is scored
    :data:`PARTIAL` lower."""
    evidence = getattr(failure, "evidence", None) or {}
    plan = list(evidence.get("plan") or [])
    methods = list(evidence.get("methods") or [])
    run = getattr(context, "run", None)
    domain = getattr(run, "domain", None)
    world = getattr(context, "world", None)
    if not plan or domain is None or world is None:
        return []
    observe = getattr(world, "observe", None)
    symbolic = getattr(world, "symbolic_state", None)
    if observe is None or symbolic is None:
        return []
    seen = {str(k): dict(v) for k, v in ((observe() or {}).get("objects") or {}).items()
            if isinstance(v, Mapping) and v.get("shape")}
    state = symbolic()
    external = getattr(run, "external", None)
    problem = getattr(run, "problem", None)
    initial = list(getattr(problem, "state", None) or getattr(problem, "init", None) or ())
    missing_names = {e.name for e in vector.missing}
    used = _used(plan)
    unusable = set(getattr(vector, "unusable", ()) or ())
    spares = sorted(n for n in seen if n not in used and n not in missing_names and n not in unusable
                    and n not in frame_supports(world))
    todo = [p for p in plan if not p.get("done")]
    wanted = [e.name for e in vector.missing if any(e.name in map(str, p["args"]) for p in todo)]
    if not wanted or not spares:
        return []
    lying = _in_the_way(vector, failure, context, {n: seen[n] for n in spares})
    spares.sort(key=lambda n: n not in lying)  # stable: by name within
    first = {m: min(int(p["step"]) for p in todo if m in map(str, p["args"])) for m in wanted}
    known = {str(f[1]) for f in initial if len(f) >= 2}

    def facts_of(spare: str, missing: str) -> list[tuple[str, ...]]:
        if spare in known:  # the problem knows it: its facts are the world's
            return []
        template = sorted({str(f[0]) for f in initial if len(f) == 2 and str(f[1]) == missing})
        return _perceived_facts(spare, seen[spare], template)

    fitting: dict[str, list[tuple[str, str]]] = {}
    recoloured: set[str] = set()  # missing entities only a spare of another colour fits
    for missing in wanted:
        for any_colour in (False, True) if colours == "prefer" else (False,):
            for spare in spares:
                ok, why = spare_fits(spare, missing, facts_of(spare, missing), methods, plan, domain, state,
                                     external, any_colour=any_colour)
                if ok:
                    fitting.setdefault(missing, []).append((spare, why + (" but for its colour" if any_colour
                                                                          else "")))
            if missing in fitting:
                if any_colour:
                    recoloured.add(missing)
                break
    if not fitting:
        return []
    # one proposal replacing every missing entity that has a spare (greedy, in name order, each spare once)
    joint: dict[str, str] = {}
    for missing in sorted(fitting):
        for spare, _ in fitting[missing]:
            if spare in joint.values():
                continue
            facts = facts_of(spare, missing)
            if spare_fits(spare, missing, facts, methods, plan, domain, state, external, joint,
                          any_colour=missing in recoloured)[0]:
                joint[missing] = spare
                break
    candidates: list[dict[str, str]] = [joint] if joint else []
    head = sorted(fitting)[0]
    candidates += [{head: spare} for spare, _ in fitting[head] if {head: spare} not in candidates]
    out = []
    localisation = evidence.get("localisation") or {}
    failed = localisation.get("step", getattr(failure, "step", None))
    for rank, mapping in enumerate(candidates[:limit]):
        from_step = min(first[m] for m in mapping)
        if failed is not None:  # a substitution renames from its step on: from the failed step is the same
            from_step = min(from_step, int(failed))
        pairs = ", ".join(f"{m} -> {s}" for m, s in sorted(mapping.items()))
        reasons = {m: next(why for s, why in fitting[m] if s == mapping[m]) for m in mapping}
        other = sorted(m for m in mapping if m in recoloured)
        note = (f" (but for the colour of {', '.join(mapping[m] for m in other)}: no spare of the colour the methods "
                "name)") if other else ""
        left = sorted(m for m in wanted if m not in mapping)
        if left:
            note += f"; leaves {', '.join(left)} without a stand-in"
        out.append(RepairProposal(
            SUBSTITUTE, round(SCORE - 0.01 * rank - (OTHER_COLOUR if other else 0.0) - (PARTIAL if left else 0.0), 4),
            f"substitute the spare(s) {pairs}: seen on the table, unused by the plan, and they meet the conditions of "
            f"the methods that chose the missing entities{note}",
            changes={"mapping": dict(sorted(mapping.items())), "from_step": from_step},
            evidence={"matcher": "spares", "vector": vector.to_dict(), "fits": reasons, "other_colour": other,
                      "left_without_stand_in": left, "spares": {m: [s for s, _ in fitting[m]] for m in fitting}}))
    return out
