"""The HTN planner: SHOP2-style total-order forward decomposition, iterative, returning a decomposition tree.

Offers:

* :func:`plan` -- plan a problem of a domain; never raises on "no plan", returns a :class:`PlanResult`
* :class:`PlanResult` -- status (``success`` / ``no_plan`` / ``budget_exhausted``), plan, tree, stats, message
* :class:`GroundAction` -- one step of the plan, with the id of its tree node
* :class:`Search` -- the search engine, shared with :mod:`bt_meta.htn.replan`

How it searches (docs/task-files.md has the full statement): the task network is an agenda processed left
to right. A primitive applies when its argument types and precondition hold; its effects give the next state.
A compound task tries its methods in file order; a method applies when its head unifies with the task and its
precondition has a satisfier; the satisfiers are tried in SHOP2 order (atoms matched left to right, facts in
state order). Every task expansion with an alternative left pushes a choice point (an iterator over the
remaining alternatives) on an explicit stack; a dead end resumes the most recent choice point, undoing the
agenda, state, tree and plan to what they were there. No Python recursion is involved, so plans of any length
fit. A compound task that reappears below itself in the same state (same ground task, equal state) is a loop
and that branch fails. A search node (state and agenda) met again after its whole subtree failed fails at once.
Goal facts, when the problem has some, must hold at the end, else the search backtracks; a node whose state lacks
a goal fact that no task left on its agenda could add fails at once (:mod:`bt_meta.htn.achievers`; each agenda
cell carries the goal facts its tasks could add). Nested expansions of a recursive task in the same state (left
recursion) form a chain whose depth is bounded per outermost expansion and raised one level at a time when a cut
happened below it (iterative deepening), so short chains come before long detours; without a cut the search
order is the plain one. ``Search(goal_pruning=False, deepening=False)`` is the plain search.

The alternatives of a task come from the domain's generated code (:mod:`bt_meta.htn.compiled`) where there is
some, else from the reference path here (:meth:`Search._method_alternatives`, primitives' satisfiers); both give
the same alternatives in the same order.
"""

from __future__ import annotations

import gc
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from bt_meta.htn.achievers import GoalAchievers
from bt_meta.htn.compiled import compiled_domain
from bt_meta.htn.conditions import ExternalFn, Var
from bt_meta.htn.model import Domain, Method, Problem, types_hold
from bt_meta.htn.state import Atom, State, atom_text
from bt_meta.htn.tree import DecompositionNode, DecompositionTree

# agenda item kinds
TASK, CLOSE, UNORDERED = 0, 1, 2
# undo entries of the search's loop-check and chain bookkeeping
ACTIVE_PUSHED, ACTIVE_CLOSED, CHAIN_PUSHED, CHAIN_CLOSED = 0, 1, 2, 3
# failed search nodes remembered per search at most (each keeps its state and agenda alive); past it the search
# goes on without remembering more, which only costs the skips it would have made
MEMO_LIMIT = 200_000


@dataclass
class GroundAction:
    name: str
    args: tuple[str, ...]
    node_id: str

    def as_list(self) -> list[str]:
        return [self.name, *self.args]

    def __str__(self) -> str:
        return atom_text((self.name, *self.args))


@dataclass
class PlanResult:
    status: str  # "success", "no_plan" or "budget_exhausted"
    plan: list[GroundAction]
    tree: DecompositionTree | None
    stats: dict[str, Any]
    message: str
    state: State | None = None  # final state when successful
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "success"


_IDS: list[str] = []  # "n0", "n1", ...: made once, shared by every search that starts at id 0


def _node_ids(offset: int, count: int) -> list[str]:
    global _IDS
    if offset:
        return [f"n{offset + index}" for index in range(count)]
    ids = _IDS
    if len(ids) < count:
        # a new list, swapped in whole: a search in another thread keeps reading a complete one
        ids = ids + [f"n{index}" for index in range(len(ids), count)]
        _IDS = ids
    return ids


def _mask(agenda: tuple | None) -> int:
    return 0 if agenda is None else agenda[2]


def _item_mask(item: tuple, of_task: Any) -> int:
    """The goal mask of a TASK or UNORDERED agenda item (CLOSE items add nothing)."""
    kind = item[0]
    if kind == TASK:
        return of_task(item[1])
    mask = 0
    if kind == UNORDERED:
        for sub in item[1]:
            mask |= of_task(sub)
    return mask


def _unify_head(method: Method, task: tuple[str, ...]) -> dict[str, str] | None:
    args = method.task_args
    if len(args) != len(task) - 1:
        return None
    env: dict[str, str] = {}
    for term, value in zip(args, task[1:], strict=False):
        if term.__class__ is Var:
            prior = env.get(term.name)  # type: ignore[union-attr]
            if prior is None:
                env[term.name] = value  # type: ignore[union-attr]
            elif prior != value:
                return None
        elif term != value:
            return None
    return env


class Search:
    """One search over an agenda. Parent keys of new nodes are trail indices (int) or existing node ids (str)."""

    def __init__(self, domain: Domain, *, external: ExternalFn | None = None, max_nodes: int | None = None,
                 max_seconds: float | None = None, id_offset: int = 0, step_offset: int = 0,
                 goal: list[Atom] | None = None, goal_pruning: bool = True, deepening: bool = True) -> None:
        self.domain = domain
        # the two search refinements (module docstring); off, the search is the plain one (tests compare them)
        self.goal_pruning = goal_pruning
        self.deepening = deepening
        self.external = external
        self.max_nodes = max_nodes
        self.max_seconds = max_seconds
        self.id_offset = id_offset
        self.step_offset = step_offset
        self.goal = goal or []
        self.expansions = 0
        self.backtracks = 0
        self.loops = 0
        self.memo_pruned = 0
        self.goal_pruned = 0
        self.depth_cuts = 0
        self.deepenings = 0
        self.deepest: tuple[int, str] | None = None  # (plan length, description) of the deepest dead end
        self.started = time.perf_counter()

    # -- alternatives ----------------------------------------------------------------------------------------
    def _method_alternatives(self, task: tuple[str, ...], state: State, exclude: Any) -> Iterator[tuple]:
        """The reference path: ``(method, bindings, subtasks)`` per method and satisfier, in search order."""
        external = self.external
        args = task[1:]
        for method in self.domain.methods_by_task.get(task[0], ()):
            names = method.head_names
            if names is not None and len(names) == len(args):
                env = dict(zip(names, args, strict=False))  # lengths checked just above
            else:
                env = _unify_head(method, task)
                if env is None:
                    continue
            builders = method.subtask_builders
            for satisfier in method.precondition.satisfiers_of(state, env, external):
                if exclude is not None and (method.name, frozenset(satisfier.items())) == exclude:
                    continue
                yield method, satisfier, tuple(build(satisfier) for build in builders)

    def _alternatives_again(self, item: tuple, state: State, compiled: Any, typed: Any) -> Iterator[tuple]:
        """The alternatives of a compound task item from the start, as its expansion made them."""
        task = item[1]
        name = task[0]
        if name in typed and not types_hold(self.domain.tasks[name].types, task[1:], state):
            return iter(())
        expanders = compiled.for_size(state._len if state._len >= compiled.threshold else 0)[0]
        expander = expanders.get(name) if item[3] is None else None
        if expander is not None:
            return expander(state, *task[1:])
        return self._method_alternatives(task, state, item[3])

    def _dead_end(self, plan_len: int, description: str) -> None:
        if self.deepest is None or plan_len >= self.deepest[0]:
            self.deepest = (plan_len, description)

    def _explain(self, task: tuple[str, ...], state: State) -> str:
        name = task[0]
        if name in self.domain.primitives:
            prim = self.domain.primitives[name]
            if not types_hold(prim.types, task[1:], state):
                return f"{atom_text(task)}: its argument types do not hold"
            return f"{atom_text(task)}: precondition false: {prim.precondition.source}"
        decl = self.domain.tasks[name]
        if not types_hold(decl.types, task[1:], state):
            return f"{atom_text(task)}: its argument types do not hold"
        methods = self.domain.methods_by_task.get(name, [])
        if not methods:
            return f"{atom_text(task)}: no method decomposes this task"
        return f"{atom_text(task)}: no method applies (tried {', '.join(m.name for m in methods)})"

    # -- the search ------------------------------------------------------------------------------------------
    def run(self, state: State, items: list[tuple]) -> PlanResult:
        """Search with the cyclic garbage collector paused.

        The search allocates many small acyclic objects (agenda cells, bindings, states) while the tree it
        keeps grows; every generation-2 collection would traverse all of it again, which made long plans
        superlinear. Nothing here creates reference cycles that need collecting during the search, and the
        collector's previous setting is restored afterwards.
        """
        axiom_set = self.domain.axiom_set
        if axiom_set is not None:
            axiom_set.begin()
        enabled = gc.isenabled()
        if enabled:
            gc.disable()
        try:
            # goal pruning costs an analysis of the tasks met, which a search that meets no complete plan failing
            # its goal does not need: it starts without, and begins again with it at the first such failure (the
            # first plan is the same either way: the pruning only cuts subtrees without a plan)
            result = self._run(state, items, False)
            if result is None:
                result = self._run(state, items, True)
            return result
        finally:
            if enabled:
                gc.enable()

    def _run(self, state: State, items: list[tuple], prune_goal: bool) -> PlanResult | None:
        domain = self.domain
        primitives = domain.primitives
        tasks_decl = domain.tasks
        external = self.external
        compiled = compiled_domain(domain)
        recursive = compiled.recursive
        typed = compiled.typed_tasks
        threshold = compiled.threshold
        small = compiled.for_size(0)  # the variant for large states is made when one is first met
        for_size = compiled.for_size
        # the agenda is a linked list of cells (item, rest, goal mask); the mask (0 without goal pruning) is the
        # goal facts the cell's tasks could still add (see bt_meta.htn.achievers)
        achievers = GoalAchievers(domain, self.goal) if prune_goal else None
        if not achievers:
            achievers = None
        of_task = achievers.of_task if achievers is not None else None
        missing = achievers.missing(state) if achievers is not None else 0
        missing_for = state  # the state ``missing`` is of
        agenda: tuple | None = None
        for item in reversed(items):
            agenda = (item, agenda, 0 if of_task is None else _item_mask(item, of_task) | _mask(agenda))
        # search nodes whose whole subtree failed: (state hash, id of the agenda) -> [(state, agenda)]. The agenda
        # is compared by identity: the same agenda object holds the same tasks and loop-check entries (CLOSE
        # items) whatever path led to it, and the subtree below a node depends only on its state and agenda
        failed: dict[tuple[int, int], list[tuple[State, tuple]]] = {}
        reached: list[tuple[State, tuple, int]] = []  # compound expansions, with the stack height then
        remembered = 0
        trail: list[tuple] = []  # (task, kind, method, bindings, parent_key, state_before, step)
        plan: list[int] = []
        active: dict[tuple, list[State]] = {}
        # open expansions of recursive tasks by task name: [(state, root, depth)], innermost last; root is
        # [depth bound, cut below it in this iteration] of the outermost expansion of a same-state chain
        chains: dict[str, list[tuple]] = {}
        link: tuple | None = None  # the chain entry of the compound expansion being taken
        undo: list[tuple] = []  # (ACTIVE_PUSHED, key) (ACTIVE_CLOSED, key, state) (CHAIN_PUSHED, name)
        # (CHAIN_CLOSED, name, entry, index): what to undo on backtracking, newest last
        # [alternatives, item, rest, state, trail_len, plan_len, undo_len, missing, chain entry or None]
        stack: list[list] = []
        step_offset = self.step_offset
        max_nodes = self.max_nodes
        deadline = self.started + self.max_seconds if self.max_seconds is not None else None
        expansions = self.expansions
        first_bound = 1 if self.deepening else sys.maxsize  # the first depth bound of a chain
        advance = False
        while True:
            if advance:
                # backtrack: resume the most recent choice point that has another alternative
                advance = False
                while stack:
                    cp = stack[-1]
                    state = missing_for = cp[3]
                    missing = cp[7]
                    del trail[cp[4]:]
                    del plan[cp[5]:]
                    while len(undo) > cp[6]:
                        entry = undo.pop()
                        tag = entry[0]
                        if tag == ACTIVE_PUSHED:
                            states = active[entry[1]]
                            states.pop()
                            if not states:
                                del active[entry[1]]
                        elif tag == ACTIVE_CLOSED:
                            active.setdefault(entry[1], []).append(entry[2])
                        elif tag == CHAIN_PUSHED:
                            entries = chains[entry[1]]
                            entries.pop()
                            if not entries:
                                del chains[entry[1]]
                        else:
                            chains.setdefault(entry[1], []).insert(entry[3], entry[2])
                    alternative = next(cp[0], None)
                    link = cp[8]
                    if alternative is None and link is not None and link[2] == 0 and link[1][1]:
                        # a chain below this root was cut at its depth bound: its next, deeper iteration
                        root = link[1]
                        root[0] += 1
                        root[1] = False
                        self.deepenings += 1
                        cp[0] = self._alternatives_again(cp[1], state, compiled, typed)
                        alternative = next(cp[0], None)
                    if alternative is not None:
                        # every search node reached after this choice point was made has failed as a whole
                        height = len(stack) - 1
                        while reached and reached[-1][2] > height:
                            done_state, done_agenda, _ = reached.pop()
                            if remembered < MEMO_LIMIT:
                                remembered += 1
                                failed.setdefault((done_state._hash, id(done_agenda)), []).append(
                                    (done_state, done_agenda))
                        self.backtracks += 1
                        item = cp[1]
                        rest = cp[2]
                        break
                    stack.pop()
                else:
                    self.expansions = expansions
                    return self._failure("no_plan", trail)
            else:
                if agenda is None:
                    if self.goal and not self._goal_holds(state):
                        if achievers is None and self.goal_pruning and not prune_goal:
                            self.expansions = expansions
                            return None
                        absent = [atom_text(a) for a in self.goal if not self._holds(a, state)]
                        self._dead_end(len(plan) + 1, f"goal facts do not hold at the end: {', '.join(absent)}")
                        advance = True
                        continue
                    self.expansions = expansions
                    return self._success(trail, plan, state)
                item, rest, _ = agenda
                kind = item[0]
                if kind == CLOSE:
                    states = active[item[1]]
                    states.remove(item[2]) if states[-1] is not item[2] else states.pop()
                    if not states:
                        del active[item[1]]
                    undo.append((ACTIVE_CLOSED, item[1], item[2]))
                    name = item[1][0][0]
                    entries = chains[name]
                    position = len(entries) - 1
                    while entries[position][0] is not item[2]:
                        position -= 1
                    entry = entries.pop(position)
                    if not entries:
                        del chains[name]
                    undo.append((CHAIN_CLOSED, name, entry, position))
                    agenda = rest
                    if entry[2] == 0 and entry[1][0] > first_bound:
                        # a root whose chains were deepened: a decomposition as shallow as an earlier iteration's
                        # is one that iteration tried, and the node after it failed then (the failure memo)
                        bucket = failed.get((state._hash, id(agenda))) if failed else None
                        if bucket is not None and any(a is agenda and s == state for s, a in bucket):
                            self.memo_pruned += 1
                            advance = True
                        elif stack:
                            reached.append((state, agenda, len(stack)))
                    continue
                if achievers is not None:
                    if state is not missing_for:
                        missing = achievers.missing_after(missing, missing_for, state)
                        missing_for = state
                    if missing & ~agenda[2]:
                        self.goal_pruned += 1
                        self._dead_end(len(plan), f"goal fact {atom_text(achievers.first(missing & ~agenda[2]))} "
                                                  "is false and no task left can add it")
                        advance = True
                        continue
                expansions += 1
                if max_nodes is not None and expansions > max_nodes:
                    self.expansions = expansions
                    return self._failure("budget_exhausted", trail, f"node budget of {max_nodes} expansions exhausted")
                if deadline is not None and (expansions & 255) == 0 and time.perf_counter() > deadline:
                    self.expansions = expansions
                    return self._failure("budget_exhausted", trail, f"time budget of {self.max_seconds} s exhausted")
                if kind == UNORDERED:
                    link = None
                    alternatives: Iterator[Any] | None = iter(range(len(item[1])))
                else:
                    task = item[1]
                    name = task[0]
                    expanders, steppers = small if state._len < threshold else for_size(state._len)
                    stepper = steppers.get(name)
                    if stepper is not None:
                        # a primitive with at most one way to apply: no choice point
                        found = stepper(state, *task[1:])
                        if found is None:
                            self._dead_end(len(plan), self._explain(task, state))
                            advance = True
                            continue
                        trail.append((task, "primitive", None, found[0], item[2], state, step_offset + len(plan)))
                        plan.append(len(trail) - 1)
                        state = found[1]
                        agenda = rest
                        continue
                    if name in primitives:
                        link = None
                        found = primitives[name].fast_satisfiers(state, task[1:], external)
                        # at most one way to apply it: no choice point (a dead end resumes the previous one)
                        alternatives = iter(found) if found.__class__ is not tuple or len(found) > 1 else None
                    else:
                        if failed:
                            bucket = failed.get((state._hash, id(agenda)))
                            if bucket is not None and any(a is agenda and s == state for s, a in bucket):
                                self.memo_pruned += 1
                                self._dead_end(len(plan), f"{atom_text(task)}: failed before in the same state with "
                                                          "the same tasks after it")
                                advance = True
                                continue
                        if stack:  # with no choice point left a failure ends the search: nothing to remember
                            reached.append((state, agenda, len(stack)))
                        if name in recursive:
                            key = (task, state._hash)
                            seen = active.get(key)
                            if seen is not None and any(s == state for s in seen):
                                self.loops += 1
                                self._dead_end(len(plan), f"{atom_text(task)}: loop (the task recurs below itself "
                                                          "in the same state)")
                                advance = True
                                continue
                            entries = chains.get(name)
                            parent = entries[-1] if entries is not None else None
                            if parent is not None and parent[0] is state:
                                # the task recurs in the same state: one level deeper in its root's chain
                                root = parent[1]
                                depth = parent[2] + 1
                                if depth > root[0]:
                                    root[1] = True
                                    self.depth_cuts += 1
                                    self._dead_end(len(plan), f"{atom_text(task)}: deeper than {root[0]} nested "
                                                              "expansions of the same task in the same state (for now)")
                                    advance = True
                                    continue
                                link = (state, root, depth)
                            else:
                                link = (state, [first_bound, False], 0)
                        else:
                            link = None
                        if name in typed and not types_hold(tasks_decl[name].types, task[1:], state):
                            alternatives = iter(())
                        else:
                            expander = expanders.get(name) if item[3] is None else None
                            if expander is not None:
                                alternatives = expander(state, *task[1:])
                            else:
                                alternatives = self._method_alternatives(task, state, item[3])
                alternative = next(alternatives if alternatives is not None else iter(found), None)
                if alternative is None:
                    if kind == TASK:
                        self._dead_end(len(plan), self._explain(item[1], state))
                    advance = True
                    continue
                if alternatives is not None:
                    stack.append([alternatives, item, rest, state, len(trail), len(plan), len(undo), missing, link])
            # take ``alternative`` for ``item``
            kind = item[0]
            if kind == TASK:
                task = item[1]
                if task[0] in primitives:
                    prim = primitives[task[0]]
                    add, delete = prim.effects(alternative, state, external)
                    trail.append((task, "primitive", None, alternative, item[2], state, step_offset + len(plan)))
                    plan.append(len(trail) - 1)
                    state = state._apply(add, delete)
                    agenda = rest
                else:
                    method, env, subtasks = alternative
                    index = len(trail)
                    trail.append((task, "compound", method.name, env, item[2], state, None))
                    if task[0] in recursive:
                        key = (task, state._hash)
                        active.setdefault(key, []).append(state)
                        undo.append((ACTIVE_PUSHED, key))
                        chains.setdefault(task[0], []).append(link)
                        undo.append((CHAIN_PUSHED, task[0]))
                        agenda = ((CLOSE, key, state), rest, _mask(rest))
                    else:
                        agenda = rest
                    if method.ordered:
                        for sub in reversed(subtasks):
                            agenda = ((TASK, sub, index, None), agenda,
                                      0 if of_task is None else of_task(sub) | _mask(agenda))
                    elif subtasks:
                        agenda = ((UNORDERED, subtasks, index), agenda,
                                  0 if of_task is None else _item_mask((UNORDERED, subtasks), of_task) | _mask(agenda))
            else:  # UNORDERED: the alternative is the index of the subtask to do first
                subs = item[1]
                remaining = subs[:alternative] + subs[alternative + 1:]
                agenda = rest
                if remaining:
                    agenda = ((UNORDERED, remaining, item[2]), agenda,
                              0 if of_task is None else _item_mask((UNORDERED, remaining), of_task) | _mask(agenda))
                agenda = ((TASK, subs[alternative], item[2], None), agenda,
                          0 if of_task is None else of_task(subs[alternative]) | _mask(agenda))

    def _holds(self, atom: Atom, state: State) -> bool:
        if atom[0] in self.domain.context.derived:
            return atom in self.domain.axiom_set.extension(state, atom[0])
        return atom in state

    def _goal_holds(self, state: State) -> bool:
        return all(self._holds(atom, state) for atom in self.goal)

    def stats(self, **more: Any) -> dict[str, Any]:
        data = {
            "expansions": self.expansions,
            "backtracks": self.backtracks,
            "loops_pruned": self.loops,
            "memo_pruned": self.memo_pruned,
            "goal_pruned": self.goal_pruned,
            "depth_cuts": self.depth_cuts,
            "deepenings": self.deepenings,
            "seconds": round(time.perf_counter() - self.started, 6),
        }
        data.update(more)
        return data

    def node_id(self, index: int) -> str:
        return f"n{self.id_offset + index}"

    def build_nodes(self, trail: list[tuple]) -> list[DecompositionNode]:
        """The trail's nodes with their children (in trail order), ids offset by ``id_offset``."""
        ids = _node_ids(self.id_offset, len(trail))
        node = DecompositionNode
        nodes: list[DecompositionNode] = []
        append = nodes.append
        for index, (task, kind, method, env, parent, state, step) in enumerate(trail):
            if parent.__class__ is int:
                nodes[parent].children.append(ids[index])
                parent = ids[parent]
            append(node(ids[index], task, kind, method, env, parent, state, step, []))
        return nodes

    def _success(self, trail: list[tuple], plan: list[int], state: State) -> PlanResult:
        nodes = self.build_nodes(trail)
        by_id = {node.id: node for node in nodes}
        roots: list[str] = []
        for node, entry in zip(nodes, trail, strict=True):
            parent = entry[4]
            if parent is None:
                roots.append(node.id)
            elif parent.__class__ is not int and parent in by_id:  # an existing id that names a new node
                by_id[parent].children.append(node.id)
        tree = DecompositionTree(by_id, roots)
        actions = [GroundAction(nodes[i].task[0], nodes[i].task[1:], nodes[i].id) for i in plan]
        stats = self.stats(plan_length=len(actions), tree_nodes=len(nodes))
        message = f"plan found: {len(actions)} steps, {len(nodes)} tree nodes, {stats['expansions']} expansions, " \
                  f"{stats['backtracks']} backtracks"
        result = PlanResult("success", actions, tree, stats, message, state)
        result.extra["nodes"] = nodes
        return result

    def _failure(self, status: str, trail: list[tuple], reason: str | None = None) -> PlanResult:
        stats = self.stats()
        if status == "no_plan":
            message = "no plan: every method and binding failed"
            if self.deepest is not None:
                message += f"; deepest dead end after {self.deepest[0]} step(s): {self.deepest[1]}"
        else:
            message = f"budget exhausted: {reason} ({stats['expansions']} expansions, {stats['seconds']:.3f} s) " \
                      "without a plan"
            if self.deepest is not None:
                message += f"; deepest dead end so far after {self.deepest[0]} step(s): {self.deepest[1]}"
        return PlanResult(status, [], None, stats, message)


def plan(domain: Domain, problem: Problem, *, max_nodes: int | None = None, max_seconds: float | None = None,
         external: ExternalFn | None = None) -> PlanResult:
    """Plan ``problem.tasks`` from ``problem.state``; see the module docstring for the semantics."""
    search = Search(domain, external=external, max_nodes=max_nodes, max_seconds=max_seconds, goal=problem.goal)
    items = [(TASK, task, None, None) for task in problem.tasks]
    return search.run(problem.state, items)
