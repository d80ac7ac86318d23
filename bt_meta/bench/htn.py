"""``bt-meta bench htn``: the bt-meta HTN planner against GTPyhop on the same problems, in one process.

Both planners get the same problems, built from GTPyhop's own problem data: the blocks_htn examples (the Sussman
anomaly, SHOP's bw_large_d, IPC-2011 BW-rand-50), seeded random 100- and 200-block problems, and the 30 IPC-2020
total-order Childsnack problems GTPyhop ships. Our side plans with the domains written once in YAML
(``problems/blocks_htn.yaml``, ``problems/childsnack.yaml``); GTPyhop plans with its own example domains. Every
plan from either planner is checked by an independent simulator of the domain before its time counts.

Offers:

* :func:`register` -- adds ``bt-meta bench htn [--json] [--repeat N] [--min-seconds S] [--only NAME] [--seed S]
  [--strategy S]``
* :class:`BenchProblem` and :func:`build_problems` -- the problems, for GTPyhop and for our planner
* :func:`random_blocks_problem` -- a seeded random blocks-world problem (initial and goal towers)
* :func:`validate_blocks_plan`, :func:`validate_childsnack_plan` -- simulate a plan and check the goal
* :func:`run_benchmark` -- run everything and return the JSON-able report that ``--json`` prints
* :class:`GtpyhopMissing` -- GTPyhop (the ``bench`` extra) is not installed

GTPyhop is run as shipped: verbosity 0, goal verification on, and Python's default recursion limit (the
benchmark never raises ``sys.setrecursionlimit``); a RecursionError is reported as such. Its three search
strategies are measured separately: ``recursive_dfs`` (the classic recursive planner with backtracking),
``iterative_dfs_backtracking`` (the same search on an explicit stack, GTPyhop >= 1.9) and ``iterative_greedy``
(GTPyhop's import-time default, which commits to the first applicable method and never backtracks).
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import fnmatch
import gc
import importlib
import importlib.util
import io
import platform
import random
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.errors import BtMetaError, UserInputError

PROBLEMS_DIR = Path(__file__).resolve().parent / "problems"

STRATEGIES = ("recursive_dfs", "iterative_dfs_backtracking", "iterative_greedy")
SHORT_STRATEGY = {"recursive_dfs": "rec", "iterative_dfs_backtracking": "iter-bt", "iterative_greedy": "greedy"}
TARGET_RATIO = 2.0
MIN_SECONDS = 0.2  # default time each planner runs a problem for (at least --repeat runs)
MAX_ROUNDS = 1000  # runs per planner and problem at most
_COMMAND = "bt-meta bench htn"
GENERATED_SIZES = (100, 200)

Atom = tuple[str, ...]
Plan = list[tuple[str, ...]]


class GtpyhopMissing(BtMetaError):
    """GTPyhop is not installed; it comes with the ``bench`` extra."""


@dataclass
class BenchProblem:
    """One problem, in GTPyhop's form and in ours, plus what the validator needs.

    ``gtpyhop_state``/``gtpyhop_todo`` are built lazily (they need the gtpyhop module); ``init``, ``tasks`` and
    ``goal`` are our initial facts, task network and goal facts, converted from the same data.
    """

    name: str
    family: str  # "blocks" or "childsnack"
    size: str
    init: list[Atom]
    tasks: list[Atom]
    goal: list[Atom]
    make_gtpyhop: Callable[[ModuleType], tuple[Any, list[Any]]]
    validate: Callable[[Sequence[Sequence[Any]]], str | None]
    notes: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------------------------------------------
# GTPyhop and its example modules


def import_gtpyhop() -> ModuleType:
    """Import gtpyhop without its import-time banner (it prints to stdout, which would spoil ``--json``)."""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            import gtpyhop
    except ImportError as error:
        raise GtpyhopMissing(
            f"GTPyhop is not installed ({error}); install the benchmark extra: pip install 'bt-meta[bench]'"
        ) from error
    return gtpyhop


def _examples_dir(gtpyhop: ModuleType) -> Path:
    return Path(gtpyhop.__file__).resolve().parent / "examples"


def _load_blocks_htn_domain(gtpyhop: ModuleType) -> Any:
    with contextlib.redirect_stdout(io.StringIO()):
        module = importlib.import_module("gtpyhop.examples.blocks_htn")
    return module.the_domain


_childsnack_module: ModuleType | None = None


def _load_childsnack_module(gtpyhop: ModuleType) -> ModuleType:
    """Import GTPyhop's Childsnack package, whose folder name (``ipc-2020-total-order``) is not importable."""
    global _childsnack_module
    if _childsnack_module is None:
        folder = _examples_dir(gtpyhop) / "ipc-2020-total-order" / "Childsnack"
        if not (folder / "__init__.py").is_file():
            raise BtMetaError(f"GTPyhop's Childsnack example is missing: {folder}")
        name = "_bt_meta_bench_gtpyhop_childsnack"
        spec = importlib.util.spec_from_file_location(
            name, folder / "__init__.py", submodule_search_locations=[str(folder)]
        )
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        with contextlib.redirect_stdout(io.StringIO()):
            spec.loader.exec_module(module)
        _childsnack_module = module
    return _childsnack_module


def _literal_attributes(path: Path, function: str) -> dict[str, Any]:
    """The literal values assigned as ``name.attr = <literal>`` in one function of an example file.

    GTPyhop's blocks examples define their problems as local variables of ``main_legacy``; reading the literals
    out of the source (never executing it) lets both planners use exactly GTPyhop's problem data.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    functions = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == function]
    if not functions:
        raise BtMetaError(f"{path}: no function {function!r}; GTPyhop's examples changed")
    found: dict[str, Any] = {}
    for node in ast.walk(functions[0]):
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1):
            continue
        target = node.targets[0]
        if not (isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name)):
            continue
        try:
            value = ast.literal_eval(node.value)
        except ValueError:
            continue  # e.g. {x: False for x in range(1, 20)}: derived from pos below instead
        found.setdefault(f"{target.value.id}.{target.attr}", value)
    return found


def _required(found: dict[str, Any], key: str, path: Path) -> Any:
    if key not in found:
        raise BtMetaError(f"{path}: no literal assignment to {key}; GTPyhop's examples changed")
    return found[key]


# --------------------------------------------------------------------------------------------------------------
# Blocks world


def _derived_clear(pos: dict[Any, Any]) -> dict[Any, bool]:
    """GTPyhop's ``clear`` for ``pos``, in block order as its examples build it (``{x: False for x in ..}``)."""
    below = set(pos.values())
    try:
        blocks = sorted(pos)
    except TypeError:  # mixed names: keep the order of pos
        blocks = list(pos)
    return {block: block not in below for block in blocks}


def _check_blocks_state(name: str, pos: dict[Any, Any]) -> None:
    """Refuse a malformed blocks state (two blocks on one, a block on a missing block, a cycle)."""
    supports = [p for p in pos.values() if p != "table"]
    if len(supports) != len(set(supports)):
        raise BtMetaError(f"{name}: two blocks on the same block")
    for block, below in pos.items():
        if below != "table" and below not in pos:
            raise BtMetaError(f"{name}: block {block} is on unknown block {below}")
    for block in pos:
        seen = set()
        while block != "table":
            if block in seen:
                raise BtMetaError(f"{name}: a cycle of blocks through {block}")
            seen.add(block)
            block = pos[block]


def _blocks_problem(
    name: str,
    pos: dict[Any, Any],
    goal_pos: dict[Any, Any],
    *,
    clear: dict[Any, bool] | None = None,
    goal_clear: dict[Any, bool] | None = None,
    notes: Iterable[str] = (),
) -> BenchProblem:
    _check_blocks_state(name, pos)
    derived = _derived_clear(pos)
    if clear is not None and any(clear.get(block, False) != is_clear for block, is_clear in derived.items()):
        raise BtMetaError(f"{name}: GTPyhop's clear facts disagree with its pos facts")
    clear = dict(clear) if clear is not None else derived
    goal_clear = dict(goal_clear or {})

    # GTPyhop's m_moveblocks takes the first suitable clear block in the order of its ``clear`` dict: our
    # ``block`` facts are listed in that order, so both planners try blocks alike and find the same plans.
    init: list[Atom] = [("block", str(block)) for block in clear]
    for block, below in pos.items():
        init.append(("on_table", str(block)) if below == "table" else ("on", str(block), str(below)))
    init.extend(("clear", str(block)) for block, is_clear in clear.items() if is_clear)
    init.append(("hand_empty",))
    for block, target in goal_pos.items():
        init.append(("goal_on_table", str(block)) if target == "table" else ("goal_on", str(block), str(target)))
    goal: list[Atom] = [("on_table", str(b)) if t == "table" else ("on", str(b), str(t)) for b, t in goal_pos.items()]
    goal.extend(("clear", str(b)) for b, c in goal_clear.items() if c)

    def make_gtpyhop(gtpyhop: ModuleType) -> tuple[Any, list[Any]]:
        state = gtpyhop.State(f"{name} initial state", pos=dict(pos), clear=dict(clear), holding={"hand": False})
        multigoal = gtpyhop.Multigoal(f"{name} goal", pos=dict(goal_pos))
        if goal_clear:
            multigoal.clear = dict(goal_clear)
        return state, [("achieve", multigoal)]

    str_pos = {str(b): str(p) for b, p in pos.items()}
    str_goal_pos = {str(b): str(p) for b, p in goal_pos.items()}
    str_goal_clear = {str(b): c for b, c in goal_clear.items()}

    def validate(plan: Sequence[Sequence[Any]]) -> str | None:
        return validate_blocks_plan(str_pos, plan, str_goal_pos, str_goal_clear)

    return BenchProblem(
        name=name,
        family="blocks",
        size=f"{len(pos)} blocks",
        init=init,
        tasks=[("achieve",)],
        goal=goal,
        make_gtpyhop=make_gtpyhop,
        validate=validate,
        notes=list(notes),
    )


def validate_blocks_plan(
    pos: dict[str, str],
    plan: Sequence[Sequence[Any]],
    goal_pos: dict[str, str],
    goal_clear: dict[str, bool] | None = None,
) -> str | None:
    """Simulate ``plan`` from ``pos`` (block -> block or "table"); return None if it reaches the goal, else why not.

    An independent blocks-world simulator (neither planner's code), so a wrong plan from either side is caught.
    """
    pos = dict(pos)
    holding: str | None = None

    def is_clear(block: str) -> bool:
        return holding != block and block not in pos.values()

    for step, action in enumerate(plan):
        name, args = str(action[0]), [str(a) for a in action[1:]]
        error = None
        if name == "pickup" and len(args) == 1:
            (x,) = args
            if holding is not None or pos.get(x) != "table" or not is_clear(x):
                error = "needs an empty hand and a clear block on the table"
            else:
                pos[x], holding = "hand", x
        elif name == "unstack" and len(args) == 2:
            x, y = args
            if holding is not None or pos.get(x) != y or y == "table" or not is_clear(x):
                error = f"needs an empty hand and clear {x} on {y}"
            else:
                pos[x], holding = "hand", x
        elif name == "putdown" and len(args) == 1:
            (x,) = args
            if holding != x:
                error = f"not holding {x}"
            else:
                pos[x], holding = "table", None
        elif name == "stack" and len(args) == 2:
            x, y = args
            if holding != x or x == y or y not in pos or not is_clear(y):
                error = f"needs {x} in hand and {y} clear"
            else:
                pos[x], holding = y, None
        else:
            error = "unknown action"
        if error:
            return f"step {step} {name}{tuple(args)}: {error}"
    wrong = [b for b, target in goal_pos.items() if pos.get(b) != target]
    if wrong:
        return f"goal not reached: {len(wrong)} block(s) misplaced, e.g. {wrong[0]} on {pos.get(wrong[0])}"
    not_clear = [b for b, want in (goal_clear or {}).items() if want and not is_clear(b)]
    if not_clear:
        return f"goal not reached: {not_clear[0]} is not clear"
    return None


def random_blocks_problem(n: int, seed: int) -> tuple[dict[int, Any], dict[int, Any]]:
    """A random initial state and a random complete goal over blocks 1..n, as GTPyhop ``pos`` dicts.

    Blocks are shuffled and cut into towers (a new tower starts with probability 0.3), independently for the
    initial state and the goal; every block has a goal position, as in the IPC BW-rand problems.
    """
    rng = random.Random(seed * 100_003 + n)

    def towers() -> dict[int, Any]:
        blocks = list(range(1, n + 1))
        rng.shuffle(blocks)
        pos: dict[int, Any] = {}
        previous: int | None = None
        for block in blocks:
            if previous is None or rng.random() < 0.3:
                pos[block] = "table"
            else:
                pos[block] = previous
            previous = block
        return dict(sorted(pos.items()))

    return towers(), towers()


def _blocks_problems(gtpyhop: ModuleType, seed: int) -> list[BenchProblem]:
    examples = _examples_dir(gtpyhop)
    htn_path = examples / "blocks_htn" / "examples.py"
    hgn_path = examples / "blocks_hgn" / "examples.py"
    htn = _literal_attributes(htn_path, "main_legacy")
    problems = [
        _blocks_problem(
            "sussman",
            _required(htn, "sus_s0.pos", htn_path),
            _required(htn, "sus_sg.pos", htn_path),
            clear=_required(htn, "sus_s0.clear", htn_path),
        ),
        _blocks_problem(
            "bw_large_d",
            _required(htn, "state3.pos", htn_path),
            _required(htn, "goal3.pos", htn_path),
            goal_clear=htn.get("goal3.clear"),
        ),
    ]
    # blocks_htn's examples skip IPC-2011 BW-rand-50 "for brevity"; its data is in the sibling blocks_hgn examples.
    hgn = _literal_attributes(hgn_path, "main_legacy")
    problems.append(
        _blocks_problem(
            "bw_rand_50",
            _required(hgn, "IPC2011BWrand50.pos", hgn_path),
            _required(hgn, "IPC2011BWrand50Goal.pos", hgn_path),
            notes=["problem data from GTPyhop's blocks_hgn examples (blocks_htn's examples skip it)"],
        )
    )
    for n in GENERATED_SIZES:
        pos, goal_pos = random_blocks_problem(n, seed)
        problems.append(_blocks_problem(f"blocks_{n}", pos, goal_pos, notes=[f"random, seed {seed}"]))
    return problems


# --------------------------------------------------------------------------------------------------------------
# Childsnack

_CHILDSNACK_SET_PREDICATES = (
    "allergic_gluten",
    "not_allergic_gluten",
    "at_kitchen_bread",
    "at_kitchen_content",
    "at_kitchen_sandwich",
    "no_gluten_bread",
    "no_gluten_content",
    "no_gluten_sandwich",
    "notexist",
)


def _childsnack_facts(state: Any) -> set[Atom]:
    """Our ground facts for one of GTPyhop's Childsnack states (sets are unary facts, dicts binary ones)."""
    facts: set[Atom] = set()
    for predicate in _CHILDSNACK_SET_PREDICATES:
        facts.update((predicate, str(x)) for x in getattr(state, predicate))
    facts.update(("at", str(t), str(p)) for t, p in state.at.items())
    facts.update(("waiting", str(c), str(p)) for c, p in state.waiting.items())
    facts.update(("ontray", str(s), str(t)) for s, t in state.ontray.items())
    facts.update(("served", str(c)) for c in state.served)
    return facts


def validate_childsnack_plan(init: Iterable[Atom], plan: Sequence[Sequence[Any]], goal: Iterable[Atom]) -> str | None:
    """Simulate a Childsnack plan with the IPC-2020 action definitions; None if it reaches the goal, else why not."""
    facts = set(init)
    for step, action in enumerate(plan):
        name, args = str(action[0]), tuple(str(a) for a in action[1:])
        pre: list[Atom]
        add: list[Atom]
        delete: list[Atom]
        if name in ("make_sandwich_no_gluten", "make_sandwich") and len(args) == 3:
            s, b, c = args
            pre = [("at_kitchen_bread", b), ("at_kitchen_content", c), ("notexist", s)]
            add, delete = [("at_kitchen_sandwich", s)], [("at_kitchen_bread", b), ("at_kitchen_content", c)]
            delete.append(("notexist", s))
            if name == "make_sandwich_no_gluten":
                pre += [("no_gluten_bread", b), ("no_gluten_content", c)]
                add.append(("no_gluten_sandwich", s))
        elif name == "put_on_tray" and len(args) == 2:
            s, t = args
            pre, add, delete = [("at_kitchen_sandwich", s), ("at", t, "kitchen")], [("ontray", s, t)], []
            delete.append(("at_kitchen_sandwich", s))
        elif name in ("serve_sandwich_no_gluten", "serve_sandwich") and len(args) == 4:
            s, c, t, p = args
            pre = [("ontray", s, t), ("waiting", c, p), ("at", t, p)]
            if name == "serve_sandwich_no_gluten":
                pre += [("allergic_gluten", c), ("no_gluten_sandwich", s)]
            else:
                pre.append(("not_allergic_gluten", c))
            add, delete = [("served", c)], [("ontray", s, t)]
        elif name == "move_tray" and len(args) == 3:
            t, p1, p2 = args
            pre, add, delete = [("at", t, p1)], [("at", t, p2)], [("at", t, p1)]
        elif name == "nop" and not args:
            pre, add, delete = [], [], []
        else:
            return f"step {step} {name}{args}: unknown action"
        missing = [atom for atom in pre if atom not in facts]
        if missing:
            return f"step {step} {name}{args}: precondition {missing[0]} does not hold"
        facts.difference_update(delete)
        facts.update(add)
    unmet = [atom for atom in goal if atom not in facts]
    if unmet:
        return f"goal not reached: {len(unmet)} goal fact(s) false, e.g. {unmet[0]}"
    return None


def _childsnack_problems(gtpyhop: ModuleType) -> list[BenchProblem]:
    module = _load_childsnack_module(gtpyhop)
    problems = []
    for key, (state, goal, _description) in sorted(module.get_problems().items()):
        name = key  # "childsnack_p01"
        facts = _childsnack_facts(state)
        init = sorted(facts)
        tasks: list[Atom] = [("serve", str(child)) for child in goal]
        goal_atoms: list[Atom] = [("served", str(child)) for child in goal]

        def make_gtpyhop(gtpyhop: ModuleType, state: Any = state, goal: Any = goal, name: str = name) -> Any:
            return state, [gtpyhop.Multigoal(f"goal_{name}", served=dict(goal))]

        def validate(plan: Sequence[Sequence[Any]], init: list[Atom] = init, goal_atoms: list[Atom] = goal_atoms):
            return validate_childsnack_plan(init, plan, goal_atoms)

        problems.append(
            BenchProblem(
                name=name,
                family="childsnack",
                size=f"{len(goal)} children",
                init=init,
                tasks=tasks,
                goal=goal_atoms,
                make_gtpyhop=make_gtpyhop,
                validate=validate,
            )
        )
    return problems


def build_problems(gtpyhop: ModuleType, *, seed: int = 1) -> list[BenchProblem]:
    """Every benchmark problem, in benchmark order."""
    return _blocks_problems(gtpyhop, seed) + _childsnack_problems(gtpyhop)


def select_problems(problems: list[BenchProblem], only: str | None) -> list[BenchProblem]:
    """Filter by ``--only``: comma-separated names or shell patterns (``childsnack_p0*``)."""
    if not only:
        return problems
    patterns = [p.strip() for p in only.split(",") if p.strip()]
    chosen = [p for p in problems if any(fnmatch.fnmatchcase(p.name, pattern) for pattern in patterns)]
    unmatched = [pat for pat in patterns if not any(fnmatch.fnmatchcase(p.name, pat) for p in problems)]
    if unmatched or not chosen:
        names = ", ".join(p.name for p in problems)
        raise UserInputError(f"--only {','.join(unmatched) or only!r} matches no problem; problems: {names}", _COMMAND)
    return chosen


# --------------------------------------------------------------------------------------------------------------
# Running the planners


def _interleaved_best(repeat: int, contenders: dict[str, Callable[[], dict[str, Any]]],
                      min_seconds: float = 0.0) -> dict[str, dict[str, Any]]:
    """Run every contender once per round and keep each one's fastest run.

    Interleaving the planners round by round keeps a change in machine load from favouring whichever ran
    first. A contender is done after ``repeat`` runs once its runs add up to ``min_seconds`` (or after
    ``MAX_ROUNDS``): on problems that take a fraction of a millisecond, three runs measure the machine's noise
    more than the planner. A failed run is deterministic, so a contender that fails is not run again.
    """
    best: dict[str, dict[str, Any]] = {}
    runs: dict[str, int] = {}
    spent: dict[str, float] = {}
    running = list(contenders)
    while running:
        for name in list(running):
            # a full collection before a contender's first run and after a long one (a clean heap for each);
            # between the many runs of a fast problem a young-generation one, or collecting would take longer
            # than the runs
            gc.collect(2 if name not in best or best[name]["seconds"] >= 0.01 else 0)
            outcome = contenders[name]()
            runs[name] = runs.get(name, 0) + 1
            spent[name] = spent.get(name, 0.0) + outcome["seconds"]
            if name not in best or outcome["status"] != "success" or outcome["seconds"] < best[name]["seconds"]:
                best[name] = outcome
            if outcome["status"] != "success" or runs[name] >= MAX_ROUNDS or (
                    runs[name] >= repeat and spent[name] >= min_seconds):
                running.remove(name)
    for name, outcome in best.items():
        outcome["runs"] = runs[name]
    return best


def _best_of(repeat: int, run: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """The fastest of ``repeat`` runs of one planner (a failing run is not repeated)."""
    return _interleaved_best(repeat, {"only": run})["only"]


def _run_gtpyhop_once(gtpyhop: ModuleType, domain: Any, problem: BenchProblem, strategy: str) -> dict[str, Any]:
    state, todo = problem.make_gtpyhop(gtpyhop)
    with contextlib.redirect_stdout(io.StringIO()):
        gtpyhop.set_verbose_level(0)
    gtpyhop.set_current_domain(domain)
    gtpyhop.set_recursive_planning(strategy)
    plan: Any = None
    status, message = "success", ""
    start = time.perf_counter()
    try:
        plan = gtpyhop.find_plan(state, todo)
    except RecursionError as error:
        status, message = "recursion_error", f"RecursionError: {error}"
    except Exception as error:  # GTPyhop raises bare Exceptions (e.g. a failed goal verification)
        status, message = "error", f"{type(error).__name__}: {error}"
    seconds = time.perf_counter() - start
    # GTPyhop's global structured logger keeps every entry; drop them so repeats do not pile up memory.
    with contextlib.suppress(Exception):
        gtpyhop.get_logger("gtpyhop_global").clear_logs()
    outcome: dict[str, Any] = {"status": status, "seconds": seconds, "plan_length": None, "valid": None}
    if status == "success":
        if plan is False or plan is None:
            outcome["status"], message = "no_plan", "find_plan returned False"
        else:
            outcome["plan_length"] = len(plan)
            error_text = problem.validate(plan)
            outcome["valid"] = error_text is None
            if error_text:
                outcome["status"], message = "invalid_plan", error_text
    outcome["message"] = message
    return outcome


def run_gtpyhop(gtpyhop: ModuleType, domains: dict[str, Any], problem: BenchProblem, strategy: str, repeat: int):
    return _best_of(repeat, lambda: _run_gtpyhop_once(gtpyhop, domains[problem.family], problem, strategy))


class OurPlanner:
    """Our domains loaded once from the shipped YAML, and the problems converted into our model."""

    def __init__(self, problems: Sequence[BenchProblem]) -> None:
        from bt_meta import htn

        self._htn = htn
        self.domains: dict[str, Any] = {}
        self.problems: dict[str, Any] = {}
        for family, filename in (("blocks", "blocks_htn.yaml"), ("childsnack", "childsnack.yaml")):
            domain = htn.load_task_file(PROBLEMS_DIR / filename).domain
            self.domains[family] = domain
            for p in problems:
                if p.family == family:
                    self.problems[p.name] = htn.problem_from_atoms(
                        domain, p.name, init=p.init, tasks=p.tasks, goal=p.goal
                    )

    def run_once(self, problem: BenchProblem, max_seconds: float | None) -> dict[str, Any]:
        domain, ours = self.domains[problem.family], self.problems[problem.name]
        start = time.perf_counter()
        try:
            result = self._htn.plan(domain, ours, max_seconds=max_seconds)
        except RecursionError as error:
            seconds = time.perf_counter() - start
            return _failure("recursion_error", seconds, f"RecursionError: {error}")
        seconds = time.perf_counter() - start
        if result.status != "success":
            return _failure(result.status, seconds, result.message)
        plan = [(action.name, *action.args) for action in result.plan]
        outcome: dict[str, Any] = {
            "status": "success",
            "seconds": seconds,
            "plan_length": len(plan),
            "tree_nodes": len(result.tree.nodes) if result.tree is not None else None,
            "message": "",
        }
        if result.tree is None:
            outcome["status"], outcome["message"] = "no_tree", "the planner returned no decomposition tree"
            return outcome
        error_text = problem.validate(plan)
        outcome["valid"] = error_text is None
        if error_text:
            outcome["status"], outcome["message"] = "invalid_plan", error_text
        return outcome

    def run(self, problem: BenchProblem, repeat: int, max_seconds: float | None) -> dict[str, Any]:
        return _best_of(repeat, lambda: self.run_once(problem, max_seconds))


def _failure(status: str, seconds: float, message: str) -> dict[str, Any]:
    return {"status": status, "seconds": seconds, "plan_length": None, "valid": None, "message": message}


def run_benchmark(
    *,
    repeat: int = 3,
    min_seconds: float = MIN_SECONDS,
    only: str | None = None,
    seed: int = 1,
    strategies: Sequence[str] = STRATEGIES,
    max_seconds: float | None = 300.0,
    progress: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Run both planners on every selected problem, interleaved round by round; return the ``--json`` report."""
    gtpyhop = import_gtpyhop()
    problems = select_problems(build_problems(gtpyhop, seed=seed), only)
    domains = {"blocks": _load_blocks_htn_domain(gtpyhop), "childsnack": _load_childsnack_module(gtpyhop).the_domain}
    ours = OurPlanner(problems)
    rows = []
    for problem in problems:
        row: dict[str, Any] = {"name": problem.name, "family": problem.family, "size": problem.size}
        contenders: dict[str, Callable[[], dict[str, Any]]] = {
            "ours": lambda problem=problem: ours.run_once(problem, max_seconds)
        }
        for strategy in strategies:
            contenders[strategy] = lambda problem=problem, strategy=strategy: _run_gtpyhop_once(
                gtpyhop, domains[problem.family], problem, strategy
            )
        best = _interleaved_best(repeat, contenders, min_seconds)
        row["ours"] = best["ours"]
        row["gtpyhop"] = {s: best[s] for s in strategies}
        row["ratio"] = {
            s: (g["seconds"] / row["ours"]["seconds"])
            if g["status"] == "success" and row["ours"]["status"] == "success" and row["ours"]["seconds"] > 0
            else None
            for s, g in row["gtpyhop"].items()
        }
        if problem.notes:
            row["notes"] = problem.notes
        rows.append(row)
        if progress is not None:
            progress(row)
    return {
        "benchmark": "htn",
        "baseline": f"GTPyhop {getattr(gtpyhop, '__version__', '?')}",
        "python": platform.python_version(),
        "recursion_limit": sys.getrecursionlimit(),
        "repeat": repeat,
        "min_seconds": min_seconds,
        "seed": seed,
        "strategies": list(strategies),
        "target_ratio": TARGET_RATIO,
        "problems": rows,
        "summary": _summary(rows, strategies),
    }


def _summary(rows: list[dict[str, Any]], strategies: Sequence[str]) -> dict[str, Any]:
    ratios = [(r["ratio"][s], r["name"], s) for r in rows for s in strategies if r["ratio"].get(s) is not None]
    ours_failed = [r["name"] for r in rows if r["ours"]["status"] != "success"]
    gtpyhop_failures: dict[str, dict[str, list[str]]] = {}
    for r in rows:
        for s, g in r["gtpyhop"].items():
            if g["status"] != "success":
                gtpyhop_failures.setdefault(s, {}).setdefault(g["status"], []).append(r["name"])
    slowest = min(ratios) if ratios else None
    return {
        "ours_failed": ours_failed,
        "gtpyhop_failures": gtpyhop_failures,
        "min_ratio": None if slowest is None else {"ratio": slowest[0], "problem": slowest[1], "strategy": slowest[2]},
        "target_met": not ours_failed and slowest is not None and slowest[0] >= TARGET_RATIO,
    }


# --------------------------------------------------------------------------------------------------------------
# Command line


def _cell_ms(outcome: dict[str, Any]) -> str:
    labels = {
        "recursion_error": "RecursionError",
        "no_plan": "no plan",
        "invalid_plan": "INVALID",
        "error": "error",
        "budget_exhausted": "budget",
        "no_tree": "no tree",
    }
    if outcome["status"] != "success":
        return labels.get(outcome["status"], outcome["status"])
    ms = outcome["seconds"] * 1000
    return f"{ms:.3f}" if ms < 1 else f"{ms:.1f}"  # three decimals below a millisecond, where the ratio lives


def _gtpyhop_length(row: dict[str, Any]) -> str:
    lengths = sorted({g["plan_length"] for g in row["gtpyhop"].values() if g["status"] == "success"})
    return "/".join(str(n) for n in lengths) or "-"


def _table_lines(report: dict[str, Any]) -> list[str]:
    strategies = report["strategies"]
    header = ["problem", "size", "ours len", "ours ms", "GTPyhop len"]
    for s in strategies:
        header += [f"{SHORT_STRATEGY[s]} ms", f"{SHORT_STRATEGY[s]} ratio"]
    rows = [header]
    for r in report["problems"]:
        ours = r["ours"]
        cells = [r["name"], r["size"], str(ours["plan_length"] or "-"), _cell_ms(ours), _gtpyhop_length(r)]
        for s in strategies:
            ratio = r["ratio"].get(s)
            cells += [_cell_ms(r["gtpyhop"][s]), "-" if ratio is None else f"{ratio:.1f}x"]
        rows.append(cells)
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    lines = []
    for index, row in enumerate(rows):
        lines.append(
            "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths, strict=True)))
        )
        if index == 0:
            lines.append("  ".join("-" * w for w in widths))
    return lines


def _print_report(report: dict[str, Any]) -> None:
    names = ", ".join(f"{SHORT_STRATEGY[s]} = {s}" for s in report["strategies"])
    print(
        f"HTN planning: bt-meta vs {report['baseline']} in one process (Python {report['python']}, "
        f"recursion limit {report['recursion_limit']}), blocks seed {report['seed']}"
    )
    print(f"each time is the best of at least {report['repeat']} run(s), more on fast problems: a planner runs a "
          f"problem until its runs add up to {report['min_seconds']} s (at most {MAX_ROUNDS} runs)")
    print(f"ratio = GTPyhop time / our time (ours includes building the decomposition tree); {names}")
    print()
    for line in _table_lines(report):
        print(line)
    print()
    summary = report["summary"]
    for r in report["problems"]:
        for who, outcome in [("ours", r["ours"]), *((f"GTPyhop {s}", g) for s, g in r["gtpyhop"].items())]:
            if outcome["status"] != "success":
                print(f"  {r['name']}: {who}: {outcome['status']}: {outcome['message'][:160]}")
    if summary["min_ratio"]:
        m = summary["min_ratio"]
        print(f"slowest ratio: {m['ratio']:.1f}x on {m['problem']} against GTPyhop {m['strategy']}")
    verdict = "met" if summary["target_met"] else "NOT met"
    print(
        f"goal (ours >= {report['target_ratio']:.0f}x faster than every GTPyhop run that found a plan, "
        f"no failure of ours): {verdict}"
    )


def _handle(args: argparse.Namespace) -> int:
    if args.repeat < 1:
        raise UserInputError(f"--repeat must be at least 1, got {args.repeat}", _COMMAND)
    if not args.min_seconds >= 0:
        raise UserInputError(f"--min-seconds must be 0 or more, got {args.min_seconds}", _COMMAND)
    strategies = args.strategy or list(STRATEGIES)

    def progress(row: dict[str, Any]) -> None:
        if not args.json:
            print(f"  {row['name']}: done", file=sys.stderr, flush=True)

    try:
        report = run_benchmark(
            repeat=args.repeat,
            min_seconds=args.min_seconds,
            only=args.only,
            seed=args.seed,
            strategies=strategies,
            max_seconds=args.max_seconds,
            progress=progress,
        )
    except GtpyhopMissing as error:
        print(f"bt-meta bench htn: {error}", file=sys.stderr)
        return 2
    if args.json:
        print_json(report)
    else:
        _print_report(report)
    return 1 if report["summary"]["ours_failed"] else 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "htn",
        help="our HTN planner vs GTPyhop on blocks-world and Childsnack problems",
        description="Our HTN planner against GTPyhop on the same problems (GTPyhop's examples), in one process.",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    parser.add_argument("--repeat", type=int, default=3, help="least runs per planner and problem; the best counts")
    parser.add_argument("--min-seconds", type=float, default=MIN_SECONDS, metavar="S",
                        help=f"run each planner on a problem until its runs add up to S seconds (default "
                             f"{MIN_SECONDS}; at most {MAX_ROUNDS} runs)")
    parser.add_argument("--only", metavar="NAME", help="comma-separated problem names or patterns, e.g. sussman")
    parser.add_argument("--seed", type=int, default=1, help="seed of the generated 100- and 200-block problems")
    parser.add_argument(
        "--strategy",
        action="append",
        choices=STRATEGIES,
        help="GTPyhop search strategy to measure (repeatable; default: all three)",
    )
    parser.add_argument(
        "--max-seconds", type=float, default=300.0, help="time budget of our planner per problem and run"
    )
    parser.set_defaults(func=_handle)
