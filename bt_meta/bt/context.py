"""The run a tree executes in: world, plugins, belief state, recorded failures, tick count.

Monitors, actions and guards find the run through the blackboard (``/bt_meta/run``) when they start, so a tree
compiled or loaded once can be ticked in any run. The run mirrors its parts to the documented keys:

* ``/bt_meta/world`` -- the :class:`~bt_meta.world.base.World`
* ``/bt_meta/state`` -- the belief :class:`~bt_meta.htn.state.State` (updated after every monitored step)
* ``/bt_meta/failures`` -- the list of :meth:`~bt_meta.bt.failures.Failure.to_dict` records

Offers:

* :class:`RunContext` -- the run; :meth:`RunContext.install` puts it on the blackboard,
  :meth:`RunContext.record_failure` records, logs, traces and hands a failure to the meta-reasoner hook
* :func:`current_run` -- the installed run (``None`` when none is)
* the key constants
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

import py_trees

from bt_meta.bt.failures import Failure, FailureKind
from bt_meta.bt.nodes.ticking import MAX_WAKE_UPS
from bt_meta.htn.state import State

if TYPE_CHECKING:
    from bt_meta.bt.expectations import StepContext
    from bt_meta.plugins import HookResult, PluginHost

RUN_KEY = "/bt_meta/run"
WORLD_KEY = "/bt_meta/world"
STATE_KEY = "/bt_meta/state"
FAILURES_KEY = "/bt_meta/failures"

log = logging.getLogger("bt_meta.run")

# py_trees keeps one process-wide blackboard store; bt-meta writes its own keys straight into it (no client
# bookkeeping on the tick path) and reads them back the same way.
_STORAGE: dict[str, Any] = py_trees.blackboard.Blackboard.storage


def current_run() -> RunContext | None:
    return _STORAGE.get(RUN_KEY)


class RunContext:
    """One execution of a tree: the world it acts on, the plugins it calls, what it believes and what failed."""

    def __init__(
        self,
        world: Any = None,
        plugins: PluginHost | None = None,
        *,
        domain: Any = None,
        problem: Any = None,
        state: State | None = None,
        task_file: Any = None,
        memory: Any = None,
    ) -> None:
        self.world = world
        # The episodic memory the run reads expectations from (expectation plugins look here before
        # BT_META_MEMORY and the default file); None when the run has none.
        self.memory = memory
        self.plugins = plugins
        self.domain = domain
        self.problem = problem
        self.task_file = task_file
        if state is None:
            state = world.symbolic_state() if world is not None else State()
        self._state = state
        self.failures: list[Failure] = []
        self.failure_records: list[dict[str, Any]] = []
        self.tick_count = 0
        self.steps_started = 0
        # What the observe plugins reported just before the run's first monitored step started (taken only when
        # some plugin compares expectations): the world as the run found it, so the first step's comparison can
        # tell what was already there from what the step did. None until then.
        self.start_observations: dict[str, Any] | None = None
        # Which hooks anyone implements, fixed for the run: monitors skip the others without asking.
        self.hooks: frozenset[str] = frozenset() if plugins is None else plugins.implemented_hooks()
        self._trace = "bt_meta_trace_event" in self.hooks
        self._external = None if plugins is None else plugins.external_predicate

    # -- blackboard ---------------------------------------------------------------------------------------------

    def install(self) -> RunContext:
        """Make this the run monitors and actions see, and write the documented keys."""
        _STORAGE[RUN_KEY] = self
        _STORAGE[WORLD_KEY] = self.world
        _STORAGE[STATE_KEY] = self._state
        _STORAGE[FAILURES_KEY] = self.failure_records
        return self

    @property
    def state(self) -> State:
        return self._state

    @state.setter
    def state(self, value: State) -> None:
        self._state = value
        if _STORAGE.get(RUN_KEY) is self:
            _STORAGE[STATE_KEY] = value

    @property
    def external(self) -> Any:
        """The ``external`` callable for conditions (``None`` without plugins)."""
        return self._external

    # -- plugins ------------------------------------------------------------------------------------------------

    @property
    def tracing(self) -> bool:
        return self._trace

    def emit(self, event_type: str, **data: Any) -> None:
        """Send a trace event to ``bt_meta_trace_event`` implementations (nothing to do when there are none)."""
        if not self._trace:
            return
        event = {"type": event_type, "tick": self.tick_count, **data}
        result = self.plugins.call("bt_meta_trace_event", event=event)  # type: ignore[union-attr]
        for error in result.errors:
            # A broken trace plugin must not recurse into tracing its own failure.
            self._store(self._internal(error, None), notify=False)

    def start(self) -> None:
        """Install the run and emit ``run_start`` (whoever drives a whole run calls this once)."""
        self.install()
        if self._trace:
            problem = getattr(self.problem, "name", None)
            self.emit("run_start", task_file=getattr(self.task_file, "path", None), problem=problem,
                      state=[" ".join(atom) for atom in sorted(self._state)])

    def finish(self, status: Any) -> None:
        """Emit ``run_end`` with the root's final status."""
        if self._trace:
            self.emit("run_end", status=getattr(status, "value", status), ticks=self.tick_count,
                      failures=len(self.failures))

    def contain(self, result: HookResult, context: StepContext | None) -> Failure | None:
        """Record every error of a safe hook call as an ``internal`` failure; return the first (or ``None``)."""
        first = None
        for error in result.errors:
            failure = self._internal(error, context)
            self.record_failure(failure, context)
            first = first or failure
        return first

    @staticmethod
    def _internal(error: Any, context: StepContext | None) -> Failure:
        return Failure(
            kind=FailureKind.INTERNAL,
            message=error.message,
            step=None if context is None else context.step,
            node_id=None if context is None else context.node_id,
            action=None if context is None else context.action,
            args=() if context is None else context.args,
            evidence={"hook": error.hook, "error": f"{type(error.error).__name__}: {error.error}",
                      "traceback": error.traceback},
            plugin=error.plugin,
            node_name=None if context is None else context.node_name,
        )

    def tick(self, root: py_trees.behaviour.Behaviour, visit: Any = None) -> py_trees.common.Status:
        """Tick ``root`` once inside this run (installing it first) and return the root's status.

        Like BehaviorTree.CPP's ``tickOnce``, the root is ticked again while it is RUNNING and a node raised the
        tree's wake-up signal (at most :data:`~bt_meta.bt.nodes.ticking.MAX_WAKE_UPS` times, where BT.CPP would
        spin forever). ``visit(behaviour)`` sees every behaviour as it finishes its part of the tick.
        """
        if _STORAGE.get(RUN_KEY) is not self:
            self.install()
        self.tick_count += 1
        signal = getattr(root, "bt_wake_up", None)
        wake_ups = 0
        while True:
            if visit is None:
                root.tick_once()
            else:
                for behaviour in root.tick():
                    visit(behaviour)
            if root.status is not py_trees.common.Status.RUNNING or signal is None or not signal.consume():
                break
            wake_ups += 1
            if wake_ups >= MAX_WAKE_UPS:  # a Repeat num_cycles="-1" over an instant child: --ticks must bound it
                break
        if self._trace:
            self.emit("tick", status=root.status.value)
        return root.status

    # -- failures -----------------------------------------------------------------------------------------------

    def record_failure(self, failure: Failure, context: StepContext | None = None) -> Failure:
        """Record ``failure`` (blackboard, run log, trace), then call the meta-reasoner hook ``bt_meta_on_failure``."""
        index = len(self.failure_records)
        self._store(failure, notify=True)
        plugins = self.plugins
        if plugins is not None and "bt_meta_on_failure" in self.hooks:
            result = plugins.call("bt_meta_on_failure", failure=failure, context=context)
            if result.results:
                failure.evidence.setdefault("meta", {}).update({name: value for name, value in result.results})
            if result.errors:
                # An observer that breaks is noted on the failure it observed, never recorded as a failure of its
                # own: that would become the run's latest failure and change (or prevent) the repair.
                notes = failure.evidence.setdefault("observer_errors", [])
                for error in result.errors:
                    log.warning("%s", error.message)
                    notes.append({"plugin": error.plugin, "hook": error.hook, "error": error.message})
            if result.results or result.errors:
                self.failure_records[index] = failure.to_dict()
        return failure

    def _store(self, failure: Failure, notify: bool) -> None:
        if failure.tick is None:
            failure.tick = self.tick_count
        self.failures.append(failure)
        record = failure.to_dict()
        self.failure_records.append(record)
        log.info("%s", failure.summary())
        if notify:
            self.emit("failure", failure=record)
