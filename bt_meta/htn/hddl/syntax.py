"""The HDDL abstract syntax: what a parsed domain and problem are made of, every part keeping its position.

Offers:

* :class:`Typed` -- a ``?var - type`` or ``name - type`` entry; ``types`` has several names for ``(either ...)``
* :class:`Formula` -- a goal description (``and or not imply exists forall = atom true``)
* :class:`Effect` -- one effect: add, delete, ``forall`` or ``when`` (with nested effects), or a cost increase
* :class:`Subtask` -- one task of a task network, with its optional id
* :class:`TaskNetwork` -- subtasks, ordering pairs, constraints (methods and a problem's ``:htn``)
* :class:`HMethod`, :class:`HAction`, :class:`HTask`, :class:`HDomain`, :class:`HProblem`
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bt_meta.htn.hddl.sexpr import SList, Sym


@dataclass
class Typed:
    name: Sym
    types: tuple[Sym, ...]  # empty: untyped (object); several: (either ...)


@dataclass
class Formula:
    op: str  # and, or, not, imply, exists, forall, =, atom, true
    where: Sym | SList
    children: list[Formula] = field(default_factory=list)
    pred: Sym | None = None  # for atoms
    terms: list[Sym] = field(default_factory=list)  # atom arguments, or the two sides of =
    params: list[Typed] = field(default_factory=list)  # quantified variables


@dataclass
class Effect:
    kind: str  # add, delete, forall, when, cost
    where: Sym | SList
    pred: Sym | None = None
    terms: list[Sym] = field(default_factory=list)
    params: list[Typed] = field(default_factory=list)  # forall
    condition: Formula | None = None  # when
    effects: list[Effect] = field(default_factory=list)  # forall / when bodies
    amount: float = 0.0  # cost


@dataclass
class Subtask:
    ident: Sym | None
    name: Sym
    args: list[Sym]
    where: SList | Sym


@dataclass
class TaskNetwork:
    subtasks: list[Subtask] = field(default_factory=list)
    ordering: list[tuple[Sym, Sym]] = field(default_factory=list)  # (before, after) task ids
    declared_ordered: bool = False  # :ordered-subtasks / :ordered-tasks
    constraints: Formula | None = None
    where: SList | Sym | None = None


@dataclass
class HTask:
    name: Sym
    params: list[Typed]


@dataclass
class HMethod:
    name: Sym
    params: list[Typed]
    task: Sym
    task_args: list[Sym]
    precondition: Formula | None
    network: TaskNetwork
    where: SList


@dataclass
class HAction:
    name: Sym
    params: list[Typed]
    precondition: Formula | None
    effects: list[Effect]
    where: SList


@dataclass
class HDomain:
    name: Sym
    path: str
    types: list[Typed] = field(default_factory=list)  # name - parent entries in file order
    constants: list[Typed] = field(default_factory=list)
    predicates: list[tuple[Sym, list[Typed]]] = field(default_factory=list)
    tasks: list[HTask] = field(default_factory=list)
    methods: list[HMethod] = field(default_factory=list)
    actions: list[HAction] = field(default_factory=list)


@dataclass
class HProblem:
    name: Sym
    domain_name: Sym | None
    path: str
    objects: list[Typed] = field(default_factory=list)
    htn_params: list[Typed] = field(default_factory=list)
    htn: TaskNetwork | None = None
    init: list[tuple[Sym, list[Sym]]] = field(default_factory=list)
    goal: Formula | None = None
