"""The plan a learned refinement keeps, and whether a repaired run keeps one at all.

A refinement replays from the problem's start. The plan as run is kept unless a repair says its plan does not replay
from there: an attempt marked ``keep: False`` (it works only from where the run stood), or one whose plugin planned
the repair from the start itself (``evidence["replay_plan"]``: a re-orientation, a re-tiling) -- then that plan is
kept, with the repairs made after it carried over (each attempt records the steps it changed as they were,
``Attempt.replaced``), so no failed attempt, release or re-pick is replayed.

Offers:

* :func:`unkept_attempts` -- the attempts that keep a run from being saved as a refinement
* :func:`replayed` -- the report with the plan the refinement replays
* :func:`replaying` -- the attempt whose replay plan is kept, and that plan with the later repairs in it
* :func:`carried_over` -- one attempt's change made again in a plan
* :func:`replaced_steps` -- what :attr:`~bt_meta.meta.reasoner.Attempt.replaced` records for a proposal
* :func:`survives` -- whether an attempt's change is still in the final plan
"""

from __future__ import annotations

import dataclasses
from typing import Any

from bt_meta.meta.proposals import PlanState
from bt_meta.meta.reasoner import Attempt

__all__ = ["carried_over", "replaced_steps", "replayed", "replaying", "survives", "unkept_attempts"]


def unkept_attempts(attempts: list[Attempt], plan: list[list[str]]) -> list[int]:
    """The attempts (numbers) whose repair does not replay from the start as the run's refinement would: marked
    ``keep: False`` by their plugin, or with a ``replay_plan`` that is not the one replayed (:func:`replaying`)
    unless the plan as run replays as well (``as_run_replays``); attempts a later one undid do not count."""
    kept = (replaying(attempts) or (None,))[0]
    out = []
    for attempt in attempts:
        evidence = attempt.proposal.get("evidence") or {}
        if not survives(attempt, plan):
            continue
        if evidence.get("keep") is False or (evidence.get("replay_plan") and attempt is not kept
                                             and not evidence.get("as_run_replays")):
            out.append(attempt.number)
    return out


def replayed(report: Any) -> Any:
    """``report`` with the plan a refinement should replay: a ``replay_plan`` its plugin planned from the initial
    state (a re-orientation: not the failed attach, its release and the re-pick), with the repairs made after it
    carried over (:func:`replaying`), else the plan as run."""
    found = replaying(report.attempts)
    if found is None or report.attempts[-1].outcome != "repaired":
        return report
    return dataclasses.replace(report, plan=found[1])


def replaying(attempts: list[Attempt]) -> tuple[Attempt, list[list[str]]] | None:
    """The last attempt with a ``replay_plan`` and that plan with every later attempt's change made again in it:
    a rebinding changes no step; a splice replaces the steps it replaced (found by what they are, once); a
    backtrack or an argument rewrite gives each step it rewrote (found once) its new arguments (magnetic s1 0016:
    three turns, then the attach's pose); a substitution renames from the step it renamed from (letters_A s1 0118:
    b2 turned, then two blocks for the bar b5 out of reach). ``None`` when there is none, when another plugin's
    attempt came before it -- the replay plan, planned from the problem's initial state, knows nothing of what that
    changed (a letters block turned after a tiling replaced two 1x1 by a 1x2: replayed, the nominal 1x1 placements
    failed, letters_H s0 0005 0023 0056) --
    or when a later change cannot be found in it."""
    index = next((i for i in range(len(attempts) - 1, -1, -1)
                  if (attempts[i].proposal.get("evidence") or {}).get("replay_plan")), None)
    if index is None:
        return None
    first = attempts[index]
    if any(a.proposal.get("plugin") != first.proposal.get("plugin") for a in attempts[:index]):
        return None  # (an attempt whose evidence says ``as_run_replays`` then leaves the plan as run to be kept)
    plan: list[list[str]] | None = [[str(a) for a in step] for step in first.proposal["evidence"]["replay_plan"]]
    for later in attempts[index + 1:]:
        plan = carried_over(plan, later)
        if plan is None:
            return None
    return first, plan


def carried_over(plan: list[list[str]], attempt: Attempt) -> list[list[str]] | None:
    """``plan`` with ``attempt``'s change made in it (see :func:`replaying`), or ``None``."""
    action = attempt.proposal.get("action")
    changes = attempt.proposal.get("changes") or {}
    if action == "rebind":
        return plan
    if action in ("backtrack", "rewrite_args"):  # each rewritten step found once, its arguments replaced
        rewritten = changes.get("args") or {}
        new_args = ([rewritten[k] for k in sorted(rewritten, key=int)] if isinstance(rewritten, dict)
                    else [rewritten])
        if len(new_args) != len(attempt.replaced) or not attempt.replaced:
            return None
        out = [list(step) for step in plan]
        for old, args in zip(attempt.replaced, new_args, strict=True):
            found = [i for i, step in enumerate(plan) if step == old]
            if len(found) != 1:
                return None
            out[found[0]] = [old[0], *(str(a) for a in args)]
        return out
    where = [i for i in range(len(plan) - len(attempt.replaced) + 1)
             if attempt.replaced and plan[i:i + len(attempt.replaced)] == attempt.replaced]
    if len(where) != 1:
        return None
    at = where[0]
    if action == "splice":
        actions = [[str(a) for a in call] for call in changes.get("actions") or []]
        return [*plan[:at], *actions, *plan[at + len(attempt.replaced):]]
    if action == "substitute":
        mapping = {str(k): str(v) for k, v in (changes.get("mapping") or {}).items()}
        return [*plan[:at], *([step[0], *(mapping.get(a, a) for a in step[1:])] for step in plan[at:])]
    return None


def replaced_steps(proposal: Any, plan_state: PlanState, failed_step: int) -> list[list[str]]:
    """The steps ``proposal`` changes, as they are before it applies (:attr:`Attempt.replaced`)."""
    steps = plan_state.steps()
    changes = getattr(proposal, "changes", None) or {}
    try:
        if proposal.action == "splice":
            span = range(int(changes.get("start", failed_step)), int(changes.get("end", failed_step + 1)))
        elif proposal.action == "substitute":
            span = range(int(changes.get("from_step", failed_step)), int(changes.get("from_step", failed_step)) + 1)
        elif proposal.action == "backtrack":
            span = sorted(int(k) for k in (changes.get("args") or {}))
        elif proposal.action == "rewrite_args":
            span = [int(changes.get("step", failed_step))]
        else:
            return []
    except (TypeError, ValueError):
        return []
    return [[str(a) for a in steps[i].task] for i in span if 0 <= i < len(steps)]


def survives(attempt: Attempt, plan: list[list[str]]) -> bool:
    """Whether what ``attempt`` changed is still in the final ``plan``: a backtrack whose new arguments a later
    attempt rewrote again (a deeper backtrack) left nothing of itself there. Other kinds are assumed to survive."""
    proposal = attempt.proposal or {}
    changes = proposal.get("changes") or {}
    if proposal.get("action") not in ("backtrack", "rewrite_args"):
        return True
    args = changes.get("args") or {}
    values = [a for group in (args.values() if isinstance(args, dict) else [args]) for a in group]
    if not values:
        return True
    used = {str(a) for step in plan for a in step[1:]}
    return any(str(v) in used for v in values)
