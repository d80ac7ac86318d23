"""What a repair may not change: the verification steps of the plan and the goal it is verified against.

A repair changes how a task is done, never what counts as done (``docs/meta-reasoning.md``, "What a repair may
change"). The executor checks every proposal, whatever plugin made it, before it applies one, and every learned
refinement before it plans with it.

Offers:

* :func:`declared_checks` -- the checks a grounding declares on a symbol (a pose with ``verify_lifted``)
* :func:`is_verification` -- whether a plan step verifies: it is under a task named ``verify...``, or one of its
  arguments carries a declared check
* :func:`verification_calls` -- the verification steps of a plan, as calls, in order
* :func:`missing_verifications` -- the verification calls of one plan another does not run (in order)
* :func:`touched_entities` -- the objects a repair changed what is known about (perceived facts, a substitution,
  a rebinding): the only ones a goal fact may be rewritten for
* :func:`weakened_goal` -- the goal facts a rewritten goal drops without a changed entity to account for them
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = ["declared_checks", "is_verification", "missing_verifications", "touched_entities",
           "verification_calls", "weakened_goal"]

Call = tuple[str, ...]


def declared_checks(world: Any, symbol: str) -> list[str]:
    """The checks the world's grounding declares on ``symbol``: ``world.declared_checks(symbol)`` when the world
    offers it, else the keys named ``verify...`` of its pose entry (``verify_lifted``); none for other symbols."""
    offered = getattr(world, "declared_checks", None)
    if offered is not None:
        try:
            return [str(c) for c in offered(symbol) or ()]
        except Exception:  # a symbol the world does not know: nothing declared on it
            return []
    spec_of = getattr(world, "pose_spec", None)
    if spec_of is None:
        return []
    try:
        spec = spec_of(symbol)
    except Exception:  # not a pose symbol (an object, a cell): nothing declared on it
        return []
    return sorted(str(k) for k in spec if str(k).lower().startswith("verify") and spec[k]) \
        if isinstance(spec, Mapping) else []


def is_verification(world: Any, call: Sequence[Any], tasks: Iterable[Any] = ()) -> bool:
    """Whether a step (``call`` = action and arguments, ``tasks`` the compound tasks above it) verifies."""
    if any(str(t).lower().startswith("verify") for t in tasks):
        return True
    return any(declared_checks(world, str(arg)) for arg in call[1:])


def verification_calls(world: Any, plan_state: Any, from_step: int = 0) -> list[Call]:
    """The verification steps of ``plan_state`` (a :class:`~bt_meta.meta.proposals.PlanState`) from step
    ``from_step`` on, as calls, in plan order."""
    tree = plan_state.tree
    out = []
    for node in plan_state.steps():
        if node.step is None or node.step < from_step:
            continue
        tasks = [a.task[0] for a in tree.ancestors(node.id)]
        call = tuple(str(a) for a in node.task)
        if is_verification(world, call, tasks):
            out.append(call)
    return out


def missing_verifications(needed: Sequence[Call], plan: Sequence[Sequence[Any]]) -> list[Call]:
    """The calls of ``needed`` that ``plan`` (calls) does not run in that order (a subsequence match)."""
    steps = [tuple(str(a) for a in s) for s in plan]
    at, missing = 0, []
    for call in needed:
        found = next((i for i in range(at, len(steps)) if steps[i] == tuple(call)), None)
        if found is None:
            missing.append(tuple(call))
        else:
            at = found + 1
    return missing


def _entity(arg: str) -> bool:
    try:
        float(arg)
    except ValueError:
        return True
    return False  # a number (a cell, a coordinate) is no entity


def touched_entities(facts: Iterable[Sequence[Any]] = (), mappings: Iterable[Mapping[str, Any]] = ()) -> set[str]:
    """The entities a repair changed what is known about: the arguments of the facts it wrote (perceived shapes,
    colours, availability), and both sides of its substitutions and rebindings; numbers are no entities."""
    out = {str(a) for fact in facts for a in list(fact)[1:] if _entity(str(a))}
    for mapping in mappings:
        out |= {str(k) for k in mapping} | {str(v) for v in mapping.values()}
    return out


def weakened_goal(goal: Iterable[Sequence[Any]], rewritten: Iterable[Sequence[Any]],
                  touched: set[str]) -> list[Call]:
    """Facts of ``goal`` that ``rewritten`` drops although they name no touched entity: the repair would change
    what counts as done (a pose rewritten under a goal ``at(show)``), not which entities it is done with."""
    kept = {tuple(str(a) for a in g) for g in rewritten}
    dropped = [tuple(str(a) for a in g) for g in goal if tuple(str(a) for a in g) not in kept]
    return [g for g in dropped if not touched.intersection(g[1:])]
