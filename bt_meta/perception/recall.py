"""How expectation plugins find the episodic memory and what it remembers about the step being monitored.

The memory a run uses is, in order: the one a plugin was built with, ``context.run.memory`` when the run carries
one, else the file ``BT_META_MEMORY`` or ``./.bt-meta/memory.sqlite`` names (see
:func:`bt_meta.memory.resolve_memory_path`) when it exists, opened read-only. No memory means no low-level
expectations, never an error: a task nobody demonstrated has nothing to expect. A file that exists but is not a
usable memory raises :class:`~bt_meta.memory.MemoryStoreError` (a monitor records it as an ``internal`` failure).

A monitored step is matched with stored steps by the root task of the run's problem and the plan step index
(``expected_states(task, i)``), keeping those with the same action and arguments; when the plan has changed
(after a repair) it falls back to every successful occurrence of the same action and arguments
(``successful_states``). The stored steps also tell whether the step ends its parent task: its expectation is
then the task's expectation too (section 6.2, "bubbled up").

Offers:

* :func:`memory_for` -- the memory for a step context (or ``None``)
* :func:`root_task` -- the root task name of the run's problem (the key of the memory's episodes)
* :class:`Remembered` / :func:`remember` -- the stored states after the matching step of up to N successful
  episodes, with the parent task and whether the step ends it
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bt_meta.memory import EpisodicMemory, StepRecord, resolve_memory_path
from bt_meta.memory.location import ENV_VAR

__all__ = ["Remembered", "memory_for", "remember", "root_task"]

_OPENED: dict[Path, tuple[float, EpisodicMemory]] = {}
_RESOLVED: dict[tuple[str | None, str], Path] = {}


def _default_path() -> Path:
    """``resolve_memory_path`` for the current environment and folder, remembered: monitors ask at every step."""
    key = (os.environ.get(ENV_VAR), os.getcwd())
    path = _RESOLVED.get(key)
    if path is None:
        path = _RESOLVED[key] = resolve_memory_path(None)
    return path


def memory_for(context: Any, explicit: EpisodicMemory | None = None) -> EpisodicMemory | None:
    """The memory the expectations of ``context`` come from (see the module docstring), or ``None``."""
    if explicit is not None:
        return explicit
    run = getattr(context, "run", None)
    memory = getattr(run, "memory", None)
    if memory is not None:
        return memory
    path = _default_path()
    try:
        stamp = os.stat(path).st_mtime
    except OSError:
        return None
    cached = _OPENED.get(path)
    if cached is not None and cached[0] == stamp:
        return cached[1]
    # A file that is there but unusable is an error worth seeing (the monitor records it as ``internal``).
    opened = EpisodicMemory.open(path, readonly=True)
    if cached is not None:
        cached[1].close()
    _OPENED[path] = (stamp, opened)
    return opened


def root_task(context: Any) -> str | None:
    """The name of the problem's root task when it has exactly one (``draw_A``, ``AttachAndVerify``)."""
    run = getattr(context, "run", None)
    problem = getattr(run, "problem", None)
    tasks = getattr(problem, "tasks", None)
    if not tasks or len(tasks) != 1:
        return None
    return str(tasks[0][0])


@dataclass(frozen=True)
class Remembered:
    """Stored steps matching the monitored one, newest first, one per episode.

    ``key`` says how they were found (``"plan step"`` or ``"action"``); ``parent_task`` is the stored steps'
    parent task; ``task_end`` whether the step is the last primitive of that task in every matching episode.
    """

    records: tuple[StepRecord, ...]
    key: str
    parent_task: str | None
    task_end: bool

    @property
    def states(self) -> list[Any]:
        return [record.step.state for record in self.records]


def _same_call(record: StepRecord, action: str, args: tuple[Any, ...]) -> bool:
    return record.step.action == action and list(record.step.args) == [str(a) for a in args]


def remember(memory: EpisodicMemory, context: Any, n: int) -> Remembered | None:
    """The stored states after the step matching ``context`` in up to ``n`` successful episodes, or ``None``."""
    action, args = context.action, tuple(context.args)
    task, step = root_task(context), getattr(context, "step", None)
    records: list[StepRecord] = []
    key = "plan step"
    if task is not None and step is not None:
        records = [r for r in memory.expected_states(task, step, last=n) if _same_call(r, action, args)]
    if not records:
        key = "action"
        seen: set[int] = set()
        for record in memory.successful_states(action, args=[str(a) for a in args]):
            if record.episode_id not in seen:
                seen.add(record.episode_id)
                records.append(record)
            if len(records) >= n:
                break
    if not records:
        return None
    return Remembered(tuple(records), key, records[0].step.parent_task, _ends_task(memory, records))


def _ends_task(memory: EpisodicMemory, records: list[StepRecord]) -> bool:
    """Whether each stored step is the last of its parent-task occurrence (no next step under the same node).

    Reads P_a (steps without their states) once per root task, not the states of the next steps."""
    plans: dict[str, dict[tuple[int, int], Any]] = {}
    for record in records:
        step = record.step
        if step.parent_node is None and step.parent_task is None:
            return False
        rows = plans.get(record.task)
        if rows is None:
            rows = plans[record.task] = {(p.episode_id, p.step_index): p
                                         for p in memory.plan_executions(record.task)}
        nxt = rows.get((record.episode_id, step.index + 1))
        if nxt is not None and nxt.parent_task == step.parent_task and nxt.parent_node == step.parent_node:
            return False
    return True
