"""HTN planning over YAML task files: load, validate, plan, and replan from a decomposition node.

Offers (re-exported here; each lives in its own module):

* :func:`load_task_file`, :func:`load_task_text` -- YAML task files to a :class:`TaskFile` (``loader``);
  :func:`problem_from_atoms` and :func:`method_from_text` build checked problems and methods in code
* :class:`State` -- immutable set of ground atoms (``state``)
* :class:`Condition`, :class:`Var` -- the safe condition language (``conditions``)
* :class:`Domain`, :class:`Primitive`, :class:`GroundPrimitive`, :class:`TaskDecl`, :class:`Method`,
  :class:`Problem`, :class:`TaskFile` -- the model (``model``); :class:`Axiom`, :class:`AxiomSet` (``axioms``)
* :func:`plan`, :class:`PlanResult`, :class:`GroundAction` -- the planner (``planner``)
* :class:`DecompositionTree`, :class:`DecompositionNode` -- its output (``tree``)
* :func:`replan` -- re-decompose from a failed node keeping the executed prefix (``replan``)
* :func:`verify_plan`, :class:`Verdict` -- an independent check of a plan and its tree (``verify``)

HDDL import lives in :mod:`bt_meta.htn.hddl` (``load_hddl``, ``import_hddl``).
"""

from __future__ import annotations

from bt_meta.htn.axioms import Axiom, AxiomSet
from bt_meta.htn.conditions import Condition, ExternalPredicateError, Var
from bt_meta.htn.loader import load_task_file, load_task_text, method_from_text, problem_from_atoms
from bt_meta.htn.model import Domain, GroundPrimitive, Method, Primitive, Problem, TaskDecl, TaskFile
from bt_meta.htn.planner import GroundAction, PlanResult, plan
from bt_meta.htn.replan import replan
from bt_meta.htn.state import State, atom_text
from bt_meta.htn.tree import DecompositionNode, DecompositionTree
from bt_meta.htn.verify import Verdict, verify_plan

__all__ = [
    "Axiom",
    "AxiomSet",
    "Condition",
    "DecompositionNode",
    "DecompositionTree",
    "Domain",
    "ExternalPredicateError",
    "GroundAction",
    "GroundPrimitive",
    "Method",
    "PlanResult",
    "Primitive",
    "Problem",
    "State",
    "TaskDecl",
    "TaskFile",
    "Var",
    "Verdict",
    "atom_text",
    "load_task_file",
    "load_task_text",
    "method_from_text",
    "plan",
    "problem_from_atoms",
    "replan",
    "verify_plan",
]
