"""The mismatch vector of object substitution (paper, section 6.4, step 1): the failed step, the entities the plan
needs that the world does not show as assumed (missing), and the ones it shows instead (unknown).

An object a skill of this run could not reach where it lies (a failure's ``out_of_reach``: the move to pick it up
has no IK solution) is of no use wherever it is: it counts as missing when the plan names it, and is never
offered as a stand-in (``unusable``).

Offers:

* :class:`Entity` -- a block as the plan assumes it or as it is seen (name, shape, colour)
* :class:`MismatchVector` -- the failed step, missing and unknown entities, the monitor's grid-map records
* :func:`mismatch_vector` -- the vector for a failure and its context (``None`` when nothing is missing)
* :func:`attributes` -- (shape, colour) per object from ``shape``/``colour`` facts
* :func:`out_of_reach` -- the objects a failure of the run could not reach where they lie
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["Entity", "MismatchVector", "attributes", "mismatch_vector", "out_of_reach"]


@dataclass(frozen=True)
class Entity:
    """A block as the plan assumes it (missing) or as it is seen (unknown)."""

    name: str
    shape: str | None
    colour: str | None

    def describe(self) -> str:
        return f"{self.name} ({self.colour or '?'} {self.shape or '?'})"


@dataclass(frozen=True)
class MismatchVector:
    """Step 1: the failed step, what is missing and what is seen instead."""

    step: int | None
    missing: tuple[Entity, ...]
    unknown: tuple[Entity, ...]
    maps: tuple[dict[str, Any], ...] = ()
    unusable: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        out = {"step": self.step, "missing": [e.describe() for e in self.missing],
               "unknown": [e.describe() for e in self.unknown]}
        if self.unusable:
            out["out_of_reach"] = list(self.unusable)
        return out


def out_of_reach(failure: Any, context: Any) -> set[str]:
    """The objects this failure or an earlier one of the run found out of reach where they lie."""
    run = getattr(context, "run", None)
    failures = [*(getattr(run, "failures", None) or []), failure]
    return {str(name) for f in failures
            if (name := (getattr(f, "evidence", None) or {}).get("out_of_reach"))}


def _problemattributes(problem: Any) -> dict[str, tuple[str | None, str | None]]:
    """(shape, colour) of every object the problem describes with ``shape``/``colour`` facts."""
    facts = getattr(problem, "init", None)
    if facts is None:
        facts = getattr(problem, "state", None) or ()
    return attributes(facts)


def attributes(facts: Iterable[Sequence[Any]]) -> dict[str, tuple[str | None, str | None]]:
    shapes: dict[str, str] = {}
    colours: dict[str, str] = {}
    for fact in facts:
        if len(fact) == 3 and fact[0] == "shape":
            shapes[str(fact[1])] = str(fact[2])
        elif len(fact) == 3 and fact[0] == "colour":
            colours[str(fact[1])] = str(fact[2])
    return {name: (shapes.get(name), colours.get(name)) for name in sorted(set(shapes) | set(colours))}


def _seen_objects(world: Any) -> dict[str, dict[str, Any]] | None:
    observe = getattr(world, "observe", None)
    if observe is None:
        return None
    objects = (observe() or {}).get("objects")
    if not isinstance(objects, Mapping):
        return None
    return {str(k): dict(v) for k, v in objects.items() if isinstance(v, Mapping) and v.get("shape")}


def mismatch_vector(failure: Any, context: Any) -> MismatchVector | None:
    """The failed step, the missing entities and the unknown ones seen; ``None`` when nothing is missing."""
    evidence = getattr(failure, "evidence", None) or {}
    maps = tuple(m for mismatch in evidence.get("mismatches") or [] for m in (mismatch.get("evidence") or {})
                 .get("maps") or [] if isinstance(m, Mapping))
    run = getattr(context, "run", None)
    assumed = _problemattributes(getattr(run, "problem", None))
    seen = _seen_objects(getattr(context, "world", None))
    missing: dict[str, Entity] = {}
    unknown: dict[str, Entity] = {}
    unusable = out_of_reach(failure, context)
    if seen is not None:
        for name, (shape, colour) in assumed.items():
            obj = seen.get(name)
            if obj is None or obj.get("shape") != shape or (colour is not None and obj.get("colour") != colour) \
                    or name in unusable:
                missing[name] = Entity(name, shape, colour)
        for name, obj in seen.items():
            if name in unusable and name not in assumed:  # a stand-in found out of reach: missing as it was seen
                missing[name] = Entity(name, str(obj.get("shape")), obj.get("colour"))
            elif (name not in assumed or name in missing) and name not in unusable:
                unknown[name] = Entity(name, str(obj.get("shape")), obj.get("colour"))
    for record in maps:  # the monitor's own account: a block seen with another form than remembered
        expected, observed = record.get("expected") or {}, record.get("observed") or {}
        name = record.get("object")
        if name and observed.get("block_seen") and observed.get("shape") != expected.get("shape") \
                and name not in missing:
            missing[str(name)] = Entity(str(name), expected.get("shape"), expected.get("colour"))
    for key, target in (("missing_entities", missing), ("unknown_entities", unknown)):
        for name in evidence.get(key) or []:
            if str(name) not in target:
                shape, colour = assumed.get(str(name), (None, None))
                if target is unknown and str(name) in unusable:
                    continue
                if target is unknown and seen is not None and str(name) in seen:
                    shape, colour = seen[str(name)].get("shape"), seen[str(name)].get("colour")
                target[str(name)] = Entity(str(name), shape, colour)
    if not missing:
        return None
    return MismatchVector(getattr(failure, "step", None), tuple(missing[n] for n in sorted(missing)),
                          tuple(unknown[n] for n in sorted(unknown)), maps, tuple(sorted(unusable)))


