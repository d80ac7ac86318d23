"""Learned method refinements: a successfully repaired plan kept as a new method of its task (section 7.4).

A refinement is a ground method ``task -> [the repaired primitives]`` whose precondition is sub-symbolic: every
object of the task and plan that the world reported a pose for must start within a tolerance of the pose it had
in the repaired run, written as the external predicate ``pose_within(obj, x, y, z, roll, pitch, yaw, pos_tol,
ang_tol)`` (evaluated by the plugin ``bt_meta_plugins.refinement_predicates``). Entity facts a repair wrote
into the world's symbolic state from perception (object substitution anchoring two red 1x1 blocks where the
problem assumed a blue 1x2) are kept with the refinement (:attr:`Refinement.facts`) and guarded by ``seen(obj,
attribute, value)`` conditions (the world reports the object with that attribute): the executor adds the facts
when the refinement's precondition holds, so it applies exactly when the same entities are seen again. The
repair's rewrite of the goal (:func:`rewrite_goal`) is kept as :attr:`Refinement.goal`, the goal a run that uses
the refinement is verified against. A repair that grounded a task-file symbol as another object (a spare for a
missing part, ``rebind``) is kept as :attr:`Refinement.rebind`: the executor rebinds the same symbols when the
precondition (which then names the spare's starting pose) holds. Refinements live in the episodic memory file
(table ``refinements``, schema v3; ``facts``, ``goal`` and ``rebind`` ride in its ``repair`` column; v4 adds the
robot that learned it, the plan it refined, its status -- a refinement whose replay failed is demoted -- and its
replay counts; an equivalent refinement is stored once, :meth:`RefinementStore.equivalent`); the next
run of the same variant plans with them first, so it succeeds with zero repair attempts; a run whose objects are
elsewhere (or other) fails the precondition and plans as before.

Offers:

* :class:`Refinement` -- one stored refinement; :meth:`Refinement.to_method` builds the HTN method
* :class:`RefinementStore` -- :meth:`~RefinementStore.open` a memory file, :meth:`~RefinementStore.save_repair`,
  :meth:`~RefinementStore.add`, :meth:`~RefinementStore.list`, :meth:`~RefinementStore.apply` (a domain copy
  with the refinements first), :meth:`~RefinementStore.export_yaml`
* :func:`with_refinements` -- a copy of a domain with refinements added as its first methods
* :func:`domain_with_pose_predicate` -- a copy of a domain that declares ``pose_within`` and ``seen``
* :func:`seen_holds` -- whether the world reports an object's attribute with a value (``seen``'s test)
* :func:`rewrite_goal` -- the problem's goal as a repair rewrote it (the goal the refined plan achieves)
* :func:`task_file_yaml` -- a domain (and problems) written back in the task-file format, refinements included;
  ``bt_meta.htn.load_task_text`` loads it
* :data:`POSE_PREDICATE`, :data:`POSE_ARITY`, :data:`SEEN_PREDICATE`, :data:`SEEN_ARITY`, :data:`DEFAULT_TOLERANCE`
* :class:`RefinementError` -- a repaired run that cannot become a refinement, or a broken stored one
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import re
import sqlite3
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import BtMetaError
from bt_meta.htn.conditions import DomainContext, template_text
from bt_meta.htn.state import atom_text

__all__ = [
    "DEFAULT_TOLERANCE",
    "POSE_ARITY",
    "POSE_PREDICATE",
    "SEEN_ARITY",
    "SEEN_PREDICATE",
    "Refinement",
    "RefinementError",
    "RefinementStore",
    "domain_with_pose_predicate",
    "pose_of",
    "rewrite_goal",
    "seen_holds",
    "task_file_yaml",
    "with_refinements",
]

POSE_PREDICATE = "pose_within"
POSE_ARITY = 9
SEEN_PREDICATE = "seen"
SEEN_ARITY = 3
_SYMBOL = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.:+-]*$")  # what a task file reads back as one constant
log = logging.getLogger("bt_meta.meta")

ACTIVE = "active"
DEMOTED = "demoted"
ANY_ROBOT: Any = object()
"""``robot`` of :meth:`RefinementStore.apply` left out: refinements of any robot."""
DEFAULT_TOLERANCE = {"position": 0.02, "angle": 0.1}
"""Metres and radians: a refinement applies when every object starts this close to its recorded pose."""


class RefinementError(BtMetaError):
    """A repaired run that cannot be saved as a refinement, or a stored refinement that no longer fits its domain."""


def _number(value: float) -> str:
    text = f"{float(value):.6g}"
    return "0" if text in ("-0", "0") else text


def pose_of(state: Any) -> list[float] | None:
    """The 6-vector pose of an object state: a dict with ``"pose"``, an object with ``.pose``, or a sequence."""
    pose = state.get("pose") if isinstance(state, dict) else getattr(state, "pose", state)
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        return None
    return values if len(values) == 6 and all(math.isfinite(v) for v in values) else None


@dataclass
class Refinement:
    """One learned refinement; ``subtasks`` are ground primitive calls in the task-file syntax."""

    domain: str
    task: str
    method: str
    precondition: str
    subtasks: list[str]
    poses: dict[str, list[float]] = field(default_factory=dict)
    tolerance: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_TOLERANCE))
    problem: str | None = None
    variant: str | None = None
    repair: dict[str, Any] = field(default_factory=dict)
    domain_path: str | None = None
    """The task file the domain was loaded from (absolute), so ``bt-meta refinements export`` can find it."""
    facts: dict[str, list[list[str]]] = field(default_factory=dict)
    """``{"add": [atom, ...], "delete": [...]}``: the entity facts the repair relied on that came from perception
    (anchored in the world's symbolic state while repairing); added to the run's state when the precondition
    holds. Atoms are lists of strings."""
    goal: list[list[str]] | None = None
    """The problem's goal as the repair rewrote it (``None``: unchanged); what a run using it is verified against."""
    rebind: dict[str, str] = field(default_factory=dict)
    """Task-file symbol -> world object the repair grounded it as (a spare standing in for a missing part)."""
    robot: str | None = None
    """The robot that learned it (``None``: unknown, stored before v4); another robot does not replay it."""
    refines: list[list[str]] | None = None
    """The plan it refined (the hand-written methods' plan): what a repair after a failed replay starts from."""
    status: str = ACTIVE
    """``active`` (planned with first) or ``demoted`` (its replay failed; kept, not planned with)."""
    status_reason: str | None = None
    replays: int = 0
    """Replays that succeeded with zero repair attempts."""
    failures: int = 0
    """Replays that failed (each demotes it)."""
    id: int | None = None
    created: str = ""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def fact_atoms(self) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]]:
        """(add, delete) of :attr:`facts` as atoms."""
        return ([tuple(str(a) for a in f) for f in self.facts.get("add") or []],
                [tuple(str(a) for a in f) for f in self.facts.get("delete") or []])

    def rebind_symbols(self) -> dict[str, str]:
        return {str(k): str(v) for k, v in (self.rebind or {}).items()}

    def goal_atoms(self) -> list[tuple[str, ...]] | None:
        return None if self.goal is None else [tuple(str(a) for a in g) for g in self.goal]

    def to_method(self, domain: Any) -> Any:
        """The HTN method (checked against ``domain``, which must declare ``pose_within`` when poses are used)."""
        from bt_meta.htn import method_from_text

        try:
            return method_from_text(domain, name=self.method, task=self.task, precondition=self.precondition,
                                    subtasks=self.subtasks)
        except BtMetaError as error:
            raise RefinementError(f"refinement {self.method} does not fit domain {self.domain}: {error}") from None


def pose_precondition(poses: dict[str, list[float]], tolerance: dict[str, float],
                      seen: Sequence[tuple[str, str, str]] = ()) -> str:
    position, angle = _number(tolerance["position"]), _number(tolerance["angle"])
    parts = [f"{POSE_PREDICATE}({name}, {', '.join(_number(v) for v in pose)}, {position}, {angle})"
             for name, pose in sorted(poses.items())]
    parts += [f"{SEEN_PREDICATE}({name}, {attribute}, {value})" for name, attribute, value in sorted(set(seen))]
    return " and ".join(parts) if parts else "true"


def seen_holds(objects: dict[str, Any], name: str, attribute: str, value: str) -> bool:
    """``seen(name, attribute, value)`` on a world's object report (``observe()["objects"]``)."""
    state = objects.get(name)
    found = state.get(attribute) if isinstance(state, dict) else getattr(state, attribute, None)
    return found is not None and str(found) == str(value)


def _final_state(domain: Any, steps: Sequence[Sequence[str]], state: Any, external: Any) -> Any:
    """``state`` after ``steps`` applied symbolically; a step whose precondition does not hold there applies its
    effects under its parameters alone, one whose effects need more bindings is skipped."""
    for step in steps:
        primitive = domain.primitives.get(str(step[0]))
        if primitive is None:
            continue
        args = tuple(str(a) for a in step[1:])
        try:
            env = next(iter(primitive.satisfiers(state, args, external)), None)
            if env is None:
                env = primitive.ground(args).bindings
            add, delete = primitive.effects(env, state, external)
        except (BtMetaError, KeyError, TypeError, ValueError):
            continue
        state = state.apply(add=add, delete=delete)
    return state


def rewrite_goal(domain: Any, goal: Sequence[Sequence[str]], old_plan: Sequence[Sequence[str]],
                 new_plan: Sequence[Sequence[str]], old_start: Any, new_start: Any, external: Any = None,
                 undone: Iterable[Sequence[str]] = ()) -> list[tuple[str, ...]]:
    """The goal a repaired plan is verified against: goal facts the original plan achieved (from ``old_start``)
    but the repaired one does not (from ``new_start``, the state with the repair's perceived facts) are replaced
    by what only the repaired plan achieves. A spliced ``place(b5, 1.5, 1)`` -> ``place(b5, 1, 1), place(b6, 2,
    1)`` turns ``at(b5, 1.5, 1)`` into ``at(b5, 1, 1), at(b6, 2, 1)``; a repair that keeps every goal fact (a new
    approach pose) leaves the goal as it is. ``undone``: facts a repair made false on purpose mid-plan (a re-tiling
    takes a drawn block off the drawing, ``changes["facts"]``) that no later step makes true again: they do not
    hold after the repaired plan."""
    goal = [tuple(str(a) for a in g) for g in goal]
    if not goal or [list(s) for s in old_plan] == [list(s) for s in new_plan]:
        return goal
    old_final = _final_state(domain, old_plan, old_start, external)
    new_final = _final_state(domain, new_plan, new_start, external)
    undone = [tuple(str(a) for a in f) for f in undone]
    if undone:
        new_final = new_final.apply(delete=[f for f in undone if f in new_final])
    dropped = [g for g in goal if g in old_final and g not in new_final]
    if not dropped:
        return goal
    achieved_old = {f for f in old_final if f not in old_start}
    gained = sorted(f for f in new_final if f not in new_start and f not in achieved_old)
    return [g for g in goal if g not in dropped] + [g for g in gained if g not in goal]


def domain_with_pose_predicate(domain: Any) -> Any:
    """A shallow copy of ``domain`` that declares the external predicates ``pose_within`` and ``seen`` (the
    original is kept)."""
    wanted = {POSE_PREDICATE: POSE_ARITY, SEEN_PREDICATE: SEEN_ARITY}
    missing = {name: arity for name, arity in wanted.items() if name not in domain.external}
    if not missing:
        return dataclasses.replace(domain, methods=list(domain.methods), methods_by_task={})
    for name in missing:
        if name in domain.context.arities:
            raise RefinementError(f"domain {domain.name} already uses {name!r} for something else")
    context = DomainContext(arities={**domain.context.arities, **missing},
                            derived=set(domain.context.derived),
                            external={*domain.context.external, *missing}, axioms=domain.context.axioms)
    external = {**domain.external, **{name: ["object"] * arity for name, arity in missing.items()}}
    return dataclasses.replace(domain, external=external, context=context, methods=list(domain.methods),
                               methods_by_task={})


def with_refinements(domain: Any, refinements: Iterable[Refinement]) -> tuple[Any, list[str]]:
    """A copy of ``domain`` whose first methods are ``refinements`` (in the order given); returns the copy and the
    names of the methods added (refinements already in the domain, or that no longer fit it, are skipped; the
    latter with a warning on the ``bt_meta.meta`` logger)."""
    refinements = list(refinements)
    copy = domain_with_pose_predicate(domain) if refinements else domain
    added: list[str] = []
    for refinement in reversed(refinements):  # add_method(first=True) puts each in front: keep the given order
        if any(m.name == refinement.method for m in copy.methods):
            continue
        try:
            method = refinement.to_method(copy)
        except RefinementError as error:  # the domain changed since it was learned: plan without it
            log.warning("skipping a stored refinement: %s", error)
            continue
        copy.add_method(method, first=True)
        added.append(refinement.method)
    return copy, list(reversed(added))


class RefinementStore:
    """The refinements of one memory file. Use :meth:`open`; close it (or use ``with``)."""

    def __init__(self, connection: sqlite3.Connection, path: Path, readonly: bool,
                 tolerance: dict[str, float] | None = None) -> None:
        self._connection = connection
        self.path = path
        self.readonly = readonly
        self.tolerance = dict(tolerance or DEFAULT_TOLERANCE)

    @classmethod
    def open(cls, path: str | Path, *, readonly: bool = False, create: bool = True,
             tolerance: dict[str, float] | None = None) -> RefinementStore:
        """Open the memory file at ``path`` (created unless ``create=False`` or ``readonly``, migrated unless
        ``readonly``); errors are :class:`~bt_meta.memory.MemoryStoreError` naming the path."""
        from bt_meta.memory import EpisodicMemory
        from bt_meta.memory.schema import sqlite_failure

        memory = EpisodicMemory.open(path, readonly=readonly, create=create)  # checks, creates, migrates
        resolved = memory.path
        memory.close()
        try:
            if readonly:
                connection = sqlite3.connect(f"{resolved.as_uri()}?mode=ro", uri=True, isolation_level=None,
                                             timeout=10)
            else:
                connection = sqlite3.connect(str(resolved), isolation_level=None, timeout=10)
        except sqlite3.Error as error:
            raise sqlite_failure(resolved, error, "cannot open") from None
        return cls(connection, resolved, readonly, tolerance)

    def close(self) -> None:
        self._connection.close()

    def __enter__(self) -> RefinementStore:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _query(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        from bt_meta.memory.schema import sqlite_failure

        try:
            return self._connection.execute(sql, params).fetchall()
        except sqlite3.Error as error:
            raise sqlite_failure(self.path, error, "refinement query failed") from None

    # -- writing -------------------------------------------------------------------------------------------------

    def add(self, refinement: Refinement) -> Refinement:
        """Store ``refinement`` (its ``id`` and ``created`` are filled in); a method name taken is an error."""
        from bt_meta.memory import MemoryStoreError

        if self.readonly:
            raise MemoryStoreError(self.path, "opened read-only; cannot save a refinement")
        refinement.created = refinement.created or datetime.now(timezone.utc).isoformat(timespec="seconds")
        try:
            cursor = self._connection.execute(
                "INSERT INTO refinements (created, domain, domain_path, task, method, precondition, subtasks, poses,"
                " tolerance, problem, variant, repair, robot, refines, status, status_reason, replays, failures)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (refinement.created, refinement.domain, refinement.domain_path, refinement.task, refinement.method,
                 refinement.precondition,
                 json.dumps(refinement.subtasks), json.dumps(refinement.poses), json.dumps(refinement.tolerance),
                 refinement.problem, refinement.variant, json.dumps(_repair_column(refinement), default=str),
                 refinement.robot, None if refinement.refines is None else json.dumps(refinement.refines),
                 refinement.status, refinement.status_reason, refinement.replays, refinement.failures))
        except sqlite3.IntegrityError:
            raise RefinementError(f"a refinement named {refinement.method} is already stored in {self.path}") from None
        except sqlite3.Error as error:
            raise MemoryStoreError(self.path, f"cannot save the refinement: {error}") from None
        refinement.id = int(cursor.lastrowid or 0)
        return refinement

    def save_repair(self, domain: Any, problem: Any, report: Any, start_objects: dict[str, Any],
                    variant: str | None = None, names: dict[str, str] | None = None,
                    facts: tuple[Iterable[Sequence[str]], Iterable[Sequence[str]]] | None = None,
                    goal: Sequence[Sequence[str]] | None = None,
                    rebind: dict[str, str] | None = None, robot: str | None = None,
                    refines: Sequence[Sequence[str]] | None = None,
                    expected: Sequence[dict[str, Any]] | None = None) -> Refinement:
        """Turn a successful repaired run (``report``, a :class:`~bt_meta.meta.executor.RunReport`) into a
        refinement of the problem's task and store it; the objects' starting poses become its precondition.

        ``names`` maps task-file symbols to the world's object names where they differ (``active_part`` ->
        ``active``): the precondition names the world's objects, as ``pose_within`` looks them up. ``facts``
        (add, delete) are the facts the repair wrote into the world's symbolic state; those naming an object of
        the refinement the world reported are kept, and each ``attribute(obj, value)`` among them that the world
        reported at the start (``start_objects[obj][attribute] == value``) becomes a ``seen`` condition. ``goal``
        is the goal as the repair rewrote it (kept when it differs from the problem's). ``rebind`` are the grounding
        symbols the repair grounded as other objects (``names`` then already maps them so). ``robot`` is the robot
        that learned it, ``refines`` the plan it refined (default: the report's initial plan), ``expected`` the
        monitor objections its plan replays through (kept in :attr:`Refinement.repair`, ``"expected"``).

        A stored refinement equivalent to the new one (:meth:`equivalent`: the same plan, facts, goal, rebinding
        and robot, its objects' starting poses within the tolerance of the new ones) is kept once: it is returned
        (made active again if it was demoted) and nothing is added."""
        tasks = list(getattr(problem, "tasks", None) or [])
        if len(tasks) != 1:
            raise RefinementError(f"the problem has {len(tasks)} root tasks; a refinement refines exactly one")
        task = tuple(tasks[0])
        if task[0] not in domain.tasks:
            raise RefinementError(f"the root task {task[0]} is a primitive: there is no method to refine")
        rebind = {str(k): str(v) for k, v in (rebind or {}).items()}
        if report.plan == report.initial_plan and not rebind:
            raise RefinementError("the repairs did not change the plan (retries only): nothing new to keep")
        subtasks = [atom_text(tuple(step)) for step in report.plan]
        mentioned = {str(a) for a in task[1:]} | {str(a) for step in report.plan for a in step[1:]}
        names = names or {}
        poses = {name: pose for name in sorted({names.get(m, m) for m in mentioned})
                 if name in start_objects and (pose := pose_of(start_objects[name])) is not None}
        kept, seen = _perceived_facts(facts, mentioned, names, start_objects)
        goal_atoms = None if goal is None else [[str(a) for a in g] for g in goal]
        if goal_atoms is not None and goal_atoms == [[str(a) for a in g] for g in getattr(problem, "goal", None) or []]:
            goal_atoms = None
        identity = [subtasks, poses, kept, goal_atoms] + ([rebind] if rebind else []) + ([robot] if robot else [])
        digest = hashlib.sha1(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:8]
        method = f"refined_{task[0]}_{digest}"
        candidate = Refinement(domain=domain.name, task=atom_text(task), method=method, precondition="",
                               subtasks=subtasks, poses=poses, facts=kept, goal=goal_atoms, rebind=rebind, robot=robot)
        existing = next((r for r in self.list(domain=domain.name)
                         if r.method == method or self.equivalent(r, candidate)), None)
        if existing is not None:
            if existing.status != ACTIVE:
                self.promote(existing.method, "learned again by a repair from the plan it refines")
                existing.status, existing.status_reason = ACTIVE, "learned again by a repair from the plan it refines"
            return existing
        source = getattr(domain, "path", None)
        domain_path = str(Path(source).resolve()) if source and not source.startswith("<") else None
        refinement = Refinement(
            domain=domain.name, domain_path=domain_path, task=atom_text(task), method=method,
            precondition=pose_precondition(poses, self.tolerance, seen), subtasks=subtasks, poses=poses,
            facts=kept, goal=goal_atoms, rebind=rebind, robot=robot,
            refines=[[str(a) for a in step] for step in (refines if refines is not None else report.initial_plan)],
            tolerance=dict(self.tolerance), problem=getattr(problem, "name", None), variant=variant,
            repair={"attempts": len(report.attempts), "kinds": [a.kind for a in report.attempts],
                    "proposals": [{"action": a.proposal.get("action"), "plugin": a.proposal.get("plugin"),
                                   "change": a.change} for a in report.attempts],
                    **({"expected": [dict(e) for e in expected]} if expected else {})})
        refinement.to_method(domain_with_pose_predicate(domain))  # it must load before it is stored
        return self.add(refinement)

    def equivalent(self, stored: Refinement, new: Refinement) -> bool:
        """Whether ``new`` would replay as ``stored`` does: the same task, plan, perceived facts, goal, rebinding
        and robot, and every object starting within the tolerance (this store's) of where it started for it."""
        same = (stored.task == new.task and list(stored.subtasks) == list(new.subtasks)
                and (stored.facts or {}) == (new.facts or {}) and stored.goal == new.goal
                and (stored.rebind or {}) == (new.rebind or {}) and stored.robot == new.robot
                and set(stored.poses) == set(new.poses))
        if not same:
            return False
        position, angle = float(self.tolerance["position"]), float(self.tolerance["angle"])
        for name, pose in new.poses.items():
            old = stored.poses[name]
            if math.dist(old[:3], pose[:3]) > position:
                return False
            if any(abs(math.remainder(a - b, math.tau)) > angle for a, b in zip(old[3:], pose[3:], strict=True)):
                return False
        return True

    # -- reading -------------------------------------------------------------------------------------------------

    def list(self, *, domain: str | None = None, task: str | None = None) -> list[Refinement]:
        """Stored refinements, newest first (the order they are tried in)."""
        where, params = [], []
        if domain is not None:
            where.append("domain = ?")
            params.append(domain)
        if task is not None:
            where.append("task = ?")
            params.append(task)
        sql = ("SELECT id, created, domain, task, method, precondition, subtasks, poses, tolerance, problem, variant,"
               " repair, domain_path, robot, refines, status, status_reason, replays, failures FROM refinements"
               + (" WHERE " + " AND ".join(where) if where else "") + " ORDER BY id DESC")
        refinements = []
        for row in self._query(sql, params):
            repair = json.loads(row[11])
            facts = repair.pop("facts", None) if isinstance(repair, dict) else None
            goal = repair.pop("goal", None) if isinstance(repair, dict) else None
            rebind = repair.pop("rebind", None) if isinstance(repair, dict) else None
            refinements.append(Refinement(
                id=row[0], created=row[1], domain=row[2], task=row[3], method=row[4], precondition=row[5],
                subtasks=json.loads(row[6]), poses=json.loads(row[7]), tolerance=json.loads(row[8]),
                problem=row[9], variant=row[10], repair=repair, domain_path=row[12], facts=facts or {}, goal=goal,
                rebind=rebind or {}, robot=row[13], refines=None if row[14] is None else json.loads(row[14]),
                status=row[15], status_reason=row[16], replays=row[17], failures=row[18]))
        return refinements

    def candidates(self, domain: Any, robot: Any = ANY_ROBOT, exclude: Iterable[str] = ()
                   ) -> tuple[list[Refinement], list[dict[str, str]]]:
        """The refinements of ``domain``'s tasks to plan with first (newest first), and the others with why not: a
        demoted one (its replay failed), one another robot learned (its motions are that arm's: this robot's own
        repair from the hand-written method is the safe start), one in ``exclude``. ``robot`` left out: any."""
        fitting, skipped = [], []
        excluded = set(exclude)
        for refinement in self.list(domain=domain.name):
            if refinement.task.split("(")[0] not in domain.tasks:
                continue
            if refinement.method in excluded:
                continue
            if refinement.status != ACTIVE:
                skipped.append({"method": refinement.method, "reason": f"{refinement.status}: "
                                f"{refinement.status_reason or 'its replay failed'}"})
            elif robot is not ANY_ROBOT and refinement.robot is not None and refinement.robot != robot:
                skipped.append({"method": refinement.method, "reason": f"learned by the robot {refinement.robot}, "
                                f"not by {robot or 'this world'}: not replayed on another robot"})
            else:
                fitting.append(refinement)
        return fitting, skipped

    def apply(self, domain: Any, problem: Any = None, *, robot: Any = ANY_ROBOT,
              exclude: Iterable[str] = ()) -> tuple[Any, list[str]]:
        """A copy of ``domain`` with this memory's active refinements of it (learned by ``robot``, or by an unknown
        robot; any robot when left out) as its first methods (newest first), and the names added; refinements of
        tasks the domain no longer has, demoted ones and ``exclude`` are skipped (:meth:`candidates`)."""
        fitting, _ = self.candidates(domain, robot, exclude)
        if not fitting:
            return domain, []
        return with_refinements(domain, fitting)

    def note_replay(self, method: str, *, succeeded: bool, reason: str | None = None) -> None:
        """Count a replay of ``method``: a success, or a failure that demotes it (kept, no longer planned with,
        ``reason`` recorded). Read-only stores and unknown methods are left alone."""
        if self.readonly:
            return
        if succeeded:
            self._query("UPDATE refinements SET replays = replays + 1 WHERE method = ?", (method,))
        else:
            self._query("UPDATE refinements SET failures = failures + 1, status = ?, status_reason = ? "
                        "WHERE method = ?", (DEMOTED, reason or "its replay failed", method))

    def promote(self, method: str, reason: str) -> None:
        """Make ``method`` active again (a repair found the same refinement again, from the hand-written plan)."""
        if not self.readonly:
            self._query("UPDATE refinements SET status = ?, status_reason = ? WHERE method = ?",
                        (ACTIVE, reason, method))

    def export_yaml(self, domain: Any, problems: Iterable[Any] = ()) -> str:
        """The task file of ``domain`` with this memory's refinements of it first, plus ``problems``."""
        refined, _ = self.apply(domain)
        return task_file_yaml(refined, problems)


def _repair_column(refinement: Refinement) -> dict[str, Any]:
    """The ``repair`` column: the repair's account plus the perceived facts and the rewritten goal (schema v3 has
    no columns of their own for them)."""
    column = dict(refinement.repair)
    if refinement.facts:
        column["facts"] = refinement.facts
    if refinement.goal is not None:
        column["goal"] = refinement.goal
    if refinement.rebind:
        column["rebind"] = refinement.rebind
    return column


def _perceived_facts(facts: tuple[Iterable[Sequence[str]], Iterable[Sequence[str]]] | None, mentioned: set[str],
                     names: dict[str, str], start_objects: dict[str, Any]
                     ) -> tuple[dict[str, list[list[str]]], list[tuple[str, str, str]]]:
    """The repair's facts about entities the refinement names and the world reported, and the ``seen`` conditions
    (world name, attribute, value) that confirm them by perception."""
    if facts is None:
        return {}, []
    entities = {m for m in mentioned if names.get(m, m) in start_objects}

    def about_entities(atoms: Iterable[Sequence[str]]) -> list[list[str]]:
        return sorted({tuple(str(a) for a in f) for f in atoms if entities.intersection(str(a) for a in f[1:])})

    add, delete = (about_entities(atoms) for atoms in facts)
    seen = []
    for fact in add:
        if len(fact) == 3 and fact[1] in entities and all(_SYMBOL.match(x) for x in fact):
            world_name = names.get(fact[1], fact[1])
            if seen_holds(start_objects, world_name, fact[0], fact[2]):
                seen.append((world_name, fact[0], fact[2]))
    kept = {key: [list(f) for f in atoms] for key, atoms in (("add", add), ("delete", delete)) if atoms}
    return kept, seen


# -- the task-file writer ---------------------------------------------------------------------------------------


def _parameter_list(names: Sequence[str], types: Sequence[str | None]) -> list[str]:
    return [f"?{name} - {kind}" if kind else f"?{name}" for name, kind in zip(names, types, strict=True)]


def task_file_yaml(domain: Any, problems: Iterable[Any] = (), header: str | None = None) -> str:
    """``domain`` (and ``problems``) in the task-file format; ``load_task_text`` reads it back to the same model."""
    data: dict[str, Any] = {}
    body: dict[str, Any] = {"name": domain.name}
    if domain.types:
        body["types"] = dict(domain.types) if any(domain.types.values()) else list(domain.types)
    if domain.predicates:
        body["predicates"] = {name: list(types) for name, types in domain.predicates.items()}
    if domain.external:
        body["external"] = {name: list(types) for name, types in domain.external.items()}
    if domain.axioms:
        body["axioms"] = [{"head": template_text(a.head_pred, a.head_args), "when": a.source} for a in domain.axioms]
    primitives: dict[str, Any] = {}
    for name, primitive in domain.primitives.items():
        entry: dict[str, Any] = {"parameters": _parameter_list(primitive.parameters, primitive.types)}
        if not primitive.precondition.trivial:
            entry["precondition"] = primitive.precondition.source
        entry["add"] = [template_text(t[0], t[1:]) for t in primitive.add]
        entry["delete"] = [template_text(t[0], t[1:]) for t in primitive.delete]
        if primitive.conditional:  # forall / when effects (docs/task-files.md, "Conditional effects")
            entry["effects"] = [{key: value for key, value in {
                "forall": [f"?{v} - {t}" for v, t in zip(e.variables, e.types, strict=True)],
                "when": None if e.when.trivial else e.when.source,
                "add": [template_text(t[0], t[1:]) for t in e.add],
                "delete": [template_text(t[0], t[1:]) for t in e.delete]}.items() if value}
                for e in primitive.conditional]
        if primitive.cost != 1:
            entry["cost"] = primitive.cost
        if primitive.expectations:
            entry["expectations"] = primitive.expectations
        primitives[name] = entry
    body["primitives"] = primitives
    if domain.tasks:
        body["tasks"] = {name: _parameter_list(task.parameters, task.types) for name, task in domain.tasks.items()}
    methods = []
    for method in domain.methods:
        entry = {"name": method.name, "task": method.task_text()}
        if not method.precondition.trivial:
            entry["precondition"] = method.precondition.source
        entry["subtasks" if method.ordered else "unordered"] = method.subtask_texts()
        methods.append(entry)
    if methods:
        body["methods"] = methods
    data["domain"] = body
    written = {}
    for problem in problems:
        entry = {}
        if problem.objects:
            entry["objects"] = {kind: list(names) for kind, names in problem.objects.items()}
        entry["init"] = [atom_text(a) for a in problem.init]
        entry["tasks"] = [atom_text(a) for a in problem.tasks]
        if problem.goal:
            entry["goal"] = [atom_text(a) for a in problem.goal]
        written[problem.name] = entry
    if written:
        data["problems"] = written
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=False, width=1_000_000, allow_unicode=True)
    return (header or f"# {domain.name} with learned refinements (written by bt-meta)\n") + text
