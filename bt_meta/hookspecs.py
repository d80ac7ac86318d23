"""The pluggy hook specifications of bt-meta (project name ``"bt_meta"``).

Every strategy -- perception, expectations, comparison, failure classification, repair, trace recording,
external predicates, node types, worlds -- is a hook implementation; the strategies bt-meta ships are plugins
registered exactly like a user's. A plugin is a module (or object) with functions decorated by
:data:`hookimpl` whose names are the hooks below; it may implement any subset and accept any subset of a hook's
arguments, by name.

Offers:

* :data:`hookspec`, :data:`hookimpl` -- the markers (``from bt_meta.plugins import hookimpl`` in a plugin)
* the hook specifications, in the order a run meets them:

  ============================== ========== ===========================================================
  hook                           firstresult called
  ============================== ========== ===========================================================
  ``bt_meta_register_nodes``     no         when a node registry is built (XML loading, compiling)
  ``bt_meta_make_world``         yes        when a command needs a world by name (``--world fake``)
  ``bt_meta_external_predicate`` yes        when the planner or a guard evaluates an external predicate
  ``bt_meta_trace_event``        no         run start/end, every tree tick, every step start/end, failures
  ``bt_meta_observation_needs``  no         before each observation: which observation keys a reader reads
  ``bt_meta_observe``            no         before a run's first step, after each step: gather observations
  ``bt_meta_expectations``       no         after a primitive's skill succeeds: what should now hold
  ``bt_meta_compare``            yes        once per expectation: does the observation match it
  ``bt_meta_classify_failure``   yes        on a mismatch or a kind-less failure: the taxonomy kind
  ``bt_meta_on_failure``         no         after a failure is recorded (the meta-reasoner hook)
  ``bt_meta_propose_repairs``    no         when the meta-reasoner asks for repairs of a failure
  ============================== ========== ===========================================================

Containment: the monitor and the run call hooks through :meth:`bt_meta.plugins.PluginHost.call`, which calls
implementations one by one; each of these becomes a :class:`~bt_meta.bt.failures.Failure` of kind ``internal``
naming the plugin, the hook and what went wrong, the monitored node fails, and the tree keeps ticking:

* an exception, ``SystemExit`` included (a plugin calling ``sys.exit`` does not end the command;
  ``KeyboardInterrupt`` still does);
* a result of the wrong type -- each hook's "Return ..." below is checked (:mod:`bt_meta.hook_contracts`), so
  ``42`` from ``bt_meta_expectations`` is ``plugin 'p' broke the contract of bt_meta_expectations: returned int
  42; ...``; hooks that return nothing may return anything, it is ignored;
* a call longer than the host's time budget (``--hook-budget SECONDS``, ``$BT_META_HOOK_BUDGET``, default 60 s;
  :mod:`bt_meta.hook_budget`): in the main thread a watchdog interrupts the late call where it is, within 50 ms of
  its deadline (a ``HookTimeout`` raised inside it, its ``finally`` blocks run); in another thread, or inside C code
  that does not return to Python, it runs to its end. Its result is discarded either way.

``bt_meta_on_failure`` is an observer: an error in it is noted on the failure it observed
(``evidence["observer_errors"]``) and logged, never recorded as a failure of its own, so it cannot change which
failure the meta-reasoner repairs. ``bt_meta_make_world`` errors surface as the command's error (no world, no run).
Hook wrappers (``wrapper=True`` / ``hookwrapper=True``) cannot be contained and are refused at load time.
Hooks nobody implements cost nothing on the tick path: monitors skip them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pluggy

if TYPE_CHECKING:
    from bt_meta.bt.expectations import Comparison, Expectation, ObserveRequest, StepContext
    from bt_meta.bt.failures import Failure, FailureKind, RepairProposal

PROJECT_NAME = "bt_meta"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


@hookspec
def bt_meta_register_nodes(registry: Any, domain: Any) -> None:
    """Add node types to a behaviour-tree node registry.

    Called when bt-meta builds the registry used to load tree XML or compile a plan, after the built-in nodes and
    the domain's primitives (``domain`` may be ``None`` for a tree without a task file). Call
    ``registry.register(NodeType(...))`` (see :mod:`bt_meta.bt.registry`); registering an ID that already
    exists is the registry's error. Return nothing.
    """


@hookspec(firstresult=True)
def bt_meta_make_world(name: str, domain: Any, problem: Any, options: dict[str, Any]) -> Any:
    """Create the world named ``name`` (``bt-meta tick --world NAME``) for ``problem`` of ``domain``.

    Return an object implementing :class:`bt_meta.world.base.World`, or ``None`` when this plugin does not
    provide a world of that name (the next plugin is asked). ``options`` holds command-line settings
    (``seed``, ``ticks_per_skill``, ...); ignore the ones you do not know. First non-``None`` result wins.
    """


@hookspec(firstresult=True)
def bt_meta_external_predicate(name: str, args: tuple[str, ...], state: Any) -> bool | None:
    """Evaluate the external predicate ``name(*args)`` (declared under ``external:`` in a task file) in ``state``.

    Called by the planner and by guards whenever a condition mentions an external predicate. Return ``True`` or
    ``False``, or ``None`` when this plugin does not know the predicate (the next plugin is asked). When no
    plugin answers, evaluation raises :class:`~bt_meta.errors.PluginError` naming the predicate.
    """


@hookspec
def bt_meta_trace_event(event: dict[str, Any]) -> None:
    """Receive one trace event of a run (episodic memory, loggers, progress displays implement this).

    ``event["type"]`` is one of ``"run_start"`` (with ``task_file``, ``problem``, ``state``; emitted by whoever
    drives the run: ``bt-meta tick``, the harness's ``from_file``, the repair executor), ``"tick"``
    (``tick``, ``status``), ``"step_start"`` / ``"step_end"`` (the step's ``action``, ``args``, ``node_id``,
    ``step``; ``step_end`` adds ``status``, ``state`` (sorted atom texts) and ``failure``), ``"uncompared"``
    (an expectation no plugin compared), ``"failure"`` (``failure``: a :meth:`Failure.to_dict` record) and
    ``"run_end"`` (``status``, ``ticks``). Other drivers add their own types (the executor's ``"repair"``);
    ignore types you do not know. Every event has ``tick``. Return nothing; an exception is recorded as an
    ``internal`` failure and the run goes on.
    """


@hookspec
def bt_meta_observation_needs(context: StepContext) -> list[str] | None:
    """Say which observation keys this plugin will read after the step in ``context`` (``"image"``,
    ``"objects"``, ...), so observe plugins produce only those.

    Called before every observation of a monitored step (and before the one a run takes before its first step).
    Implement it in a plugin that reads observations (a ``bt_meta_compare``, or anything reading
    ``RunContext.start_observations``); include what later steps read from this observation (a view kept to
    compare the next step with). Return a list of keys, ``[]`` when it reads nothing now, or ``None`` for "I do not
    know": then every key is requested. While any ``bt_meta_compare`` plugin does not implement this hook, every
    observation requests every key (a reader written before this hook existed gets everything, as before); with
    no comparison plugin and no implementation of this hook only ``"symbolic_state"`` (the belief) is requested.
    """


@hookspec
def bt_meta_observe(world: Any, context: StepContext, request: ObserveRequest) -> dict[str, Any] | None:
    """Observe the world: before a run's first step (``RunContext.start_observations``), after the step in
    ``context`` succeeded, and after it failed (for the belief state).

    Return a dict of observations keyed by modality, or ``None`` to contribute nothing. Keys in use:
    ``"symbolic_state"`` (a :class:`bt_meta.htn.State`: the monitor also adopts it as the new belief state),
    ``"objects"`` (object name -> object state), ``"gridmaps"``, ``"image"``. Results of all plugins are merged;
    when two plugins give the same key the first one called (the last registered) is kept.

    ``request`` (an :class:`~bt_meta.bt.expectations.ObserveRequest`) says which keys will be read
    (``request.wants("image")``, gathered through :func:`bt_meta_observation_needs`): skip costly keys nobody
    wants (a camera frame), and return ``None`` when you would produce none of them. A key not wanted may still
    be returned; it is ignored. Accepting ``request`` is optional (pluggy passes only the arguments a hook
    implementation names): an implementation taking ``(world, context)`` is called as before and its results
    used alike.
    """


@hookspec
def bt_meta_expectations(context: StepContext) -> list[Expectation] | None:
    """What should hold after the step in ``context`` succeeded.

    Return a list of :class:`~bt_meta.bt.expectations.Expectation` (or ``None``). Each is compared with the
    observations through :func:`bt_meta_compare`; an expectation no plugin compares is skipped and reported as a
    ``"uncompared"`` trace event. All plugins' lists are concatenated.
    """


@hookspec(firstresult=True)
def bt_meta_compare(expectation: Expectation, observations: dict[str, Any], context: StepContext) -> Comparison | None:
    """Compare one expectation with the merged observations of the step.

    Return a :class:`~bt_meta.bt.expectations.Comparison` (``matched`` plus evidence), or ``None`` when this
    plugin does not compare expectations of ``expectation.kind`` (the next plugin is asked). First non-``None``
    result wins.
    """


@hookspec(firstresult=True)
def bt_meta_classify_failure(
    failure: Failure, mismatches: list[Comparison], context: StepContext | None
) -> FailureKind | str | None:
    """Decide the taxonomy kind of a failure.

    Called when a monitor found mismatches (``failure.kind`` then holds the expectation's suggested kind) and when
    a skill failed without saying why. Return a kind (a :class:`FailureKind` or its string) or ``None`` to leave
    the decision to the next plugin; with no answer the suggested kind stays. Firstresult: the first plugin that
    answers decides (the shipped rules are one plugin among others; ``tryfirst=True`` overrides them).
    """


@hookspec
def bt_meta_on_failure(failure: Failure, context: StepContext | None) -> dict[str, Any] | None:
    """React to a recorded failure: the meta-reasoner hook.

    Called after ``failure`` was appended to ``/bt_meta/failures`` and logged, before the monitored node returns
    FAILURE. Return ``None`` or a JSON-able dict of notes; notes are stored under ``failure.evidence["meta"]``
    keyed by plugin name. The shipped default (``bt_meta_plugins.reporting``) only reports.
    """


@hookspec
def bt_meta_propose_repairs(failure: Failure, context: StepContext | None) -> list[RepairProposal] | None:
    """Propose repairs for ``failure``.

    Return a list of :class:`~bt_meta.bt.failures.RepairProposal` (or ``None``); the meta-reasoner collects every
    plugin's proposals and applies the best-scored first. Never loop on collision or reachability failures:
    return nothing for kinds you cannot repair.
    """
