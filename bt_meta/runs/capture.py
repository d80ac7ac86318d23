"""What a watched run records: a progress display, the run's events, object states and tree pictures.

Neither the demo nor ``bt-meta run --report`` ticks trees itself: the :class:`~bt_meta.meta.executor.MetaExecutor`
does, and everything a report shows comes through the framework's own interfaces -- a ``bt_meta_trace_event``
plugin (step starts and ends, failures, repairs, ticks) and, per segment the executor runs, the same
``compile_plan`` of the same plan state (so the picture is the tree that was ticked, with the statuses the step
events reported).

Offers:

* :class:`Progress` -- compact terminal output: one line per step or repair, a tick counter per run on a TTY
* :class:`RunCapture` -- a trace-event plugin collecting one run's events, per-step object states and segments
* :class:`CapturingExecutor` -- a :class:`~bt_meta.meta.executor.MetaExecutor` that snapshots each segment's tree
* :func:`top_view_png` -- a top-view camera image of a simulated world as PNG bytes
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, TextIO

from bt_meta.hookspecs import hookimpl
from bt_meta.meta.executor import MetaExecutor

__all__ = ["CapturingExecutor", "Progress", "RunCapture", "Segment", "top_view_png"]


class Progress:
    """Terminal output of a watched run. ``quiet`` prints nothing (``--json``); on a TTY a run shows a live tick counter
    that the next line overwrites, elsewhere only the lines."""

    def __init__(self, stream: TextIO | None = None, *, quiet: bool = False) -> None:
        self.stream = stream or sys.stdout
        self.quiet = quiet
        self.live = bool(getattr(self.stream, "isatty", lambda: False)()) and not quiet
        self._pending = False
        self._last_live = 0.0

    def line(self, text: str) -> None:
        if self.quiet:
            return
        if self._pending:
            self.stream.write("\r\033[K")
            self._pending = False
        self.stream.write(text + "\n")
        self.stream.flush()

    def tick(self, text: str) -> None:
        """A transient progress indicator (rate-limited; nothing when not on a terminal)."""
        if not self.live:
            return
        now = time.perf_counter()
        if now - self._last_live < 0.05:
            return
        self._last_live = now
        self.stream.write("\r\033[K" + text)
        self.stream.flush()
        self._pending = True

    def done(self) -> None:
        if self._pending:
            self.stream.write("\r\033[K")
            self.stream.flush()
            self._pending = False


@dataclass
class Segment:
    """One ticked tree of a run: its number, the compiled tree (see :mod:`bt_meta.runs.svg`), where it resumed."""

    number: int
    tree: Any
    cursor: int
    statuses: dict[str, str] = field(default_factory=dict)
    guards: dict[str, str] = field(default_factory=dict)


class RunCapture:
    """Collects one run's trace events and the object states after each step; prints progress lines.

    Register it as a plugin for the run only. ``world`` is read (object states) when a step ends.
    """

    def __init__(self, progress: Progress, world: Any = None, *, label: str = "", echo: bool = True) -> None:
        self.progress = progress
        self.world = world
        self.label = label
        self.echo = echo
        self.events: list[dict[str, Any]] = []
        self.steps: list[dict[str, Any]] = []
        self.failures: list[dict[str, Any]] = []
        self.repairs: list[dict[str, Any]] = []
        self.segments: list[Segment] = []
        self.decisions: list[dict[str, Any]] = []
        self.ticks = 0
        self._running: str | None = None

    @property
    def segment(self) -> Segment | None:
        return self.segments[-1] if self.segments else None

    def _objects(self) -> dict[str, Any]:
        sim = getattr(self.world, "sim", None)
        if sim is None:
            return {}
        return {name: state.as_dict() for name, state in sim.object_states().items()}

    @hookimpl
    def bt_meta_trace_event(self, event: dict[str, Any]) -> None:
        kind = event.get("type")
        if kind == "tick":
            self.ticks += 1
            self.progress.tick(f"  {self.label} tick {self.ticks:>5}  {self._running or ''}")
            return
        segment = self.segment
        record = {key: value for key, value in event.items() if key != "state"}
        record["segment"] = None if segment is None else segment.number
        record["run_tick"] = self.ticks
        self.events.append(record)
        call = f"{event.get('node_id') or ''} {event.get('action')}({', '.join(map(str, event.get('args') or ()))})"
        if kind == "step_start":
            self._running = call.strip()
        elif kind == "step_end":
            status = str(event.get("status"))
            step = {"segment": record["segment"], "step": event.get("step"), "node_id": event.get("node_id"),
                    "action": event.get("action"), "args": list(event.get("args") or ()), "status": status,
                    "tick": self.ticks, "objects": self._objects()}
            self.steps.append(step)
            if segment is not None and event.get("node_id"):
                segment.statuses[str(event["node_id"])] = status
            if self.echo:
                self.progress.line(f"    tick {self.ticks:>5}  {call.strip():<38} {status}")
            self._running = None
        elif kind == "failure":
            failure = dict(event.get("failure") or {})
            failure["segment"] = record["segment"]
            failure["run_tick"] = self.ticks
            self.failures.append(failure)
            node_id = failure.get("node_id")
            guard = failure.get("step") is None or (failure.get("kind") == "precondition" and
                                                     failure.get("action") is None)
            if segment is not None and node_id and guard:  # a method guard failed (no primitive step named)
                segment.guards[str(node_id)] = "FAILURE"
            if self.echo:
                message = str(failure.get("message", ""))
                if len(message) > 150:
                    message = message[:147] + "..."
                self.progress.line(f"    {'':>10}  ! [{failure.get('kind')}] step {failure.get('step')}: {message}")
        elif kind == "repair":
            self.repairs.append(record)
            if self.echo:
                self.progress.line("    " + _repair_line(record))


def _repair_line(event: dict[str, Any]) -> str:
    outcome = event.get("outcome")
    if outcome == "applied":
        attempt = event.get("attempt") or {}
        proposal = attempt.get("proposal") or {}
        return (f"{'':>10}  repair #{attempt.get('number')}: {proposal.get('action')} by {proposal.get('plugin')} "
                f"(score {proposal.get('score', 0):.2f}) -- {attempt.get('change')}")
    if outcome in ("not_applicable", "equivalent"):
        proposal = event.get("proposal") or {}
        why = "not applicable" if outcome == "not_applicable" else "skipped"
        return f"{'':>10}  proposal {proposal.get('action')} by {proposal.get('plugin')} {why}: " \
               f"{str(event.get('reason'))[:110]}"
    return f"{'':>10}  meta-reasoner stops: {str(event.get('reason'))[:140]}"


class CapturingExecutor(MetaExecutor):
    """The repair executor, unchanged, plus a snapshot of each segment's compiled tree for the report.

    The snapshot is compiled by the same :func:`~bt_meta.bt.compiler.compile_plan` from the same plan state the
    executor compiles and ticks; it is never ticked itself -- node statuses come from the run's step events.
    """

    def __init__(self, *args: Any, capture: RunCapture, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.capture = capture
        decide = self.reasoner.decide

        def recording_decide(diagnosis: Any, *more: Any, **options: Any) -> Any:
            decision = decide(diagnosis, *more, **options)
            capture.decisions.append(_decision_record(diagnosis, decision, capture))
            return decision

        self.reasoner.decide = recording_decide  # type: ignore[method-assign]

    def _segment(self, run: Any, plan_state: Any, *args: Any, **kwargs: Any) -> Any:
        from bt_meta.bt.compiler import compile_plan
        from bt_meta.bt.domain_nodes import domain_registry

        number = len(self.capture.segments) + 1
        tree = None
        remaining = plan_state.remaining_tree()
        if remaining.roots:
            try:
                tree = compile_plan(remaining, run.domain, registry=domain_registry(run.domain, self.plugins),
                                    name=f"plan {getattr(self.problem, 'name', '')} segment {number}")
            except Exception as error:  # the picture is optional; the executor reports compile errors itself
                tree = error
        self.capture.segments.append(Segment(number, tree, plan_state.cursor))
        if number > 1:
            self.capture.progress.line(f"    {'':>10}  segment {number}: resume at step {plan_state.cursor}")
        return super()._segment(run, plan_state, *args, **kwargs)


def _decision_record(diagnosis: Any, decision: Any, capture: RunCapture) -> dict[str, Any]:
    """The reasoner's diagnosis (kind, step, evidence) and every proposal it ranked, for the repair log."""
    failure = diagnosis.failure
    evidence = {key: value for key, value in (failure.evidence or {}).items()
                if key not in ("plan", "repair_history", "localisation")}
    return {
        "segment": None if capture.segment is None else capture.segment.number,
        "run_tick": capture.ticks,
        "kind": diagnosis.kind.value, "step": diagnosis.step, "node_id": diagnosis.node_id,
        "classified_by": diagnosis.classified_by, "message": failure.message,
        "action": failure.action, "args": list(failure.args or ()),
        "evidence": evidence,
        "proposals": [p.to_dict() for p in decision.proposals],
        "dropped": list(decision.dropped or []),
        "stop": decision.stop, "reason": decision.reason,
    }


def top_view_png(world: Any, camera: Any = None) -> tuple[bytes | None, Any]:
    """A top-view RGB image of ``world``'s table as PNG bytes, and the analysed view (``None`` without a sim)."""
    import cv2

    if camera is None:
        from bt_meta_plugins.camera_perception import CameraPerception

        camera = CameraPerception()
    view = camera.look(world)
    if view is None:
        return None, None
    ok, buffer = cv2.imencode(".png", cv2.cvtColor(view.rgb, cv2.COLOR_RGB2BGR))
    return (buffer.tobytes() if ok else None), view
