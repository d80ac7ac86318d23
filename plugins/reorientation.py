"""Re-orientation repair: a part in an orientation no demonstrated pose can fix is turned over by regrasping.

Pose backtracking (section 7.4) samples known-good poses from the traces; a part lying on its side or upside
down may have none that is reachable or collision-free as it is held -- the limits section 7.5.2 names. This
plugin is the symbolic repair a low-level expectation triggers (the dual encoding's point): when the part's
attachment normal, as perceived now, is grossly off (more than :data:`GROSS_ANGLE`) from where the demonstrations
had it at the start, it looks in the method library for a **re-orientation task** -- a task whose name starts with
``Reorient`` and whose first parameter is the part -- and proposes to run it as many times as needed, then the
problem's own task network again, from where the run stands (else, mid-plan where the network cannot be planned
again, the rest of the failed plan). The part is the root task's first argument, else the failed step's argument
whose normal is off (the letters' ``draw_A()`` names no block). A held part that started grossly off but shows the
demonstrated normal (a letters block picked on its side and carried upright by a tilted wrist) is judged by the
normal it would have under a top-down grasp. The task files that need it ship the methods (a
regrasp: set the part down on another face, pick it again; ``trees/magnetic_attach.yaml``,
``trees/housing_insertion.yaml``, ``trees/letters.yaml``). A ``precondition`` failure is answered only when an atom
its condition misses is a property of the part alone (``upright(housing)``, which sensing dropped): a symbolic
failure answered by a re-orientation, decided from the missing atoms and the low-level mismatch; those atoms are
taken out of the state the repair plans from.

How many times: each run of the task (planned one after the other: the method may differ, a held part is set
down first) turns the part by the rotation between its last set-down pose and the top-down grasp (read from the
world's pose grounding when it offers ``ground_pose``, against the robot's top-down grasp, ``top_down_rotation``;
else a quarter turn about the robot's x axis); the fewest
runs that bring the normal within :data:`ALIGNED_ANGLE` of the demonstrated one.

The proposal is a ``splice`` of the planned steps from the failed step on. Its evidence carries ``replay_plan``: the
same re-orientation planned from the problem's initial state (the part's normal when the run started,
``run.start_objects``; without the orientation facts sensing contradicted, which were no truer then), which the
executor stores as the refinement (the failed attempt, its release and re-pick are not replayed on the next
exposure). Mid-plan, where the turns go in before the rest of the failed plan and nothing that ran is redone, the
evidence also says ``as_run_replays``: after another plugin's repair (a tiling), which the replay plan knows nothing
of, the plan as run is kept instead (letters_H s1 0015). A held part whose method lets it go without a turn (a part
jammed in an insertion) is only set down first (``keep_goal``: the goal is not rewritten): the turns are counted at
the next failure, from how it landed. A settle, or a number of turns, the run's repair history already tried is not
proposed again (the part lands the same way: proposing it from each new step spent the attempt budget).

Offers:

* :class:`Reorientation` -- the plugin as an object (memory, traces used, score)
* :func:`reorientation_tasks` -- the domain's re-orientation tasks
* :func:`quarter_turns` -- how many runs of a turn bring a normal to the wanted one
* :func:`part_properties_missing` -- a precondition failure's missing atoms that are properties of the part alone
* :func:`turned_facts_held` -- the bookkept facts about the part a re-orientation method needs false
* :func:`bt_meta_propose_repairs` -- the module-level hook (the ``reorientation`` entry point)
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bt_meta.bt.failures import FailureKind, RepairProposal
from bt_meta.errors import BtMetaError
from bt_meta.meta.proposals import SPLICE
from bt_meta.perception.keypoints import KeypointError, keypoints_of
from bt_meta.perception.recall import memory_for, root_task
from bt_meta.plugins import ConfiguredPlugin, hookimpl
from bt_meta.world.simulation.objects import rpy_to_matrix

__all__ = ["Reorientation", "bt_meta_propose_repairs", "configure", "part_properties_missing", "quarter_turns",
           "reorientation_tasks", "turned_facts_held"]

log = logging.getLogger("bt_meta.meta.reorientation")

STRATEGY = "reorientation"
PREFIX = "Reorient"
KINDS = (FailureKind.VERIFICATION, FailureKind.UNEXPECTED_CONFIGURATION, FailureKind.COLLISION,
         FailureKind.REACHABILITY, FailureKind.PRECONDITION)
GROSS_ANGLE = math.radians(45.0)
"""A normal further than this from the demonstrated one is an orientation no pose sampled near it can fix."""
ALIGNED_ANGLE = math.radians(30.0)
UPSIDE_DOWN = math.radians(135.0)
"""Further off than this a part is upside down (the turn's axis is then the flip axis, not the shortest way)."""
MAX_TURNS = 3
TOP_DOWN = rpy_to_matrix(math.pi, 0.0, math.pi)
"""The grasp orientation turns are measured from when the world does not say its own (``top_down_rotation``:
the robot's top-down yaw; rpy 180, 0, 180 is the Baxter's)."""


def top_down(world: Any) -> np.ndarray:
    """The world's top-down grasp rotation (the robot's), else :data:`TOP_DOWN`."""
    offered = getattr(world, "top_down_rotation", None)
    if callable(offered):
        try:
            return np.asarray(offered(), float)
        except Exception as error:  # a world that cannot say: the documented default
            log.info("reorientation: no top-down rotation from the world (%s)", error)
    return TOP_DOWN


def reorientation_tasks(domain: Any, part_type: str | None = None) -> list[str]:
    """Tasks of ``domain`` named ``Reorient...`` whose first parameter is a part (of ``part_type`` when given)."""
    out = []
    for name, task in domain.tasks.items():
        if not name.startswith(PREFIX) or not task.parameters:
            continue
        types = getattr(task, "types", None) or ()
        if part_type is not None and types and types[0] not in (None, part_type):
            continue
        out.append(name)
    return sorted(out)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, float(a @ b) / (float(np.linalg.norm(a) * np.linalg.norm(b)) or 1.0))))


def quarter_turns(normal: Sequence[float], wanted: Sequence[float], turn: np.ndarray,
                  limit: int = MAX_TURNS) -> int | None:
    """The fewest applications (1..``limit``) of rotation ``turn`` that bring ``normal`` within
    :data:`ALIGNED_ANGLE` of ``wanted``; ``None`` when none does."""
    current = np.asarray(normal, float)
    target = np.asarray(wanted, float)
    for k in range(1, limit + 1):
        current = turn @ current
        if _angle(current, target) <= ALIGNED_ANGLE:
            return k
    return None


def _about_x() -> np.ndarray:
    return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


class Reorientation:
    """The repair plugin (see the module docstring)."""

    def __init__(self, memory: Any = None, *, n: int = 5, score: float = 0.6) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        self.memory = memory
        self.n = n
        self.score = score

    # -- what the demonstrations and the world say ----------------------------------------------------------------

    def demonstrated_normal(self, memory: Any, task: str, part: str) -> np.ndarray | None:
        """The part's attachment normal (base frame) at the start of the last successful traces, averaged."""
        normals = []
        for trace in memory.last_traces(task, self.n):
            for state in (trace.initial, *(s.state for s in trace.steps[:1])):
                try:
                    normals.append(keypoints_of(state.object(part))[1])
                    break
                except (KeyError, KeypointError):
                    continue
        if not normals:
            return None
        mean = np.mean(normals, axis=0)
        norm = float(np.linalg.norm(mean))
        return None if norm < 1e-9 else mean / norm

    @staticmethod
    def turn_of(world: Any, domain: Any, plan: Sequence[Sequence[str]], normal: Sequence[float] | None = None,
                wanted: Sequence[float] | None = None) -> np.ndarray:
        """The rotation one re-orientation gives the held part: its set-down pose against the top-down grasp; a
        method without a ``MoveTo`` (one skill turns the part, the letters' ``turn_over``) or whose set-down pose
        is a ``turn_up`` pose (grounded from how the part lies *now*: no model of a turn from another normal, e.g.
        the one the run started with) turns it a quarter toward ``wanted`` from ``normal``, when both are given."""
        ground = getattr(world, "ground_pose", None)
        moves = [step[1] for step in plan if step[0] == "MoveTo" and len(step) > 1]
        if normal is not None and wanted is not None and (not moves or _turns_up(world, str(moves[-1]))):
            return _quarter_toward(np.asarray(normal, float), np.asarray(wanted, float))
        if ground is not None and moves:
            try:
                rotation = np.asarray(ground(str(moves[-1])), float)[:3, :3]
                return rotation @ top_down(world).T
            except Exception as error:  # a world that cannot ground it now: the documented default
                log.info("reorientation: set-down pose %s not grounded (%s); a quarter turn about x", moves[-1], error)
        return _about_x()

    # -- the hook ---------------------------------------------------------------------------------------------------

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        if failure.kind not in KINDS:
            return None
        run = getattr(context, "run", None)
        domain = getattr(run, "domain", None)
        problem = getattr(run, "problem", None)
        world = getattr(context, "world", None)
        task = root_task(context)
        if domain is None or problem is None or world is None or task is None:
            return None
        names = reorientation_tasks(domain)
        if not names:
            return None
        memory = memory_for(context, self.memory)
        if memory is None:
            return None
        history = failure.evidence.get("repair_history") or []
        ours = [a for a in history if ((a.get("proposal") or {}).get("evidence") or {}).get("strategy") == STRATEGY]
        earlier = {str(a["proposal"]["evidence"].get("part")) for a in ours}
        found = None
        for part in _candidate_parts(problem, failure):
            seen = self._orientation(world, memory, task, part)
            if seen is not None and _angle(seen[2], seen[1]) <= GROSS_ANGLE:
                tilted = _held_tilted(world, run, seen[0], seen[1])
                seen = seen if tilted is None else (seen[0], seen[1], tilted)
            if seen is not None and (_angle(seen[2], seen[1]) > GROSS_ANGLE or part in earlier):
                found = (part, *seen)
                break
        if found is None:
            return None  # every part the task or the failed step names is as demonstrated: not a re-orientation's
        part, seen_name, wanted, normal = found
        off = _angle(normal, wanted)
        missing = part_properties_missing(failure, part)
        if failure.kind is FailureKind.PRECONDITION and not missing:
            log.info("reorientation: the precondition failure misses no property of %s alone", part)
            return None  # a symbolic failure about something else (a pose, a feature): not an orientation's
        # What sensing contradicted at this failed precondition (or at the one an earlier re-orientation of this
        # run answered, while the part is still off): the world's bookkeeping may still hold it.
        missing = missing or sorted({str(m) for a in ours for m in a["proposal"]["evidence"].get("missing") or ()})
        state = world.symbolic_state()
        back: list[list[str]] = []
        if not missing and _held_turned(failure, seen_name, wanted):
            # The failed step measured the held part grossly off (the insertion's end normal): it is held turned,
            # not jammed. The orientation facts the re-orientation methods need false are contradicted; the
            # gripper first backs out to where the failed step started (it stopped pressing the part on the
            # target: dragged sideways from there, the grasp slips).
            missing = turned_facts_held(domain, names, part, state)
            back = _back_out(domain, state)
        if missing:
            state = state.apply(add=(), delete=[_atom(text) for text in missing])
        held = (world.observe() or {}).get("held") or {}
        evidence: dict[str, Any] = {"strategy": STRATEGY, "part": part, "object": seen_name,
                                    "normal": [round(float(v), 4) for v in normal],
                                    "demonstrated_normal": [round(float(v), 4) for v in wanted],
                                    "off_degrees": round(math.degrees(off), 1)}
        if missing:
            evidence["missing"] = missing
        if held and seen_name not in held.values() and any(h is not None for h in held.values()):
            log.info("reorientation: the gripper holds %s, not %s", held, part)
            return None
        localisation = failure.evidence.get("localisation") or {}
        start = int(localisation.get("step", failure.step if failure.step is not None else 0))
        end = max(len(failure.evidence.get("plan") or []), start + 1)
        initial = self._initial_normal(run, seen_name)
        tried = {_tried_key(a["proposal"]["evidence"]) for a in ours}
        for name in names:
            settle = self._settle(world, domain, problem, state, name, part, run)
            if settle is not None and off > GROSS_ANGLE and (name, 0, True) not in tried:
                # A held part is let go without a turn first (it may land any way: a jammed part springs free);
                # the turns are counted once it lies where it can be seen, at the next failure.
                evidence.update(method_task=name, turns=0, settle=True, keep_goal=True)
                return [RepairProposal(
                    SPLICE, self.score, f"let {part} go and set it down ({name}) to see how it lies: its normal is "
                    f"{math.degrees(off):.0f} deg from the demonstrations'",
                    changes={"start": start, "end": end, "actions": settle}, evidence=evidence)]
            turns = self._turns(world, domain, problem, state, name, part, normal, wanted, run)
            if turns is None:
                log.info("reorientation: no number of %s brings the normal of %s to the demonstrated one", name, part)
                continue
            now = self._plan(domain, problem, state, [(name, part)] * turns + [tuple(t) for t in problem.tasks], run)
            as_run = now is None
            if now is None:  # the task network cannot be planned again from here (its blocks are placed): the turns,
                now = self._before_rest(domain, problem, state, name, part, turns, failure, start, run)
            if now is None:  # then the rest of the plan as it was
                log.info("reorientation: %d x %s of %s leaves no plan for %s", turns, name, part, task)
                continue
            replay = None
            first = None if initial is None else self._turns(world, domain, problem, problem.state, name, part,
                                                             initial, wanted, run)
            if first is not None:  # the same repair from the start, for the refinement; the orientation facts
                # sensing contradicted are no truer of the start, where the part already lay off (else the replay
                # plans the turn that makes no claim, and the insertion's precondition fails on the next exposure)
                start_state = problem.state.apply(add=(), delete=[_atom(text) for text in missing]) if missing \
                    else problem.state
                replay = self._plan(domain, problem, start_state,
                                    [(name, part)] * first + [tuple(t) for t in problem.tasks], run)
            if (name, turns, False) in tried:
                log.info("reorientation: %d x %s of %s was tried and failed: not again", turns, name, part)
                continue
            evidence.update(method_task=name, turns=turns, replay_plan=replay)
            if as_run:  # turns put in before the failed step, nothing run redone: the plan as run replays as well
                evidence["as_run_replays"] = True
            if back and now[:1] != back:
                now = back + now
            return [RepairProposal(
                SPLICE, self.score, f"re-orient {part} by {turns} x {name} (its normal is "
                f"{math.degrees(off):.0f} deg from the demonstrations'), then {task} again",
                changes={"start": start, "end": end, "actions": now}, evidence=evidence)]
        return None

    def _before_rest(self, domain: Any, problem: Any, state: Any, name: str, part: str, turns: int, failure: Any,
                     start: int, run: Any) -> list[list[str]] | None:
        """``turns`` runs of ``name`` then the failed plan's steps from ``start`` on, when they still apply."""
        turned = self._plan(domain, problem, state, [(name, part)] * turns, run)
        rest = [[str(s["action"]), *map(str, s.get("args") or ())] for s in failure.evidence.get("plan") or ()
                if int(s.get("step", -1)) >= start]
        if turned is None or not rest:
            return None
        current = state
        for step in turned + rest:
            primitive = domain.primitives.get(step[0])
            if primitive is None:
                return None
            try:
                current = primitive.ground(step[1:]).apply(current)
            except Exception as error:  # the rest does not apply after the turns
                log.info("reorientation: %s does not apply after the turns: %s", step, error)
                return None
        return turned + rest

    def _orientation(self, world: Any, memory: Any, task: str, part: str
                     ) -> tuple[str, np.ndarray, np.ndarray] | None:
        """(world name, demonstrated normal, observed normal) of ``part``, or ``None`` when one is not known."""
        to_world = getattr(world, "object_name", None)
        try:
            seen_name = str(to_world(part)) if to_world is not None else part
        except Exception:
            seen_name = part
        observed = (world.observe() or {}).get("objects", {}).get(seen_name)
        if observed is None:
            return None
        wanted = self.demonstrated_normal(memory, task, seen_name)
        if wanted is None:
            return None
        try:
            return seen_name, wanted, keypoints_of(observed)[1]
        except KeypointError:
            return None

    @staticmethod
    def _initial_normal(run: Any, name: str) -> np.ndarray | None:
        """The part's normal when the run started (the executor keeps the first observation on the run)."""
        objects = getattr(run, "start_objects", None) or {}
        try:
            return keypoints_of(objects[name])[1] if name in objects else None
        except KeypointError:
            return None

    def _settle(self, world: Any, domain: Any, problem: Any, state: Any, name: str, part: str, run: Any
                ) -> list[list[str]] | None:
        """The steps of ``name`` planned now when they let the held part go without turning it, else ``None``."""
        tree = self._plan_tree(domain, problem, state, [(name, part)], run)
        if tree is None:
            return None
        steps = [[n.task[0], *map(str, n.task[1:])] for n in tree.primitives()]
        moves = [step[1] for step in steps if step[0] == "MoveTo" and len(step) > 1]
        if moves and _turns_up(world, str(moves[-1])):
            return None  # a turn toward the part's base, whatever it grounds to now
        turn = self.turn_of(world, domain, steps)
        if _angle(turn @ np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])) > ALIGNED_ANGLE / 3:
            return None
        if _angle(turn @ np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])) > ALIGNED_ANGLE / 3:
            return None
        return steps

    def _turns(self, world: Any, domain: Any, problem: Any, state: Any, name: str, part: str, normal: np.ndarray,
               wanted: np.ndarray, run: Any) -> int | None:
        """The fewest runs of task ``name`` (planned one after the other from ``state``: the method may differ per
        run, e.g. a held part is set down first) whose turns bring ``normal`` within :data:`ALIGNED_ANGLE` of
        ``wanted``; ``None`` when none up to :data:`MAX_TURNS` + 1 does."""
        if _angle(np.asarray(normal, float), wanted) <= ALIGNED_ANGLE:
            return 0
        for k in range(1, MAX_TURNS + 2):
            tree = self._plan_tree(domain, problem, state, [(name, part)] * k, run)
            if tree is None:
                return None
            current = np.asarray(normal, float)
            for root in tree.roots:
                steps = [[n.task[0], *map(str, n.task[1:])] for n in tree.primitives(root)]
                current = self.turn_of(world, domain, steps, normal, wanted) @ current
            if _angle(current, wanted) <= ALIGNED_ANGLE:
                return k
        return None

    @staticmethod
    def _plan(domain: Any, problem: Any, state: Any, tasks: list[tuple[str, ...]], run: Any,
              goal: list[Any] | None = None) -> list[list[str]] | None:
        tree = Reorientation._plan_tree(domain, problem, state, tasks, run, goal)
        return None if tree is None else [[n.task[0], *map(str, n.task[1:])] for n in tree.primitives()]

    @staticmethod
    def _plan_tree(domain: Any, problem: Any, state: Any, tasks: list[tuple[str, ...]], run: Any,
                   goal: list[Any] | None = None) -> Any:
        from bt_meta.htn import plan

        external = getattr(run, "external", None)
        if goal is None:  # the problem's goal only when its own tasks are planned too
            only_turns = all(str(t[0]).startswith(PREFIX) for t in tasks)
            goal = [] if only_turns else list(getattr(problem, "goal", None) or [])
        fresh = dataclasses.replace(problem, state=state, init=sorted(state), tasks=list(tasks), goal=goal)
        try:
            result = plan(domain, fresh, external=external, max_seconds=5.0)
        except BtMetaError as error:
            log.info("reorientation: planning %s failed: %s", tasks, error)
            return None
        if result.status != "success" or result.tree is None:
            return None
        return result.tree


def part_properties_missing(failure: Any, part: str) -> list[str]:
    """The atoms of a precondition failure's condition that are properties of ``part`` alone (every argument is
    the part, e.g. ``upright(housing)``) and are not in the failure's state: with a normal grossly off, the
    missing fact is the part's orientation, which a re-orientation restores. Empty for other failures."""
    from bt_meta.htn.conditions import AndExpr, AtomExpr, Var, parse_condition

    evidence = failure.evidence or {}
    text = evidence.get("condition")
    if failure.kind is not FailureKind.PRECONDITION or not isinstance(text, str):
        return []
    try:
        condition = parse_condition(text)
    except Exception:  # a condition this module cannot read: no claim about it
        return []
    bindings = {str(k).lstrip("?"): str(v) for k, v in (evidence.get("bindings") or {}).items()}
    state = {str(atom).replace(" ", "") for atom in evidence.get("state") or ()}
    out = []
    for child in (condition.children if isinstance(condition, AndExpr) else (condition,)):
        if not isinstance(child, AtomExpr) or not child.args:
            continue
        args = [bindings.get(a.name) if isinstance(a, Var) else a for a in child.args]
        if any(a != part for a in args):
            continue
        atom = f"{child.pred}({', '.join(args)})"
        if atom.replace(" ", "") not in state:
            out.append(atom)
    return out


def turned_facts_held(domain: Any, names: Sequence[str], part: str, state: Any) -> list[str]:
    """The atoms of ``state`` that a re-orientation method of ``names`` needs false of ``part`` alone (``not
    upright(?part)``): what a part measured turned contradicts in the bookkept state."""
    from bt_meta.htn.conditions import AndExpr, AtomExpr, NotExpr, term_text

    held = {tuple(map(str, atom)) for atom in state}
    out: set[str] = set()
    for method in domain.methods:
        if method.task_name not in names or not method.task_args:
            continue
        first = term_text(method.task_args[0])
        expr = method.precondition.expr
        for child in (expr.children if isinstance(expr, AndExpr) else (expr,)):
            atom = child.child if isinstance(child, NotExpr) else None
            if not isinstance(atom, AtomExpr) or not atom.args or any(term_text(a) != first for a in atom.args):
                continue
            if (atom.pred, *[part] * len(atom.args)) in held:
                out.add(f"{atom.pred}({', '.join([part] * len(atom.args))})")
    return sorted(out)


def _back_out(domain: Any, state: Any) -> list[list[str]]:
    """``MoveTo`` the pose the state says the gripper is at (a no-op symbolically: the failed step did not get
    to change it), when the domain has that one-pose primitive; else nothing."""
    primitive = domain.primitives.get("MoveTo")
    if primitive is None or len(primitive.parameters) != 1:
        return []
    poses = sorted(str(atom[1]) for atom in state if len(atom) == 2 and atom[0] == "at")
    return [["MoveTo", poses[0]]] if len(poses) == 1 else []


def _held_turned(failure: Any, name: str, wanted: np.ndarray) -> bool:
    """Whether the failed step measured the part it handled (``end_normal`` of an insertion: its insertable end)
    more than :data:`GROSS_ANGLE` (and at most :data:`UPSIDE_DOWN`) from the demonstrated normal: held turned on
    its side, not jammed (a jammed part faces the hole and fails as ``physical``)."""
    evidence = failure.evidence or {}
    measured = evidence.get("end_normal")
    if measured is None or str(evidence.get("part", name)) not in (name, *map(str, failure.args or ())):
        return False
    try:
        off = _angle(np.asarray(measured, float), np.asarray(wanted, float))
    except (TypeError, ValueError):
        return False
    # Upside down (past UPSIDE_DOWN) it is let go first and the turns counted from how it lands: measured, two
    # flips in a hand the insertion had pressed it into landed it 31 deg off (a third turn, no refinement kept).
    return GROSS_ANGLE < off <= UPSIDE_DOWN


def _held_tilted(world: Any, run: Any, name: str, wanted: np.ndarray) -> np.ndarray | None:
    """The normal a part that started grossly off and is held now would have under a top-down grasp (the
    skills' grasp, :func:`top_down`), when that is grossly off too; else ``None``. A block picked on its side is
    carried upright with the wrist tilted (the letters' place keeps its tilt in the gripper): its normal as the
    table sees it is the demonstrated one, but no wrist reaches down at the cell so held."""
    start = Reorientation._initial_normal(run, name)
    if start is None or _angle(start, wanted) <= GROSS_ANGLE:
        return None
    seen = world.observe() or {}
    arm = next((a for a, held in (seen.get("held") or {}).items() if held == name), None)
    pose = (seen.get("gripper") or {}).get(arm) if arm is not None else None
    observed = (seen.get("objects") or {}).get(name)
    if pose is None or len(pose) != 6 or observed is None:
        return None
    try:
        normal = top_down(world) @ rpy_to_matrix(*pose[3:]).T @ keypoints_of(observed)[1]
    except KeypointError:
        return None
    return normal if _angle(normal, wanted) > GROSS_ANGLE else None


def _turns_up(world: Any, symbol: str) -> bool:
    """Whether pose ``symbol`` is grounded as a turn toward the part's base (``turn_up`` in the grounding)."""
    spec = getattr(world, "pose_spec", None)
    try:
        return spec is not None and isinstance(spec(symbol), dict) and "turn_up" in spec(symbol)
    except Exception:  # a world without that pose: not a turn_up pose
        return False


def _quarter_toward(normal: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The rotation by at most a quarter turn that brings ``normal`` toward ``wanted`` (opposite: about x)."""
    a, b = normal / np.linalg.norm(normal), wanted / np.linalg.norm(wanted)
    axis = np.cross(a, b)
    if float(np.linalg.norm(axis)) < 1e-6 or _angle(a, b) > math.radians(135.0):
        axis = np.array([1.0, 0.0, 0.0]) - float(b[0]) * b
    axis = axis / float(np.linalg.norm(axis))
    angle = min(_angle(a, b), math.pi / 2.0)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _candidate_parts(problem: Any, failure: Any) -> list[str]:
    """The parts a re-orientation may be for: the root task's first argument (``InsertPart(housing, ...)``),
    then the failed step's arguments (``place(b3, 0, 1)``: the letters' root task names none)."""
    out: list[str] = []
    root = problem.tasks[0] if problem.tasks else ()
    for arg in (*root[1:2], *(getattr(failure, "args", None) or ())):
        if str(arg) not in out:
            out.append(str(arg))
    return out


def _atom(text: str) -> tuple[str, ...]:
    """``"upright(housing)"`` -> ``("upright", "housing")``."""
    pred, _, rest = text.partition("(")
    return (pred, *(a.strip() for a in rest.rstrip(")").split(",") if a.strip()))


def _tried_key(evidence: dict[str, Any]) -> tuple[str, int, bool]:
    """What a re-orientation proposal would do, as the run's repair history has it: (task, turns, settle only). The
    same settle or the same number of turns is not proposed twice in a run (it would start from another step each
    time, so the executor's effect identity does not see the repeat)."""
    return (str(evidence.get("method_task")), int(evidence.get("turns") or 0), bool(evidence.get("settle")))


plugin = ConfiguredPlugin(Reorientation)
configure = plugin.configure


@hookimpl
def bt_meta_propose_repairs(failure: Any, context: Any) -> list[RepairProposal] | None:
    return plugin.current.bt_meta_propose_repairs(failure, context)
