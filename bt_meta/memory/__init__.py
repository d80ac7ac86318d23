"""The episodic memory: a crash-safe SQLite store of execution traces, P_a and E_db, for the meta-reasoner.

Offers:

* :class:`EpisodicMemory` -- open a memory file, write a whole :class:`Trace` in one transaction, read it back,
  and ask the paper's queries: expected state after step i of a task, states that led to success of an action,
  last N traces of a task, P_a (``plan_executions``), E_db (``expectations``, ``expectation_of``) and vectorised
  nearest-neighbour grid-map retrieval (``nearest_grid_maps``)
* the trace data model: :class:`Trace`, :class:`Episode`, :class:`Step`, :class:`State`, :class:`ObjectState`,
  :class:`GridMap`, :class:`Expectation`, and :class:`TraceError` for malformed ones
* query results: :class:`EpisodeSummary`, :class:`StepRecord`, :class:`PlanStep`, :class:`GridMapMatch`;
  :func:`grid_distance`, the metric of the grid-map retrieval
* :class:`MemoryStoreError` -- an unusable memory file (corrupt, foreign, newer schema, unwritable), naming its path
* :class:`MemoryFileError` -- the subclass for a file the user must fix (bad input: the CLI exits 2)
* :func:`add_memory_argument` / :func:`resolve_memory_path` -- the ``--memory PATH`` flag and ``BT_META_MEMORY``
  every memory-using command shares; the default file is ``./.bt-meta/memory.sqlite``
* :data:`SCHEMA_VERSION` -- the schema version this bt-meta writes
"""

from __future__ import annotations

from bt_meta.memory.location import ENV_VAR, add_memory_argument, resolve_memory_path
from bt_meta.memory.schema import SCHEMA_VERSION, MemoryFileError, MemoryStoreError
from bt_meta.memory.store import (
    EpisodeSummary,
    EpisodicMemory,
    GridMapMatch,
    PlanStep,
    StepRecord,
    grid_distance,
)
from bt_meta.memory.trace import (
    Episode,
    Expectation,
    GridMap,
    ObjectState,
    State,
    Step,
    Trace,
    TraceError,
)

__all__ = [
    "ENV_VAR",
    "SCHEMA_VERSION",
    "Episode",
    "EpisodeSummary",
    "EpisodicMemory",
    "Expectation",
    "GridMap",
    "GridMapMatch",
    "MemoryFileError",
    "MemoryStoreError",
    "ObjectState",
    "PlanStep",
    "State",
    "Step",
    "StepRecord",
    "Trace",
    "TraceError",
    "add_memory_argument",
    "grid_distance",
    "resolve_memory_path",
]
