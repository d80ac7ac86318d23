"""A domain's planner fast path: generated code per compound task and primitive, and which tasks can recur.

Offers:

* :class:`CompiledDomain` -- made once per domain (:func:`compiled_domain`): for each compound task a generator
  of its alternatives ``(method, bindings, subtasks)``, for each primitive a function giving ``(bindings, add,
  delete)`` or None, both as generated Python (:meth:`bt_meta.htn.codegen.Generated.task_expander`,
  :meth:`~bt_meta.htn.codegen.Generated.primitive_stepper`), and :attr:`~CompiledDomain.recursive`, the tasks
  that can appear below themselves, and :attr:`~CompiledDomain.typed_tasks`, those with typed parameters
* :func:`compiled_domain` -- the compiled form of a domain, remade when its methods change

Why: on small problems the planner's time went into the generic layers between a task and its answer (method
heads unified into dicts, matchers chosen per call, subtasks built from templates, effects built from
templates). One generated function per task answers the same questions in the same order without them.

A task or primitive whose conditions the generator does not handle (external predicates, typed parameters,
a primitive precondition that binds variables of its own) has no entry, and the planner takes its reference
path for it. Loop detection only needs to watch the tasks in :attr:`~CompiledDomain.recursive`: a task that
cannot reach itself through method subtasks never appears below itself.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from bt_meta.htn.conditions import REFERENCE_PROOFS_MIN
from bt_meta.htn.model import Domain

_ATTRIBUTE = "_compiled"


def _recursive_tasks(domain: Domain) -> frozenset[str]:
    """Compound tasks that can reach themselves through the subtasks of their methods."""
    calls: dict[str, set[str]] = {}
    for method in domain.methods:
        calls.setdefault(method.task_name, set()).update(
            template[0] for template in method.subtasks if template[0] in domain.tasks)
    recursive: set[str] = set()
    for task in calls:
        todo = list(calls[task])
        seen: set[str] = set()
        while todo:
            name = todo.pop()
            if name == task:
                recursive.add(task)
                break
            if name not in seen:
                seen.add(name)
                todo.extend(calls.get(name, ()))
    return frozenset(recursive)


class CompiledDomain:
    """Generated expanders and steppers of one domain, in two variants chosen by state size (see below)."""

    def __init__(self, domain: Domain) -> None:
        self.domain = domain
        self.methods_by_task = domain.methods_by_task  # Domain.add_method replaces it: a new one means a change
        self.recursive = _recursive_tasks(domain)
        self.typed_tasks = frozenset(name for name, decl in domain.tasks.items()
                                     if any(t is not None for t in decl.types))
        axioms = domain.axiom_set
        # ground derived tests either use the generated provers (a fresh memo per state) or AxiomSet.holds
        # (memos inherited by successor states), as bt_meta.htn.conditions.Condition.satisfiers_of chooses
        self.fixed_variant: bool | None = axioms.reference_proofs
        self.threshold = REFERENCE_PROOFS_MIN
        self._variants: dict[bool, tuple[dict[str, Callable[..., Any]], dict[str, Callable[..., Any]]]] = {}
        self.enabled = bool(axioms.codegen)

    def for_size(self, atoms: int) -> tuple[dict[str, Callable[..., Any]], dict[str, Callable[..., Any]]]:
        """The variant for a state of ``atoms`` atoms: inherited proofs from ``threshold`` atoms on, unless fixed."""
        fixed = self.fixed_variant
        return self.variant(atoms >= self.threshold if fixed is None else fixed)

    def variant(self, reference_proofs: bool) -> tuple[dict[str, Callable[..., Any]], dict[str, Callable[..., Any]]]:
        """``(expanders, steppers)`` by task / primitive name; a name missing takes the reference path."""
        found = self._variants.get(reference_proofs)
        if found is None:
            found = self._variants[reference_proofs] = self._build(reference_proofs)
        return found

    def _build(self, reference_proofs: bool) -> tuple[dict[str, Callable[..., Any]], dict[str, Callable[..., Any]]]:
        from bt_meta.htn.fastpath import Unsupported

        expanders: dict[str, Callable[..., Any]] = {}
        steppers: dict[str, Callable[..., Any]] = {}
        if not self.enabled:
            return expanders, steppers
        generated = self.domain.axiom_set.generated(reference_proofs)
        if generated is None:
            return expanders, steppers
        for name, decl in self.domain.tasks.items():
            with contextlib.suppress(Unsupported):  # no entry: the planner's reference path
                expanders[name] = generated.task_expander(name, len(decl.parameters),
                                                          self.domain.methods_by_task.get(name, ()))
        for name, primitive in self.domain.primitives.items():
            if primitive._typed:
                continue
            with contextlib.suppress(Unsupported):
                steppers[name] = generated.primitive_stepper(primitive)
        return expanders, steppers


def compiled_domain(domain: Domain) -> CompiledDomain:
    """The domain's :class:`CompiledDomain`, made on first use and again after a method was added."""
    found: CompiledDomain | None = domain.__dict__.get(_ATTRIBUTE)
    if found is None or found.methods_by_task is not domain.methods_by_task \
            or found.enabled != bool(domain.axiom_set.codegen) \
            or found.fixed_variant != domain.axiom_set.reference_proofs:
        found = CompiledDomain(domain)
        domain.__dict__[_ATTRIBUTE] = found
    return found
