"""Recording demonstrations: a trace-event plugin that turns one run into a :class:`~bt_meta.memory.Trace`.

The recorder listens to ``bt_meta_trace_event`` (``run_start``, ``step_start``, ``step_end``, ``run_end``) and, at
every ``step_end``, reads what the run left behind from the installed run and its world: the belief state
(symbolic facts), the object states (pose, attachment point AP in the base frame, attachment normal AN in the
object frame) and -- when the world is a simulator with a top camera -- the grid-map of each object the step names
or moved (:func:`moved_objects`), of any type (camera perception's ``object_gridmaps`` for blocks, the same view
cropped for a cylinder, a mesh, a housing: the object's 3 lb window centred where it truly lies, the instructor's
annotation of section 6.3). Parent task and parent node come from the decomposition tree (given, or planned again
from the run's domain and problem). At ``run_end`` the trace -- episode, initial state, steps and E_db rows -- is
written in ONE :meth:`~bt_meta.memory.EpisodicMemory.write` (one transaction): successful runs always, failed runs
only with ``record_failed=True`` (their outcome recorded, so no query takes them for a success).

What is stored matches what the expectation plugins look up (:mod:`bt_meta.perception.recall`): the episode's
task is the problem's root task, step ``i`` is plan step ``i`` of a nominal run, arguments are strings, grid-maps
carry the object name; keypoint expectations read the object states. A step executed again after a repair
backtracked replaces the steps it undid, and a successful run keeps only the steps of its final execution (a
failed step's state is no expectation); the repairs and failures are in the episode's ``config``. E_db: one row
per successful step, keyed by its action and exact arguments, pointing to its parent task, with the facts the
step added and a reference to each of its grid-maps (the store bubbles a task's expectation up from its last
primitive: :meth:`~bt_meta.memory.EpisodicMemory.expectation_of`). A driver that puts the step's observations in
the ``step_end`` event (``event["observations"]["object_gridmaps"]``) saves the recorder its own camera frame.

Offers:

* :class:`TraceRecorder` -- the plugin (register it with a :class:`~bt_meta.plugins.PluginHost`); after the run:
  :attr:`~TraceRecorder.trace`, :attr:`~TraceRecorder.episode_id`, :attr:`~TraceRecorder.skipped`,
  :attr:`~TraceRecorder.error`, :attr:`~TraceRecorder.seconds`
* :class:`RecorderError` -- a run that cannot become a trace (no installed run, no root task, no task file)
* :func:`object_states_of` -- a world's object states as memory :class:`~bt_meta.memory.ObjectState`
* :func:`root_task_name` -- the episode key of a problem (its root task)
* :func:`moved_objects` -- the objects a step shifted or turned (what is watched besides what it names)
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bt_meta.errors import BtMetaError
from bt_meta.memory.trace import Episode, Expectation, GridMap, ObjectState, State, Step, Trace
from bt_meta.plugins import hookimpl

__all__ = ["RecorderError", "TraceRecorder", "object_states_of", "root_task_name"]

log = logging.getLogger("bt_meta.memory")

_SUCCESS_STATUSES = {"SUCCESS", "success"}
_RUNNING_STATUSES = {"RUNNING", "running", "INVALID"}


class RecorderError(BtMetaError):
    """A run that cannot be recorded as a trace."""


def root_task_name(problem: Any) -> str:
    """The episode key of ``problem``: its root task's name (``draw_A``); several roots are joined by ``+``."""
    tasks = getattr(problem, "tasks", None) or ()
    names = [str(task[0]) for task in tasks if task]
    if not names:
        raise RecorderError(f"problem {getattr(problem, 'name', problem)!r} has no root task to key its trace by")
    return "+".join(names)


def object_states_of(world: Any) -> tuple[ObjectState, ...]:
    """The objects of ``world`` with pose, AP (base frame) and AN (object frame), as the memory stores them.

    A simulator world gives them through ``world.sim.object_states()``; any other world through
    ``world.observe()["objects"]`` (normals in the base frame, turned into the object frame). A world with neither
    has no object states."""
    sim = getattr(world, "sim", None)
    states = getattr(sim, "object_states", None)
    if states is not None:
        return tuple(ObjectState(s.name, tuple(s.pose), tuple(s.ap), tuple(s.an_object))  # type: ignore[arg-type]
                     for s in states().values())
    observe = getattr(world, "observe", None)
    if observe is None:
        return ()
    objects = (observe() or {}).get("objects") or {}
    out = []
    for name, value in objects.items():
        if not isinstance(value, Mapping) or value.get("pose") is None or len(value["pose"]) != 6:
            continue
        out.append(ObjectState.from_base_normal(str(name), value["pose"], value.get("ap") or (0.0, 0.0, 0.0),
                                                value.get("an") or (0.0, 0.0, 1.0)))
    return tuple(out)


def _facts(state: Any) -> tuple[tuple[str, ...], ...]:
    return tuple(tuple(str(part) for part in atom) for atom in sorted(state)) if state is not None else ()


def _fact_from_text(text: str) -> tuple[str, ...]:
    """``at(b0, 0, 1)`` -> ``("at", "b0", "0", "1")`` (the ``state`` of a ``step_end`` event)."""
    head, _, rest = text.partition("(")
    args = [part.strip() for part in rest.rstrip(")").split(",")] if rest else []
    return (head.strip(), *[a for a in args if a])


@dataclass
class _Pending:
    """One finished step, before the trace is built."""

    step: int | None
    action: str
    args: tuple[str, ...]
    node_id: str | None
    parent_task: str | None
    parent_node: str | None
    state: State
    outcome: str
    failure_kind: str | None
    duration: float | None
    added: tuple[tuple[str, ...], ...] = ()


@dataclass
class _RunRecord:
    run: Any
    started: float
    task_file: str | None
    problem: str | None
    initial: State
    facts: tuple[tuple[str, ...], ...]
    steps: list[_Pending] = field(default_factory=list)
    starts: dict[tuple[Any, Any], float] = field(default_factory=dict)
    failures: list[dict[str, Any]] = field(default_factory=list)
    repairs: list[dict[str, Any]] = field(default_factory=list)


class TraceRecorder:
    """Records the runs it hears about; writes each finished one to ``memory`` (when given) in one transaction.

    ``record_failed``: also store runs that did not succeed (outcome ``failure``/``aborted``; default: only
    successes). ``tree``: the run's decomposition tree (default: the run's problem planned again when a step needs
    its parent; the repair executor's caller sets it per segment). ``camera``: a camera-perception plugin object
    with ``look(world)`` and ``object_grid_maps(world, view)`` (default: the shipped module's current settings);
    ``grid_maps=False`` records no grid-maps. ``variant``, ``seed``, ``task_file`` and ``config`` override what the
    run says (``variant`` and ``seed`` default to the world's attributes).
    """

    def __init__(
        self,
        memory: Any = None,
        *,
        record_failed: bool = False,
        tree: Any = None,
        camera: Any = None,
        grid_maps: bool = True,
        variant: str | None = None,
        seed: int | None = None,
        task_file: str | None = None,
        config: Mapping[str, Any] | None = None,
    ) -> None:
        self.memory = memory
        self.record_failed = record_failed
        self.tree = tree
        self.camera = camera
        self.grid_maps = grid_maps
        self.variant = variant
        self.seed = seed
        self.task_file = task_file
        self.config = dict(config or {})
        self.trace: Trace | None = None
        """The trace of the last finished run (also when it was not stored)."""
        self.episode_id: int | None = None
        """The episode id the last finished run was stored under (``None`` when not stored)."""
        self.skipped: str | None = None
        """Why the last finished run was not stored (``None`` when it was, or when there is no memory)."""
        self.error: BtMetaError | None = None
        """The error that kept the last finished run from being stored (an unwritable memory), if any."""
        self.seconds = 0.0
        """Time spent recording (observing and writing) during the last run."""
        self._current: _RunRecord | None = None
        self._planned_for: Any = None

    # -- the hook -------------------------------------------------------------------------------------------------

    @hookimpl
    def bt_meta_trace_event(self, event: dict[str, Any]) -> None:
        kind = event.get("type")
        if kind == "run_start":
            self._run_start(event)
        elif self._current is None:
            return
        elif kind == "step_start":
            self._current.starts[(event.get("step"), event.get("node_id"))] = time.perf_counter()
        elif kind == "step_end":
            self._step_end(event)
        elif kind == "failure":
            record = event.get("failure") or {}
            self._current.failures.append({key: record.get(key) for key in ("kind", "step", "action", "message")})
        elif kind == "repair":
            self._current.repairs.append({key: event[key] for key in ("outcome", "reason") if key in event}
                                         | _repair_summary(event))
        elif kind == "run_end":
            self._run_end(event)

    # -- events ---------------------------------------------------------------------------------------------------

    def _run_start(self, event: dict[str, Any]) -> None:
        from bt_meta.bt.context import current_run

        began = time.perf_counter()
        run = current_run()
        self.trace, self.episode_id, self.skipped, self.error = None, None, None, None
        self._planned_for = None
        world = getattr(run, "world", None)
        if run is not None:
            facts = _facts(run.state)
        else:
            facts = tuple(_fact_from_text(text) for text in event.get("state") or ())
        initial = State(facts=facts, objects=object_states_of(world) if world is not None else ())
        task_file = event.get("task_file")
        self._current = _RunRecord(run=run, started=time.time(),
                                   task_file=None if task_file is None else str(task_file),
                                   problem=event.get("problem"), initial=initial, facts=facts)
        self.seconds = time.perf_counter() - began

    def _step_end(self, event: dict[str, Any]) -> None:
        from bt_meta.bt.context import current_run

        began = time.perf_counter()
        record = self._current
        assert record is not None
        run = current_run() or record.run
        world = getattr(run, "world", None)
        action = str(event["action"])
        args = tuple(str(a) for a in event.get("args") or ())
        node_id, index = event.get("node_id"), event.get("step")
        status = str(event.get("status"))
        outcome = "success" if status in _SUCCESS_STATUSES else "failure"
        failure = event.get("failure") or None
        failure_kind = None if outcome == "success" else str((failure or {}).get("kind") or "internal")
        if run is not None:
            facts = _facts(run.state)
        else:
            facts = tuple(_fact_from_text(text) for text in event.get("state") or ())
        objects = object_states_of(world) if world is not None else ()
        parent_task, parent_node = self._parent(run, node_id, action, args)
        started = record.starts.pop((index, node_id), None)
        if index is not None:
            # A step run again (a repair backtracked to it) undoes the steps recorded from it on.
            while record.steps and record.steps[-1].step is not None and record.steps[-1].step >= index:
                record.steps.pop()
        earlier = record.steps[-1].state.objects if record.steps else record.initial.objects
        maps = self._grid_maps(world, args, event, moved_objects(earlier, objects)) if outcome == "success" else ()
        before = set(record.steps[-1].state.facts) if record.steps else set(record.facts)
        pending = _Pending(
            step=index, action=action, args=args, node_id=node_id, parent_task=parent_task, parent_node=parent_node,
            state=State(facts=facts, objects=objects, grid_maps=maps), outcome=outcome, failure_kind=failure_kind,
            duration=None if started is None else time.perf_counter() - started,
            added=tuple(f for f in facts if f not in before),
        )
        record.steps.append(pending)
        self.seconds += time.perf_counter() - began

    def _run_end(self, event: dict[str, Any]) -> None:
        began = time.perf_counter()
        record = self._current
        assert record is not None
        self._current = None
        status = str(event.get("status"))
        outcome = ("success" if status in _SUCCESS_STATUSES
                   else "aborted" if status in _RUNNING_STATUSES else "failure")
        try:
            self.trace = self.build(record, outcome, event)
        except BtMetaError as error:
            self.error = error
            raise
        if self.memory is None:
            self.skipped = "no memory to write to"
        elif outcome != "success" and not self.record_failed:
            self.skipped = f"the run ended with {status}; failed runs are stored only when asked (record_failed)"
        else:
            try:
                self.episode_id = self.memory.write(self.trace)
            except BtMetaError as error:
                self.error = error  # the run records it as an ``internal`` failure too
                raise
            log.info("recorded episode %d: %s, %d steps, %s", self.episode_id, self.trace.episode.task,
                     len(self.trace.steps), outcome)
        self.seconds += time.perf_counter() - began

    # -- pieces ---------------------------------------------------------------------------------------------------

    def build(self, record: _RunRecord, outcome: str, event: Mapping[str, Any] | None = None) -> Trace:
        """The trace of a finished run record (see the module docstring for what a successful run keeps)."""
        run = record.run
        problem = getattr(run, "problem", None)
        if problem is None:
            raise RecorderError("no run was installed when the run started: nothing names its problem")
        steps = record.steps
        if outcome == "success":
            steps = [s for s in steps if s.outcome == "success"]
        world = getattr(run, "world", None)
        variant = self.variant if self.variant is not None else getattr(world, "variant", None)
        seed = self.seed if self.seed is not None else getattr(world, "seed", None)
        task_file = self.task_file or record.task_file or str(getattr(getattr(run, "task_file", None), "path", "")
                                                               or "")
        if not task_file:
            raise RecorderError("the run names no task file")
        config: dict[str, Any] = {"recorded_by": "bt_meta.memory.recorder", **self.config}
        if event is not None:
            config["status"] = event.get("status")
            if event.get("ticks") is not None:
                config["ticks"] = event.get("ticks")
        if record.failures:
            config["failures"] = record.failures
        if record.repairs:
            config["repairs"] = record.repairs
        episode = Episode(
            task=root_task_name(problem), task_file=task_file, problem=str(getattr(problem, "name", record.problem)),
            started=record.started, finished=time.time(), outcome=outcome, variant=variant,
            seed=int(seed) if isinstance(seed, int) else None, config=config,
        )
        trace_steps: list[Step] = []
        expectations: list[Expectation] = []
        for index, pending in enumerate(steps):
            trace_steps.append(Step(
                index, pending.action, pending.args, node_id=pending.node_id, parent_task=pending.parent_task,
                parent_node=pending.parent_node, state=pending.state, outcome=pending.outcome,
                failure_kind=pending.failure_kind, duration=pending.duration))
            if pending.outcome != "success":
                continue
            maps = pending.state.grid_maps
            for position in range(len(maps)) or [None]:
                expectations.append(Expectation(index, pending.action, pending.args, parent_task=pending.parent_task,
                                                facts=pending.added, grid_map_index=position))
        return Trace(episode, tuple(trace_steps), initial=record.initial, expectations=tuple(expectations))

    def _grid_maps(self, world: Any, args: tuple[str, ...], event: Mapping[str, Any],
                   moved: Iterable[str] = ()) -> tuple[GridMap, ...]:
        """The grid-maps of the objects the step names and of those it moved (:func:`moved_objects`), whatever
        their type: from the event's observations when a driver sends them, else from camera perception looking
        at the world now; an object the camera's per-block maps leave out (a catalogue cylinder, a mesh, the
        housing) is cropped from the same view, centred where it truly lies."""
        if not self.grid_maps or world is None:
            return ()
        names = _object_names(world, args)
        names += [name for name in moved if name not in names]
        if not names:
            return ()
        observations = event.get("observations") or {}
        observed = observations.get("object_gridmaps")
        view = observations.get("image")
        camera = None
        if observed is None:
            camera = self._camera()
            if camera is None or getattr(world, "sim", None) is None:
                return ()
            view = camera.look(world)
            if view is None:
                return ()
            observed = camera.object_grid_maps(world, view)
        maps = []
        for name in names:
            found = observed.get(name)
            if found is None:
                found = _cropped(world, view, name)
            if found is not None:
                maps.append(_memory_grid_map(found, name))
        return tuple(maps)

    def _camera(self) -> Any:
        if self.camera is None:
            try:
                import bt_meta_plugins.camera_perception as camera_perception
            except ImportError:  # an installation without the shipped plugins: no grid-maps
                return None
            return camera_perception.plugin.current
        return self.camera

    def _parent(self, run: Any, node_id: str | None, action: str,
                args: tuple[str, ...]) -> tuple[str | None, str | None]:
        if node_id is None:
            return None, None
        tree = self.tree
        if tree is None or node_id not in tree.nodes:
            tree = self._planned(run)
        node = None if tree is None else tree.nodes.get(node_id)
        if node is None or tuple(node.task) != (action, *args) or node.parent is None:
            return None, None
        parent = tree.nodes[node.parent]
        return str(parent.task[0]), str(parent.id)

    def _planned(self, run: Any) -> Any:
        """The decomposition tree of the run's problem, planned once per run when no tree was given."""
        if self._planned_for is not None and self._planned_for[0] is run:
            return self._planned_for[1]
        tree = None
        domain, problem = getattr(run, "domain", None), getattr(run, "problem", None)
        if domain is not None and problem is not None:
            from bt_meta.htn import plan

            try:
                result = plan(domain, problem, external=getattr(run, "external", None))
                tree = result.tree if result.status == "success" else None
            except BtMetaError as error:
                log.info("recorder: the run's problem could not be planned again for parent tasks: %s", error)
        self._planned_for = (run, tree)
        return tree


MOVED_DISTANCE = 0.01
"""m: an object whose position changed more than this during a step was moved by it."""
MOVED_ANGLE = math.radians(10.0)
"""rad: an object turned more than this during a step was moved by it."""


def moved_objects(before: Iterable[ObjectState], after: Iterable[ObjectState]) -> list[str]:
    """The objects whose pose changed by more than :data:`MOVED_DISTANCE` or :data:`MOVED_ANGLE` between two
    states (the step carried, turned or knocked them), in the order of ``after``."""
    old = {state.name: state.pose for state in before}
    out = []
    for state in after:
        pose = old.get(state.name)
        if pose is None:
            continue
        shift = math.dist(pose[:3], state.pose[:3])
        turn = _angle_between(_rotation(pose[3:]), _rotation(state.pose[3:]))
        if shift > MOVED_DISTANCE or turn > MOVED_ANGLE:
            out.append(state.name)
    return out


def _rotation(rpy: Any) -> np.ndarray:
    roll, pitch, yaw = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, (float(np.trace(a.T @ b)) - 1.0) / 2.0)))


def _cropped(world: Any, view: Any, name: str) -> Any:
    """The grid-map of object ``name`` cropped from ``view`` centred where the simulator has it (``None`` without
    a view or the object)."""
    sim = getattr(world, "sim", None)
    if view is None or not hasattr(view, "grid_map_at") or sim is None or name not in sim.object_names():
        return None
    state = sim.object_states().get(name)
    if state is None:
        return None
    block = view.block_near(state.pose[:2], 0.5 * _LB)
    return view.grid_map_at(state.pose[:2], z=None if block is None else block.top_z, object_name=name,
                            colour=state.colour, shape=state.shape)


_LB = 0.061
"""m: a Mega Blok's unit, the width of the search for the object's blob (as camera perception names blocks)."""


def _object_names(world: Any, args: Iterable[str]) -> list[str]:
    """World objects the step's arguments name (through ``world.object_name`` when the world has it)."""
    sim = getattr(world, "sim", None)
    known = set(sim.object_names()) if sim is not None and hasattr(sim, "object_names") else None
    to_world = getattr(world, "object_name", None)
    names = []
    for arg in args:
        name = arg
        if to_world is not None:
            try:
                name = to_world(arg)
            except Exception:  # a number, a pose symbol: not an object
                continue
        if (known is None or name in known) and name not in names:
            names.append(name)
    return names


def _memory_grid_map(value: Any, name: str) -> GridMap:
    if isinstance(value, GridMap):
        return value if value.object_name else GridMap(value.occupancy, value.image, name, value.colour,
                                                        value.shape, value.centroid)
    return GridMap(value.occupancy, getattr(value, "image", None), getattr(value, "object_name", None) or name,
                   getattr(value, "colour", None), getattr(value, "shape", None),
                   tuple(getattr(value, "centroid", (0.0, 0.0))))


def _repair_summary(event: Mapping[str, Any]) -> dict[str, Any]:
    attempt = event.get("attempt") or {}
    proposal = attempt.get("proposal") or event.get("proposal") or {}
    out: dict[str, Any] = {}
    if proposal:
        out["action"] = proposal.get("action")
        out["plugin"] = proposal.get("plugin")
    if attempt.get("step") is not None:
        out["step"] = attempt.get("step")
    return out

