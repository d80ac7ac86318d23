"""The shipped failure-taxonomy rules, as a plain ``bt_meta_classify_failure`` plugin (DESIGN.md, paper 6.4, 7.3).

The first rule that applies decides; a failure no rule speaks about keeps the kind its monitor or skill gave it.
Another plugin overrides these rules with ``@hookimpl(tryfirst=True)`` or by answering first.

Rules, in order:

1. ``internal`` and ``precondition`` failures keep their kind (a raising plugin; a symbolic precondition).
2. **collision** -- the evidence names a colliding pair or contacts (``colliding_pair``, ``collision``, ``contacts``).
3. **reachability** -- the evidence names an unreachable target or a failed IK (``unreachable_target``,
   ``ik_failed``, ``ik: "failed"``), or the message says no IK / unreachable / out of workspace / singular.
4. **verification** -- a verifier produced it (``verifier`` in the evidence), or the failing step belongs to a
   task whose name starts with ``verify`` (``localisation.ancestors``, filled in by the meta-reasoner).
5. **unknown_entity** -- the evidence lists ``unknown_entities``, a mismatch's expectation plugin suggests it (the
   grid-map plugin does when the block seen has another shape than the one expected), or an expected atom names an
   object the world no longer reports while the world reports objects the problem does not know (section 6.4's
   missing 1x2 block).
6. **physical** -- an expected atom about the gripper (``held``, ``holding``, ``grasped``, ``in_hand``,
   ``gripper``) did not come true, or the message says the object was dropped, lost or slipped.
7. **unexpected_configuration** -- any other expectation mismatch (known entities, unseen configuration), unless
   the mismatch's plugin suggested another kind of the taxonomy, which is then kept.

Offers:

* :func:`classify` -- the rules as a function ``(failure, mismatches, context) -> kind | None``
* :func:`bt_meta_classify_failure` -- the hook
"""

from __future__ import annotations

import re
from typing import Any

from bt_meta.bt.failures import FailureKind
from bt_meta.plugins import hookimpl

_UNREACHABLE = re.compile(r"\b(no ik|ik failed|unreachable|out of (the )?workspace|singular)", re.IGNORECASE)
_PHYSICAL_MESSAGE = re.compile(r"\b(dropped|lost|slipped|not held|never held)\b", re.IGNORECASE)
_GRIPPER_PREDICATES = re.compile(r"^(held|holding|grasped|in_hand|gripper)\b")
_ATOM = re.compile(r"^\s*([\w\-]+)\s*\((.*)\)\s*$")


def _atoms(mismatches: list[Any]) -> list[tuple[str, list[str]]]:
    atoms = []
    for mismatch in mismatches:
        evidence = getattr(mismatch, "evidence", None) or {}
        for text in evidence.get("missing", []):
            match = _ATOM.match(str(text))
            if match:
                atoms.append((match[1], [a.strip() for a in match[2].split(",") if a.strip()]))
    return atoms


def _observed_objects(context: Any) -> set[str] | None:
    world = getattr(context, "world", None)
    observe = getattr(world, "observe", None)
    if observe is None:
        return None
    try:
        objects = observe().get("objects")
    except Exception:  # a world that cannot observe says nothing about entities
        return None
    return set(objects) if objects else None


def _known_objects(context: Any, observed: set[str]) -> tuple[set[str], set[str]]:
    """The problem's objects, and those of them the world should report: the objects of every type of which the
    world reports at least one (cells, poses and other symbols are never observed)."""
    run = getattr(context, "run", None)
    problem = getattr(run, "problem", None)
    objects = getattr(problem, "objects", None) or {}
    known = {name for names in objects.values() for name in names}
    observable = {name for names in objects.values() if observed.intersection(names) for name in names}
    return known, observable


def _suggested_kinds(mismatches: list[Any]) -> list[FailureKind]:
    """The kinds expectation plugins suggested for their mismatches, in order, ignoring names outside the taxonomy."""
    kinds = []
    for mismatch in mismatches:
        suggested = (getattr(mismatch, "evidence", None) or {}).get("suggested_kind")
        if suggested is None:
            suggested = getattr(getattr(mismatch, "expectation", None), "failure_kind", None)
        try:
            kinds.append(FailureKind(suggested))
        except ValueError:
            continue
    return kinds


def classify(failure: Any, mismatches: list[Any], context: Any) -> FailureKind | None:
    kind = failure.kind
    if kind in (FailureKind.INTERNAL, FailureKind.PRECONDITION):
        return None
    evidence = failure.evidence or {}
    if any(evidence.get(key) for key in ("colliding_pair", "collision", "contacts")):
        return FailureKind.COLLISION
    ik = evidence.get("ik")
    if evidence.get("unreachable_target") is not None or evidence.get("ik_failed") or ik in ("failed", False) \
            or _UNREACHABLE.search(failure.message or ""):
        return FailureKind.REACHABILITY
    ancestors = (evidence.get("localisation") or {}).get("ancestors") or []
    if evidence.get("verifier") or any(str(a.get("task", [""])[0]).lower().startswith("verify") for a in ancestors):
        return FailureKind.VERIFICATION
    suggested = _suggested_kinds(mismatches)
    if any((getattr(m, "evidence", None) or {}).get("unknown_entities") for m in mismatches) \
            or evidence.get("unknown_entities") or FailureKind.UNKNOWN_ENTITY in suggested:
        return FailureKind.UNKNOWN_ENTITY
    atoms = _atoms(mismatches)
    observed = _observed_objects(context) if atoms else None
    if observed is not None:
        known, observable = _known_objects(context, observed)
        unknown = observed - known if known else set()
        missing = {arg for _, args in atoms for arg in args if arg in observable and arg not in observed}
        if missing and unknown:
            failure.evidence["missing_entities"] = sorted(missing)
            failure.evidence["unknown_entities"] = sorted(unknown)
            return FailureKind.UNKNOWN_ENTITY
    if any(_GRIPPER_PREDICATES.match(pred) for pred, _ in atoms) or _PHYSICAL_MESSAGE.search(failure.message or ""):
        return FailureKind.PHYSICAL
    if mismatches:
        return suggested[0] if suggested else FailureKind.UNEXPECTED_CONFIGURATION
    return None


@hookimpl
def bt_meta_classify_failure(failure: Any, mismatches: list[Any], context: Any) -> FailureKind | None:
    return classify(failure, mismatches, context)
