"""Meta-reasoning: diagnose a failed execution, repair the plan from plugins' proposals, keep what worked.

Offers (each in its own module):

* :class:`MetaReasoner`, :class:`Limits`, :class:`Diagnosis`, :class:`Decision`, :class:`Attempt`,
  :class:`ReasonerPlugin` -- gather, localise, classify, rank repairs, decide (``reasoner``)
* :class:`MetaExecutor`, :class:`RunReport`, :func:`goal_verifier`, :func:`run_task_file` -- run a plan as a
  monitored tree, repair on failure, verify (``executor``)
* :class:`RepairProposal`, :class:`PlanState`, :func:`apply_proposal`, :data:`PROPOSAL_KINDS`,
  :class:`ProposalError` -- what a repair may change and how it is applied (``proposals``)
* :class:`Refinement`, :class:`RefinementStore`, :func:`with_refinements`, :func:`task_file_yaml` -- learned
  method refinements in the memory file, exportable as task-file YAML (``refinements``); which plan a repaired run
  keeps, with later repairs carried into a plugin's replay plan (``kept_plan``)
* what no repair may change -- verification steps, the goal (``invariants``)
* :data:`MOTION_LIMITS`, :func:`is_motion_limit` -- how the reasoner treats taxonomy kinds (``taxonomy``)

The taxonomy rules, the retry baseline and the pose-tolerance predicate are plugins: ``bt_meta_plugins.
classification_rules``, ``bt_meta_plugins.retry_repair``, ``bt_meta_plugins.refinement_predicates``.
See ``docs/meta-reasoning.md``.
"""

from __future__ import annotations

from bt_meta.meta.executor import MetaExecutor, RunReport, goal_verifier, run_task_file
from bt_meta.meta.proposals import PROPOSAL_KINDS, PlanState, ProposalError, RepairProposal, apply_proposal
from bt_meta.meta.reasoner import Attempt, Decision, Diagnosis, Limits, MetaReasoner, ReasonerPlugin
from bt_meta.meta.refinements import Refinement, RefinementError, RefinementStore, task_file_yaml, with_refinements
from bt_meta.meta.taxonomy import MOTION_LIMITS, is_motion_limit

__all__ = [
    "MOTION_LIMITS",
    "PROPOSAL_KINDS",
    "Attempt",
    "Decision",
    "Diagnosis",
    "Limits",
    "MetaExecutor",
    "MetaReasoner",
    "PlanState",
    "ProposalError",
    "ReasonerPlugin",
    "Refinement",
    "RefinementError",
    "RefinementStore",
    "RepairProposal",
    "RunReport",
    "apply_proposal",
    "goal_verifier",
    "is_motion_limit",
    "run_task_file",
    "task_file_yaml",
    "with_refinements",
]
