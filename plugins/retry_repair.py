"""The baseline repair: retry the failed step, then replan from its decomposition node, then from scratch.

What a robot without experience would do (the ablation's "retry baseline", issue 6). Scores are low so any
experience-based plugin (substitution, pose backtracking, a user's) ranks first. Collision and reachability get
nothing: retrying the same motion fails the same way. A precondition failure is not retried (the state will not
change by itself), nor a failed verification (re-running the last step does not redo what verification found
missing); a plugin's own error (``internal`` naming a plugin) gets nothing either.

Offers:

* :data:`RETRIES` -- how many times one step is retried (default 1)
* :func:`proposals_for` -- the proposals for a failure, as a function
* :func:`bt_meta_propose_repairs` -- the hook (``trylast``)
"""

from __future__ import annotations

from typing import Any

from bt_meta.bt.failures import FailureKind, RepairProposal
from bt_meta.meta.proposals import REPLAN, REPLAN_SCRATCH, RETRY
from bt_meta.meta.taxonomy import MOTION_LIMITS
from bt_meta.plugins import hookimpl

RETRIES = 1
SCORES = {RETRY: 0.3, REPLAN: 0.2, REPLAN_SCRATCH: 0.1}


def proposals_for(failure: Any, retries: int = RETRIES) -> list[RepairProposal]:
    kind = failure.kind
    if kind in MOTION_LIMITS or (kind is FailureKind.INTERNAL and failure.plugin):
        return []
    localisation = failure.evidence.get("localisation") or {}
    step = localisation.get("step", failure.step)
    node_id = localisation.get("node_id") or failure.node_id
    history = failure.evidence.get("repair_history") or []
    done = sum(1 for a in history if a.get("step") == step and (a.get("proposal") or {}).get("action") == RETRY)
    proposals = []
    if kind not in (FailureKind.PRECONDITION, FailureKind.VERIFICATION) and done < retries:
        proposals.append(RepairProposal(RETRY, SCORES[RETRY], f"retry step {step} as it is",
                                        changes={"attempt": done + 1}))
    if node_id:
        proposals.append(RepairProposal(REPLAN, SCORES[REPLAN], f"replan from {node_id} in the observed state",
                                        changes={"node_id": node_id}))
    proposals.append(RepairProposal(REPLAN_SCRATCH, SCORES[REPLAN_SCRATCH],
                                    "plan the task network afresh from the observed state"))
    return proposals


@hookimpl(trylast=True)
def bt_meta_propose_repairs(failure: Any, context: Any) -> list[RepairProposal] | None:
    return proposals_for(failure) or None
