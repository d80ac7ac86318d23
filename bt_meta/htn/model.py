"""The task-file model: what a loaded YAML domain and its problems are made of.

Offers:

* :class:`Primitive` (with :meth:`Primitive.ground` -> :class:`GroundPrimitive`) -- an action
* :class:`ConditionalEffect` -- a primitive's ``forall`` / ``when`` effect, decided in the state the action starts in
* :class:`TaskDecl` -- a compound task's name and parameters
* :class:`Method` -- a recipe decomposing a compound task (ordered or unordered subtasks)
* :class:`Domain` -- types, predicates, externals, axioms, primitives, tasks, methods (in file order)
* :class:`Problem` -- objects, initial state, task network, goal facts
* :class:`TaskFile` -- a loaded file: its path, domain and problems

Atom templates (effects, subtasks, task heads) are tuples ``(name, term, ...)`` whose terms are constants
(``str``) or :class:`~bt_meta.htn.conditions.Var`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bt_meta.errors import PlanningError
from bt_meta.htn.axioms import Axiom, AxiomSet
from bt_meta.htn.conditions import (
    Condition,
    DomainContext,
    ExternalFn,
    Term,
    Var,
    template_builder,
    template_text,
)
from bt_meta.htn.state import Atom, State, atom_text

Template = tuple  # (name, *terms)


def _bind_parameters(kind: str, name: str, parameters: Sequence[str], args: Sequence[str]) -> dict[str, str]:
    if len(args) != len(parameters):
        raise PlanningError(f"{kind} {name} takes {len(parameters)} argument(s), got {len(args)}")
    env: dict[str, str] = {}
    for param, arg in zip(parameters, args, strict=False):
        if param in env and env[param] != arg:
            raise PlanningError(f"{kind} {name}: parameter ?{param} given two values")
        env[param] = str(arg)
    return env


def types_hold(types: Sequence[str | None], args: Sequence[str], state: State) -> bool:
    """Typed parameters require the fact ``type(arg)`` in the state (from ``objects:`` or ``init:``)."""
    for type_name, arg in zip(types, args, strict=False):
        if type_name is not None and (type_name, arg) not in state:
            return False
    return True


@dataclass
class ConditionalEffect:
    """``forall ?v - t, ...: when C: add / delete``: applies once per binding of ``variables`` under which C holds.

    ``when`` is the condition alone (bound: the primitive's bound variables and ``variables``); ``condition`` is
    the type atoms of ``variables`` followed by ``when``, which enumerates the bindings. Both are evaluated in the
    state the action starts in, so every effect of a step sees the same state (PDDL's simultaneous effects).
    """

    variables: list[str]
    types: list[str]
    when: Condition
    condition: Condition
    add: list[Template]
    delete: list[Template]
    line: int | None = None
    column: int | None = None

    def __post_init__(self) -> None:
        self._add = [template_builder(t[0], t[1:]) for t in self.add]
        self._delete = [template_builder(t[0], t[1:]) for t in self.delete]

    def collect(self, state: State, env: dict[str, str], external: ExternalFn | None, add: list[Atom],
                delete: list[Atom]) -> None:
        """Append this effect's ground atoms for every satisfying binding in ``state`` (the pre-state)."""
        for found in self.condition.satisfiers(state, env, external):
            add.extend(build(found) for build in self._add)
            delete.extend(build(found) for build in self._delete)


@dataclass
class Primitive:
    name: str
    parameters: list[str]
    types: list[str | None]
    precondition: Condition
    add: list[Template]
    delete: list[Template]
    cost: float = 1.0
    expectations: dict[str, Any] = field(default_factory=dict)
    line: int | None = None
    column: int | None = None
    conditional: list[ConditionalEffect] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._typed = any(t is not None for t in self.types)
        # effect templates compiled once (the lists are not changed after construction)
        self._add = [template_builder(t[0], t[1:]) for t in self.add]
        self._delete = [template_builder(t[0], t[1:]) for t in self.delete]

    def fast_satisfiers(self, state: State, args: Sequence[str], external: ExternalFn | None) -> Iterable[dict]:
        """Planner fast path: arguments already checked against the arity at load time."""
        if self._typed and not types_hold(self.types, args, state):
            return ()
        return self.precondition.satisfiers_of(state, dict(zip(self.parameters, args, strict=True)), external)

    def ground(self, args: Sequence[str]) -> GroundPrimitive:
        return GroundPrimitive(self, tuple(str(a) for a in args),
                               _bind_parameters("primitive", self.name, self.parameters, args))

    def satisfiers(self, state: State, args: Sequence[str], external: ExternalFn | None = None) -> Iterator[dict]:
        """Bindings under which the primitive applies to ``args`` in ``state`` (types, then precondition)."""
        env = _bind_parameters("primitive", self.name, self.parameters, args)
        if not types_hold(self.types, args, state):
            return iter(())
        return self.precondition.satisfiers(state, env, external)

    def effects(self, env: dict[str, str], state: State | None = None,
                external: ExternalFn | None = None) -> tuple[list[Atom], list[Atom]]:
        """(add, delete) under the precondition's binding ``env``; conditional effects need the pre-``state``."""
        add = [build(env) for build in self._add]
        delete = [build(env) for build in self._delete]
        if self.conditional:
            if state is None:
                raise PlanningError(f"primitive {self.name} has conditional (forall / when) effects: its effects "
                                    "depend on the state the step starts in, which was not given")
            for effect in self.conditional:
                effect.collect(state, env, external, add, delete)
            add = list(dict.fromkeys(add))
            delete = list(dict.fromkeys(delete))
        return add, delete

    def signature(self) -> str:
        return template_text(self.name, [Var(p) for p in self.parameters])


@dataclass
class GroundPrimitive:
    """A primitive with its parameters bound; checks the precondition and applies the effects."""

    primitive: Primitive
    args: tuple[str, ...]
    bindings: dict[str, str]

    @property
    def name(self) -> str:
        return self.primitive.name

    def holds(self, state: State, external: ExternalFn | None = None) -> bool:
        return next(iter(self.primitive.satisfiers(state, self.args, external)), None) is not None

    def effects(self, state: State, external: ExternalFn | None = None) -> tuple[list[Atom], list[Atom]]:
        """(add, delete) atoms under the first binding that satisfies the precondition."""
        env = next(iter(self.primitive.satisfiers(state, self.args, external)), None)
        if env is None:
            raise PlanningError(f"precondition of {self} does not hold: {self.primitive.precondition.source}")
        return self.primitive.effects(env, state, external)

    def apply(self, state: State, external: ExternalFn | None = None) -> State:
        add, delete = self.effects(state, external)
        return state.apply(add=add, delete=delete)

    def __str__(self) -> str:
        return atom_text((self.name, *self.args))


@dataclass
class TaskDecl:
    name: str
    parameters: list[str]
    types: list[str | None]
    line: int | None = None
    column: int | None = None


@dataclass
class Method:
    name: str
    task_name: str
    task_args: tuple[Term, ...]
    precondition: Condition
    subtasks: list[Template]
    ordered: bool = True
    line: int | None = None
    column: int | None = None
    # the head's variable names when they are all distinct variables (the planner binds them with one zip)
    head_names: tuple[str, ...] | None = field(default=None, init=False, repr=False, compare=False)
    # the subtask templates compiled once (the list is not changed after construction)
    subtask_builders: list[Any] = field(default_factory=list, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        names = tuple(a.name for a in self.task_args if isinstance(a, Var))
        if len(names) == len(self.task_args) and len(set(names)) == len(names):
            self.head_names = names
        self.subtask_builders = [template_builder(t[0], t[1:]) for t in self.subtasks]

    def task_text(self) -> str:
        return template_text(self.task_name, self.task_args)

    def subtask_texts(self) -> list[str]:
        return [template_text(t[0], t[1:]) for t in self.subtasks]


@dataclass
class Domain:
    name: str
    types: dict[str, str | None]
    predicates: dict[str, list[str]]
    external: dict[str, list[str]]
    axioms: list[Axiom]
    primitives: dict[str, Primitive]
    tasks: dict[str, TaskDecl]
    methods: list[Method]
    context: DomainContext
    axiom_set: AxiomSet
    path: str | None = None
    methods_by_task: dict[str, list[Method]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.methods_by_task:
            for method in self.methods:
                self.methods_by_task.setdefault(method.task_name, []).append(method)

    def add_method(self, method: Method, *, first: bool = False) -> None:
        """Add a method (e.g. a learned refinement); ``first=True`` makes it the first one tried."""
        if method.task_name not in self.tasks:
            raise PlanningError(f"method {method.name}: {method.task_name} is not a compound task")
        if any(m.name == method.name for m in self.methods):
            raise PlanningError(f"a method named {method.name} already exists")
        if first:
            self.methods.insert(0, method)
        else:
            self.methods.append(method)
        self.methods_by_task = {}
        for existing in self.methods:
            self.methods_by_task.setdefault(existing.task_name, []).append(existing)

    def derived_atoms(self, state: State) -> list[Atom]:
        return self.axiom_set.derived_atoms(state)

    def is_primitive(self, name: str) -> bool:
        return name in self.primitives


@dataclass
class Problem:
    name: str
    objects: dict[str, list[str]]
    init: list[Atom]
    tasks: list[Atom]
    goal: list[Atom]
    state: State
    line: int | None = None
    column: int | None = None


@dataclass
class TaskFile:
    path: str
    domain: Domain
    problems: dict[str, Problem]
    domain_path: str | None = None

    def problem(self, name: str | None = None) -> Problem:
        """The named problem, or the only one; a clear error otherwise."""
        from bt_meta.errors import UserInputError

        if name is None:
            if len(self.problems) == 1:
                return next(iter(self.problems.values()))
            if not self.problems:
                raise UserInputError("the file defines no problems", Path(self.path))
            names = ", ".join(self.problems)
            raise UserInputError(f"the file has several problems, choose one with --problem: {names}", self.path)
        if name not in self.problems:
            names = ", ".join(self.problems) or "none"
            raise UserInputError(f"no problem named {name!r}; problems: {names}", self.path)
        return self.problems[name]
