"""The episodic memory: a SQLite file of execution traces and the queries the meta-reasoner asks of it.

Offers:

* :class:`EpisodicMemory` -- ``EpisodicMemory.open(path)``; ``write(trace)`` in one transaction; read back
  (``trace``, ``traces``, ``episodes``, ``last_traces``, ``grid_map``); the paper's queries
  (``expected_states``, ``successful_states``, ``plan_executions`` = P_a, ``expectations`` and
  ``expectation_of`` = E_db) and ``nearest_grid_maps``, vectorised NN retrieval; ``check`` and
  ``integrity_check`` prove a file sound
* :class:`EpisodeSummary`, :class:`StepRecord`, :class:`PlanStep`, :class:`GridMapMatch` -- query results
* :func:`grid_distance` -- the grid-map distance used by ``nearest_grid_maps`` (for callers that compare two maps)
* :func:`pack_bits` -- rows of 0/1 cells as 64-bit words, the form the NN cache keeps

Durability: the file is in WAL mode with ``synchronous=NORMAL``, foreign keys on and a busy timeout, and a
trace is written between ``BEGIN IMMEDIATE`` and ``COMMIT``: a process killed at any instant leaves either the
whole trace or none of it (a power cut may lose the last committed traces, never leave half of one). Every
episode and step declares its counts, and :meth:`EpisodicMemory.check` proves them.

Grid-map distance: the number of cells whose occupancy differs (Hamming distance of the binary occupancy, equal
to the L1 distance of 0/1 grids), minimised over the quarter-turn rotations of the query (four for square maps,
two for others). Rotation matters because a block placed at 90 degrees in one shape is the same form as in
another (section 6.4 matches A's 1x2 against H's pair of 1x1); callers who need orientation to count pass
``rotations=False``. It is computed for every stored map at once as the popcount of ``stored XOR query`` over a
cached array of bit-packed maps (one 64-bit word per 6x6 map); the cache is rebuilt after this connection writes
or when ``PRAGMA data_version`` shows another connection did.
"""

from __future__ import annotations

import json
import os
import sqlite3
import stat
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from bt_meta.errors import UserInputError
from bt_meta.memory.schema import (
    SCHEMA_VERSION,
    MemoryFileError,
    MemoryStoreError,
    migrate,
    read_version,
    sqlite_failure,
)
from bt_meta.memory.trace import (
    Episode,
    Expectation,
    GridMap,
    ObjectState,
    State,
    Step,
    Trace,
    json_tuple,
)
from bt_meta.user_files import check_path_text

BUSY_TIMEOUT_MS = 10_000
SQLITE_HEADER = b"SQLite format 3\x00"

_T = TypeVar("_T")


@dataclass(frozen=True)
class EpisodeSummary:
    """One line of ``memory ls``: the episode header and the sizes of its trace."""

    episode: Episode
    step_count: int
    object_count: int
    grid_map_count: int
    expectation_count: int


@dataclass(frozen=True)
class StepRecord:
    """A stored step with where it came from; ``before`` is the state it started from (when asked for)."""

    episode_id: int
    task: str
    step: Step
    before: State | None = None


@dataclass(frozen=True)
class PlanStep:
    """One row of P_a: step i of a successful (annotated) plan execution and its symbolic outcome."""

    episode_id: int
    task: str
    problem: str
    variant: str | None
    step_index: int
    task_index: int | None
    action: str
    args: tuple[Any, ...]
    node_id: str | None
    parent_task: str | None
    facts: tuple[tuple[Any, ...], ...]
    parent_node: str | None = None


@dataclass(frozen=True)
class GridMapMatch:
    """One nearest-neighbour hit in E_db; ``rotation`` quarter-turns of the query (``np.rot90``) matched best."""

    expectation_id: int
    grid_map_id: int
    episode_id: int
    task: str
    step_index: int
    action: str
    args_pattern: tuple[Any, ...]
    parent_task: str | None
    colour: str | None
    shape: str | None
    distance: int
    rotation: int


def grid_distance(a: np.ndarray, b: np.ndarray, *, rotations: bool = True) -> tuple[int, int]:
    """(cells that differ, quarter-turns of ``a``) for the best rotation; the metric of ``nearest_grid_maps``."""
    first = np.asarray(a) != 0
    second = np.asarray(b) != 0
    best: tuple[int, int] | None = None
    for turns in _turns(first.shape, rotations):
        turned = np.rot90(first, turns)
        if turned.shape != second.shape:
            continue
        candidate = (int(np.count_nonzero(turned != second)), turns)
        if best is None or candidate[0] < best[0]:
            best = candidate
    if best is None:
        raise ValueError(f"grid-maps of shapes {first.shape} and {second.shape} cannot be compared")
    return best


def _turns(shape: tuple[int, ...], rotations: bool) -> tuple[int, ...]:
    if not rotations:
        return (0,)
    return (0, 1, 2, 3) if shape[0] == shape[1] else (0, 2)


class _GridIndex:
    """Every stored expectation grid-map of one shape as a matrix, with the columns the filters need."""

    def __init__(self, rows: list[tuple[Any, ...]], shape: tuple[int, int]) -> None:
        self.shape = shape
        count = len(rows)
        cells = shape[0] * shape[1]
        blob = b"".join(row[9] for row in rows)
        occupancy = np.frombuffer(blob, dtype=np.uint8).reshape(count, cells)
        self.cells = cells
        self.packed = pack_bits(occupancy != 0)
        self.expectation_ids = np.array([row[0] for row in rows], dtype=np.int64)
        self.grid_map_ids = np.array([row[1] for row in rows], dtype=np.int64)
        self.episode_ids = np.array([row[2] for row in rows], dtype=np.int64)
        self.step_indices = np.array([row[4] for row in rows], dtype=np.int64)
        self.success = np.array([row[12] == "success" for row in rows], dtype=bool)
        self.all_success = bool(self.success.all())
        self.tasks = [row[3] for row in rows]
        self.actions = [row[5] for row in rows]
        self.args_patterns = [row[6] for row in rows]
        self.parent_tasks = [row[7] for row in rows]
        self.colours = [row[10] for row in rows]
        self.shapes = [row[11] for row in rows]
        self._codes: dict[str, np.ndarray] = {}

    def mask_equal(self, column: str, value: str) -> np.ndarray:
        # Code strings once per column so that a filter is one vectorised comparison.
        codes = self._codes.get(column)
        values: list[Any] = getattr(self, column)
        if codes is None:
            table: dict[Any, int] = {}
            codes = np.array([table.setdefault(v, len(table)) for v in values], dtype=np.int64)
            self._codes[column] = codes
            self._codes[column + ":table"] = np.array(list(table), dtype=object)
        table_values = self._codes[column + ":table"]
        hits = np.nonzero(table_values == value)[0]
        return codes == hits[0] if hits.size else np.zeros(len(values), dtype=bool)


def pack_bits(binary: np.ndarray) -> np.ndarray:
    """Rows of 0/1 cells (n x cells) as rows of 64-bit words (n x ceil(cells / 64)), for XOR + popcount."""
    rows, cells = binary.shape
    words = max(1, -(-cells // 64))
    packed = np.zeros((rows, words * 8), dtype=np.uint8)
    bits = np.packbits(binary.astype(bool), axis=1, bitorder="little")
    packed[:, : bits.shape[1]] = bits
    return packed.view(np.uint64)


_BYTE_BITS = np.array([bin(value).count("1") for value in range(256)], dtype=np.uint8)


def _popcount_rows(words: np.ndarray) -> np.ndarray:
    """Set bits per row of an (n x w) uint64 array, as int32."""
    if hasattr(np, "bitwise_count"):  # numpy >= 2.0
        counts = np.bitwise_count(words)
    else:
        counts = _BYTE_BITS[words.view(np.uint8)].reshape(words.shape[0], -1)
    if counts.shape[1] == 1:
        return counts[:, 0].astype(np.int32)
    return counts.sum(axis=1, dtype=np.int32)


def _and(mask: np.ndarray | None, other: np.ndarray) -> np.ndarray:
    return other if mask is None else mask & other


def _dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), allow_nan=False)


def _facts(text: str) -> tuple[tuple[Any, ...], ...]:
    return tuple(tuple(fact) for fact in json.loads(text))


class EpisodicMemory:
    """One open memory file. Use :meth:`open`; close it (or use ``with``) when done."""

    def __init__(self, connection: sqlite3.Connection, path: Path, readonly: bool) -> None:
        self._connection = connection
        self.path = path
        self.readonly = readonly
        self._index: dict[tuple[int, int], _GridIndex] | None = None
        self._data_version: int | None = None

    # -- opening -------------------------------------------------------------------------------------------

    @classmethod
    def open(cls, path: str | os.PathLike[str], *, create: bool = True, readonly: bool = False) -> EpisodicMemory:
        """Open (and, unless ``readonly``, create and migrate) the memory file at ``path``.

        Raises :class:`MemoryStoreError` naming the path when the file is missing (``create=False`` or
        ``readonly``), is not a SQLite database, belongs to another program, has a newer schema, or its folder
        cannot be created or written. Nothing existing is ever deleted or overwritten.
        """
        path = Path(check_path_text(path, "memory file", UserInputError)).expanduser().absolute()
        if path.is_dir():
            raise MemoryFileError(path, "is a folder, not a memory file")
        if path.exists():
            _check_header(path)
        elif create and not readonly:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise MemoryFileError(path, f"cannot create the folder {path.parent}: {error.strerror}") from None
            if not os.access(path.parent, os.W_OK | os.X_OK):
                raise MemoryFileError(path, f"the folder {path.parent} is not writable")
        else:
            raise MemoryFileError(
                path, "no episodic memory here (record a demonstration first, or choose a file with --memory)"
            )
        try:
            if readonly:
                connection = sqlite3.connect(
                    f"{path.as_uri()}?mode=ro", uri=True, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000
                )
            else:
                connection = sqlite3.connect(str(path), isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
        except sqlite3.Error as error:
            raise sqlite_failure(path, error, "cannot open") from None
        try:
            connection.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
            connection.execute("PRAGMA foreign_keys = ON")
            version = read_version(connection, path)
            if readonly:
                if version != SCHEMA_VERSION:
                    raise MemoryFileError(
                        path, f"memory schema v{version} needs migrating to v{SCHEMA_VERSION}; open it writable once"
                    )
            else:
                mode = connection.execute("PRAGMA journal_mode = WAL").fetchone()[0]
                if mode.lower() != "wal":
                    raise MemoryStoreError(path, f"cannot switch the journal to WAL (got {mode})")
                connection.execute("PRAGMA synchronous = NORMAL")
                migrate(connection, path)
        except MemoryStoreError:
            connection.close()
            raise
        except sqlite3.Error as error:
            connection.close()
            raise sqlite_failure(path, error, "cannot open the memory") from None
        return cls(connection, path, readonly)

    def close(self) -> None:
        self._connection.close()

    def __enter__(self) -> EpisodicMemory:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        return int(self._query(lambda c: c.execute("PRAGMA user_version").fetchone()[0]))

    def _query(self, run: Callable[[sqlite3.Connection], _T]) -> _T:
        try:
            return run(self._connection)
        except sqlite3.Error as error:
            raise sqlite_failure(self.path, error, "memory query failed") from None

    # -- writing -------------------------------------------------------------------------------------------

    def write(self, trace: Trace) -> int:
        """Store a whole trace in one transaction and return its episode id."""
        if not isinstance(trace, Trace):
            raise TypeError(f"write() takes a Trace, got {type(trace).__name__}")
        if self.readonly:
            raise MemoryStoreError(self.path, "opened read-only; cannot write a trace")
        episode = trace.episode
        states: list[tuple[int, State]] = [(-1, trace.initial)] + [(s.index, s.state) for s in trace.steps]
        object_count = sum(len(state.objects) for _, state in states)
        grid_map_count = sum(len(state.grid_maps) for _, state in states)
        step_rows = []
        previous_parent: object = object()
        task_index = 0
        for step in trace.steps:
            parent = (step.parent_task, step.parent_node)
            task_index = task_index + 1 if parent == previous_parent else 0
            previous_parent = parent
            step_rows.append(
                (
                    step.index,
                    step.action,
                    _dumps(list(step.args)),
                    step.node_id,
                    step.parent_task,
                    _dumps([list(f) for f in step.state.facts]),
                    step.outcome,
                    step.failure_kind,
                    step.duration,
                    len(step.state.objects),
                    len(step.state.grid_maps),
                    task_index,
                    step.parent_node,
                )
            )
        object_rows = [
            (index, ord_, o.name, *o.pose, *o.ap, *o.an)
            for index, state in states
            for ord_, o in enumerate(state.objects)
        ]
        map_rows = [
            (
                index,
                ord_,
                g.object_name,
                g.occupancy.shape[0],
                g.occupancy.shape[1],
                g.occupancy.tobytes(),
                g.image,
                g.colour,
                g.shape,
                *g.centroid,
            )
            for index, state in states
            for ord_, g in enumerate(state.grid_maps)
        ]
        connection = self._connection
        try:
            connection.execute("BEGIN IMMEDIATE")
        except sqlite3.Error as error:
            raise sqlite_failure(self.path, error, "cannot write a trace") from None
        try:
            episode_id = connection.execute(
                "INSERT INTO episodes (task, task_file, problem, variant, seed, started, finished, outcome, config,"
                " initial_facts, step_count, object_count, grid_map_count, expectation_count, recorded)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    episode.task,
                    episode.task_file,
                    episode.problem,
                    episode.variant,
                    episode.seed,
                    episode.started,
                    episode.finished,
                    episode.outcome,
                    _dumps(episode.config),
                    _dumps([list(f) for f in trace.initial.facts]),
                    len(trace.steps),
                    object_count,
                    grid_map_count,
                    len(trace.expectations),
                    time.time(),
                ),
            ).lastrowid
            connection.executemany(
                "INSERT INTO steps (episode_id, step_index, action, args, node_id, parent_task, facts, outcome,"
                " failure_kind, duration, object_count, grid_map_count, task_index, parent_node)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                [(episode_id, *row) for row in step_rows],
            )
            connection.executemany(
                "INSERT INTO object_states (episode_id, step_index, ord, name, x, y, z, roll, pitch, yaw,"
                " ap_x, ap_y, ap_z, an_x, an_y, an_z) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                [(episode_id, *row) for row in object_rows],
            )
            map_ids: dict[tuple[int, int], int] = {}
            for row in map_rows:
                cursor = connection.execute(
                    "INSERT INTO grid_maps (episode_id, step_index, ord, object_name, rows, cols, occupancy,"
                    " image_png, colour, shape, cx, cy) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (episode_id, *row),
                )
                map_ids[(row[0], row[1])] = int(cursor.lastrowid or 0)
            connection.executemany(
                "INSERT INTO expectations (episode_id, ord, step_index, action, args_pattern, parent_task, facts,"
                " grid_map_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [
                    (
                        episode_id,
                        ord_,
                        x.step_index,
                        x.action,
                        _dumps(list(x.args_pattern)),
                        x.parent_task,
                        _dumps([list(f) for f in x.facts]),
                        None if x.grid_map_index is None else map_ids[(x.step_index, x.grid_map_index)],
                    )
                    for ord_, x in enumerate(trace.expectations)
                ],
            )
            connection.execute("COMMIT")
        except BaseException as error:
            if connection.in_transaction:
                connection.execute("ROLLBACK")
            if isinstance(error, sqlite3.Error):
                raise sqlite_failure(self.path, error, "writing a trace failed, nothing was stored") from None
            raise
        finally:
            self._index = None
        return int(episode_id or 0)

    # -- reading -------------------------------------------------------------------------------------------

    def episodes(
        self, *, task: str | None = None, outcome: str | None = None, limit: int | None = None
    ) -> list[EpisodeSummary]:
        """Episode headers, newest first, optionally of one root task and/or outcome."""
        where, params = _where(task=task, outcome=outcome)
        sql = f"SELECT {_EPISODE_COLUMNS} FROM episodes{where} ORDER BY started DESC, id DESC"
        if limit is not None:
            sql += " LIMIT ?"
            params.append(int(limit))
        rows = self._query(lambda c: c.execute(sql, params).fetchall())
        return [EpisodeSummary(_episode(row), row[10], row[11], row[12], row[13]) for row in rows]

    def has_episode(self, episode_id: int) -> bool:
        return self._query(
            lambda c: c.execute("SELECT 1 FROM episodes WHERE id = ?", (episode_id,)).fetchone() is not None
        )

    def episode(self, episode_id: int) -> Episode:
        row = self._query(
            lambda c: c.execute(f"SELECT {_EPISODE_COLUMNS} FROM episodes WHERE id = ?", (episode_id,)).fetchone()
        )
        if row is None:
            raise MemoryStoreError(self.path, f"no episode {episode_id}")
        return _episode(row)

    def trace(self, episode_id: int) -> Trace:
        """The whole stored trace of one episode, equal to the one written."""
        row = self._query(
            lambda c: c.execute(
                f"SELECT {_EPISODE_COLUMNS}, initial_facts FROM episodes WHERE id = ?", (episode_id,)
            ).fetchone()
        )
        if row is None:
            raise MemoryStoreError(self.path, f"no episode {episode_id}")
        episode = _episode(row)
        objects, maps = self._states(episode_id, None)
        step_rows = self._query(
            lambda c: c.execute(
                f"SELECT {_STEP_COLUMNS} FROM steps s WHERE episode_id = ? ORDER BY step_index", (episode_id,)
            ).fetchall()
        )
        steps = tuple(_step(r, objects, maps) for r in step_rows)
        initial = State(_facts(row[14]), tuple(objects.get(-1, ())), tuple(maps.get(-1, ())))
        expectation_rows = self._query(
            lambda c: c.execute(
                f"SELECT {_EXPECTATION_COLUMNS} FROM expectations x WHERE episode_id = ? ORDER BY ord",
                (episode_id,),
            ).fetchall()
        )
        map_positions = {g.id: (index, ord_) for index, gs in maps.items() for ord_, g in enumerate(gs)}
        expectations = tuple(_expectation(r, map_positions) for r in expectation_rows)
        return Trace(episode=episode, steps=steps, initial=initial, expectations=expectations)

    def traces(self) -> Iterator[Trace]:
        """Every stored trace, oldest first (for export)."""
        ids = self._query(lambda c: [r[0] for r in c.execute("SELECT id FROM episodes ORDER BY id")])
        for episode_id in ids:
            yield self.trace(episode_id)

    def last_traces(self, task: str, n: int, *, outcome: str | None = "success") -> list[Trace]:
        """The last ``n`` traces of a root task (section 7.4's T_past), newest first; ``outcome=None`` for all."""
        return [self.trace(s.episode.id or 0) for s in self.episodes(task=task, outcome=outcome, limit=n)]

    def grid_map(self, grid_map_id: int) -> GridMap:
        row = self._query(
            lambda c: c.execute(f"SELECT {_MAP_COLUMNS} FROM grid_maps WHERE id = ?", (grid_map_id,)).fetchone()
        )
        if row is None:
            raise MemoryStoreError(self.path, f"no grid-map {grid_map_id}")
        return _grid_map(row)

    # -- the paper's queries -------------------------------------------------------------------------------

    def expected_states(
        self, task: str, step_index: int, *, by: str = "episode", last: int | None = None, with_before: bool = False
    ) -> list[StepRecord]:
        """What held after step ``step_index`` of ``task`` in successful episodes, newest first.

        ``by="episode"``: ``task`` is an episode's root task and the index counts its steps. ``by="parent"``:
        ``task`` is a parent task and the index counts the steps of each run of it (``Step.task_index``), so a
        sub-task such as MagneticAttach has the same step i wherever it sits in a larger plan.
        """
        if by == "episode":
            condition = "e.task = ? AND s.step_index = ?"
        elif by == "parent":
            condition = "s.parent_task = ? AND s.task_index = ?"
        else:
            raise ValueError(f"by must be 'episode' or 'parent', not {by!r}")
        return self._step_records(
            f"{condition} AND e.outcome = 'success'", [task, int(step_index)], last, with_before=with_before
        )

    def successful_states(
        self, action: str, *, args: Sequence[Any] | None = None, last: int | None = None
    ) -> list[StepRecord]:
        """The states that led to success of ``action``: each successful step of it in a successful episode,
        with the state it started from (``before``) and the state it left (``step.state``), newest first.

        ``args`` filters by arguments; ``None`` or ``"?name"`` in it matches anything.
        """
        records = self._step_records(
            "s.action = ? AND s.outcome = 'success' AND e.outcome = 'success'", [action], None, with_before=True
        )
        if args is not None:
            pattern = Expectation(step_index=0, action=action, args_pattern=tuple(args))
            records = [r for r in records if pattern.matches(r.step.action, r.step.args)]
        return records[:last] if last is not None else records

    def plan_executions(self, task: str | None = None) -> list[PlanStep]:
        """P_a: every step of every successful episode (optionally of one root task), in plan order."""
        sql = (
            "SELECT episode_id, task, problem, variant, step_index, task_index, action, args, node_id, parent_task,"
            " facts, parent_node FROM p_a"
        )
        params: list[Any] = []
        if task is not None:
            sql += " WHERE task = ?"
            params.append(task)
        sql += " ORDER BY episode_id, step_index"
        rows = self._query(lambda c: c.execute(sql, params).fetchall())
        return [
            PlanStep(
                r[0], r[1], r[2], r[3], r[4], r[5], r[6], tuple(json.loads(r[7])), r[8], r[9], _facts(r[10]), r[11]
            )
            for r in rows
        ]

    def expectations(
        self, *, action: str | None = None, parent_task: str | None = None, task: str | None = None
    ) -> list[Expectation]:
        """E_db rows (with ``id``, ``episode_id`` and ``grid_map_id`` set), oldest first, optionally filtered."""
        clauses, params = [], []
        for column, value in (("x.action", action), ("x.parent_task", parent_task), ("e.task", task)):
            if value is not None:
                clauses.append(f"{column} = ?")
                params.append(value)
        where = f" WHERE {' AND '.join(clauses)}" if clauses else ""
        sql = (
            f"SELECT {_EXPECTATION_COLUMNS}, g.step_index, g.ord FROM expectations x"
            f" JOIN episodes e ON e.id = x.episode_id LEFT JOIN grid_maps g ON g.id = x.grid_map_id{where}"
            " ORDER BY x.id"
        )
        rows = self._query(lambda c: c.execute(sql, params).fetchall())
        return [_expectation(r[:9], {r[7]: (r[9], r[10])} if r[7] is not None else {}) for r in rows]

    def expectation_of(self, parent_task: str) -> list[Expectation]:
        """A task's expectations bubbled up (section 6.2): those of the last primitive under each run of it."""
        sql = (
            f"SELECT {_EXPECTATION_COLUMNS}, g.step_index, g.ord FROM expectations x"
            " JOIN steps s ON s.episode_id = x.episode_id AND s.step_index = x.step_index"
            " LEFT JOIN grid_maps g ON g.id = x.grid_map_id"
            " WHERE s.parent_task = ? AND NOT EXISTS (SELECT 1 FROM steps n WHERE n.episode_id = s.episode_id"
            " AND n.step_index = s.step_index + 1 AND n.parent_task IS s.parent_task"
            " AND n.parent_node IS s.parent_node) ORDER BY x.id"
        )
        rows = self._query(lambda c: c.execute(sql, (parent_task,)).fetchall())
        return [_expectation(r[:9], {r[7]: (r[9], r[10])} if r[7] is not None else {}) for r in rows]

    def nearest_grid_maps(
        self,
        query: GridMap | np.ndarray,
        k: int = 5,
        *,
        rotations: bool = True,
        action: str | None = None,
        parent_task: str | None = None,
        task: str | None = None,
        successful_only: bool = True,
        exclude_episode: int | None = None,
    ) -> list[GridMapMatch]:
        """The ``k`` stored expectation grid-maps nearest to ``query``, nearest first (ties: oldest first).

        Only maps of the query's shape are candidates. See the module docstring for the distance.
        """
        grid = query.occupancy if isinstance(query, GridMap) else np.asarray(query)
        if grid.ndim != 2:
            raise ValueError(f"a grid-map query must be 2-D, got shape {grid.shape}")
        index = self._grid_index().get((int(grid.shape[0]), int(grid.shape[1])))
        if index is None or k <= 0:
            return []
        binary = grid != 0
        turns = _turns(binary.shape, rotations)
        queries = pack_bits(np.stack([np.rot90(binary, t).reshape(-1) for t in turns]))
        # Hamming distance = popcount(stored XOR query) on bit-packed rows, minimised over the rotations. Integer
        # work on one thread: a BLAS product was as fast on an idle machine but 30x slower on a loaded one.
        best = _popcount_rows(index.packed ^ queries[0])
        for query_bits in queries[1:]:
            np.minimum(best, _popcount_rows(index.packed ^ query_bits), out=best)
        mask: np.ndarray | None = index.success if successful_only and not index.all_success else None
        if exclude_episode is not None:
            mask = _and(mask, index.episode_ids != exclude_episode)
        for column, value in (("actions", action), ("parent_tasks", parent_task), ("tasks", task)):
            if value is not None:
                mask = _and(mask, index.mask_equal(column, value))
        excluded = index.cells + 1
        if mask is not None:
            best = np.where(mask, best, excluded)
        if best.size > k:
            threshold = best[np.argpartition(best, k - 1)[k - 1]]
            candidates = np.nonzero(best <= threshold)[0]
        else:
            candidates = np.arange(best.size)
        candidates = candidates[best[candidates] < excluded]
        # Rows are in expectation-id order, so a stable sort on distance breaks ties oldest first.
        chosen = candidates[np.argsort(best[candidates], kind="stable")][:k]
        per_turn = np.stack([_popcount_rows(index.packed[chosen] ^ q) for q in queries])
        best_turn = per_turn.argmin(axis=0)
        return [
            GridMapMatch(
                expectation_id=int(index.expectation_ids[i]),
                grid_map_id=int(index.grid_map_ids[i]),
                episode_id=int(index.episode_ids[i]),
                task=index.tasks[i],
                step_index=int(index.step_indices[i]),
                action=index.actions[i],
                args_pattern=tuple(json.loads(index.args_patterns[i])),
                parent_task=index.parent_tasks[i],
                colour=index.colours[i],
                shape=index.shapes[i],
                distance=int(best[i]),
                rotation=int(turns[turn]),
            )
            for i, turn in zip(chosen, best_turn, strict=True)
        ]

    def _grid_index(self) -> dict[tuple[int, int], _GridIndex]:
        version = self._query(lambda c: c.execute("PRAGMA data_version").fetchone()[0])
        if self._index is None or version != self._data_version:
            rows = self._query(
                lambda c: c.execute(
                    "SELECT x.id, g.id, x.episode_id, e.task, x.step_index, x.action, x.args_pattern,"
                    " x.parent_task, g.rows * 65536 + g.cols, g.occupancy, g.colour, g.shape, e.outcome"
                    " FROM expectations x JOIN grid_maps g ON g.id = x.grid_map_id"
                    " JOIN episodes e ON e.id = x.episode_id ORDER BY x.id"
                ).fetchall()
            )
            by_shape: dict[tuple[int, int], list[tuple[Any, ...]]] = {}
            for row in rows:
                by_shape.setdefault((row[8] // 65536, row[8] % 65536), []).append(row)
            self._index = {shape: _GridIndex(group, shape) for shape, group in by_shape.items()}
            self._data_version = version
        return self._index

    # -- integrity -----------------------------------------------------------------------------------------

    def integrity_check(self) -> str:
        """SQLite's own verdict on the file: ``"ok"`` or the first problems it found."""
        rows = self._query(lambda c: c.execute("PRAGMA integrity_check").fetchall())
        return "\n".join(str(r[0]) for r in rows)

    def require_sound(self) -> None:
        """Raise :class:`MemoryFileError` unless SQLite's ``quick_check`` finds the file sound: writers call it
        before a run, so a trace is never recorded into a corrupted file that only some queries would notice."""
        verdict = self._query(lambda c: [str(r[0]) for r in c.execute("PRAGMA quick_check(5)").fetchall()])
        if verdict != ["ok"]:
            found = "; ".join(verdict).replace("\n", "; ")[:160]
            raise MemoryFileError(self.path, f"the memory file is corrupted ({found}); restore it from a backup or "
                                             "choose another file with --memory")

    def check(self) -> list[str]:
        """Every way a stored trace is incomplete (declared counts that its rows do not match); empty when sound."""
        checks = (
            (
                "SELECT e.id, e.step_count, (SELECT count(*) FROM steps s WHERE s.episode_id = e.id) FROM episodes e",
                "episode {} declares {} steps, has {}",
            ),
            (
                "SELECT e.id, e.object_count, (SELECT count(*) FROM object_states o WHERE o.episode_id = e.id)"
                " FROM episodes e",
                "episode {} declares {} object states, has {}",
            ),
            (
                "SELECT e.id, e.grid_map_count, (SELECT count(*) FROM grid_maps g WHERE g.episode_id = e.id)"
                " FROM episodes e",
                "episode {} declares {} grid-maps, has {}",
            ),
            (
                "SELECT e.id, e.expectation_count, (SELECT count(*) FROM expectations x WHERE x.episode_id = e.id)"
                " FROM episodes e",
                "episode {} declares {} expectations, has {}",
            ),
            (
                "SELECT s.episode_id || ' step ' || s.step_index, s.object_count, (SELECT count(*) FROM object_states"
                " o WHERE o.episode_id = s.episode_id AND o.step_index = s.step_index) FROM steps s",
                "episode {} declares {} object states, has {}",
            ),
            (
                "SELECT s.episode_id || ' step ' || s.step_index, s.grid_map_count, (SELECT count(*) FROM grid_maps g"
                " WHERE g.episode_id = s.episode_id AND g.step_index = s.step_index) FROM steps s",
                "episode {} declares {} grid-maps, has {}",
            ),
        )
        problems = []
        for sql, message in checks:
            for key, declared, found in self._query(lambda c, sql=sql: c.execute(sql).fetchall()):
                if declared != found:
                    problems.append(message.format(key, declared, found))
        return problems

    # -- helpers -------------------------------------------------------------------------------------------

    def _states(
        self, episode_id: int, step_indices: Sequence[int] | None
    ) -> tuple[dict[int, list[ObjectState]], dict[int, list[GridMap]]]:
        condition = "episode_id = ?"
        params: list[Any] = [episode_id]
        if step_indices is not None:
            condition += f" AND step_index IN ({', '.join('?' for _ in step_indices)})"
            params.extend(step_indices)
        objects: dict[int, list[ObjectState]] = {}
        for row in self._query(
            lambda c: c.execute(
                "SELECT step_index, name, x, y, z, roll, pitch, yaw, ap_x, ap_y, ap_z, an_x, an_y, an_z"
                f" FROM object_states WHERE {condition} ORDER BY step_index, ord",
                params,
            ).fetchall()
        ):
            objects.setdefault(row[0], []).append(ObjectState(row[1], row[2:8], row[8:11], row[11:14]))
        maps: dict[int, list[GridMap]] = {}
        for row in self._query(
            lambda c: c.execute(
                f"SELECT step_index, {_MAP_COLUMNS} FROM grid_maps WHERE {condition} ORDER BY step_index, ord",
                params,
            ).fetchall()
        ):
            maps.setdefault(row[0], []).append(_grid_map(row[1:]))
        return objects, maps

    def _step_records(
        self, condition: str, params: list[Any], last: int | None, *, with_before: bool
    ) -> list[StepRecord]:
        sql = (
            f"SELECT e.id, e.task, {_STEP_COLUMNS}, e.initial_facts"
            f" FROM steps s JOIN episodes e ON e.id = s.episode_id WHERE {condition}"
            " ORDER BY e.started DESC, e.id DESC, s.step_index"
        )
        if last is not None:
            sql += " LIMIT ?"
            params = [*params, int(last)]
        rows = self._query(lambda c: c.execute(sql, params).fetchall())
        records = []
        for row in rows:
            episode_id, task, step_row, initial_facts = row[0], row[1], row[2:-1], row[-1]
            index = step_row[0]
            wanted = [index - 1, index] if with_before else [index]
            objects, maps = self._states(episode_id, wanted)
            step = _step(step_row, objects, maps)
            before = None
            if with_before:
                if index == 0:
                    facts = _facts(initial_facts)
                else:
                    facts = self._query(
                        lambda c, e=episode_id, i=index: _facts(
                            c.execute(
                                "SELECT facts FROM steps WHERE episode_id = ? AND step_index = ?", (e, i - 1)
                            ).fetchone()[0]
                        )
                    )
                before = State(facts, tuple(objects.get(index - 1, ())), tuple(maps.get(index - 1, ())))
            records.append(StepRecord(episode_id, task, step, before))
        return records


_EPISODE_COLUMNS = (
    "id, task, task_file, problem, started, outcome, finished, variant, seed, config,"
    " step_count, object_count, grid_map_count, expectation_count"
)
_STEP_COLUMNS = (
    "s.step_index, s.action, s.args, s.node_id, s.parent_task, s.facts, s.outcome, s.failure_kind, s.duration,"
    " s.task_index, s.parent_node"
)
_MAP_COLUMNS = "id, rows, cols, occupancy, image_png, object_name, colour, shape, cx, cy"
_EXPECTATION_COLUMNS = (
    "x.id, x.episode_id, x.step_index, x.action, x.args_pattern, x.parent_task, x.facts, x.grid_map_id, x.ord"
)


def _where(**filters: Any) -> tuple[str, list[Any]]:
    clauses = [f"{name} = ?" for name, value in filters.items() if value is not None]
    params = [value for value in filters.values() if value is not None]
    return (f" WHERE {' AND '.join(clauses)}" if clauses else ""), params


def _episode(row: Sequence[Any]) -> Episode:
    return Episode(
        id=row[0],
        task=row[1],
        task_file=row[2],
        problem=row[3],
        started=row[4],
        outcome=row[5],
        finished=row[6],
        variant=row[7],
        seed=row[8],
        config=json.loads(row[9]),
    )


def _step(row: Sequence[Any], objects: dict[int, list[ObjectState]], maps: dict[int, list[GridMap]]) -> Step:
    index = row[0]
    return Step(
        index=index,
        action=row[1],
        args=json_tuple(json.loads(row[2]), "stored args"),
        node_id=row[3],
        parent_task=row[4],
        parent_node=row[10],
        state=State(_facts(row[5]), tuple(objects.get(index, ())), tuple(maps.get(index, ()))),
        outcome=row[6],
        failure_kind=row[7],
        duration=row[8],
        task_index=row[9],
    )


def _grid_map(row: Sequence[Any]) -> GridMap:
    occupancy = np.frombuffer(row[3], dtype=np.uint8).reshape(row[1], row[2]).copy()
    return GridMap(
        occupancy=occupancy,
        image=row[4],
        object_name=row[5],
        colour=row[6],
        shape=row[7],
        centroid=(row[8], row[9]),
        id=row[0],
    )


def _expectation(row: Sequence[Any], map_positions: dict[int | None, tuple[int, int]]) -> Expectation:
    grid_map_id = row[7]
    grid_map_index = map_positions[grid_map_id][1] if grid_map_id is not None else None
    return Expectation(
        step_index=row[2],
        action=row[3],
        args_pattern=tuple(json.loads(row[4])),
        parent_task=row[5],
        facts=_facts(row[6]),
        grid_map_index=grid_map_index,
        id=row[0],
        grid_map_id=grid_map_id,
        episode_id=row[1],
    )


def _check_header(path: Path) -> None:
    # Non-blocking, and a regular file only: a named pipe or a device given as --memory must not hang the command.
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as error:
        raise MemoryFileError(path, f"cannot read: {error.strerror}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise MemoryFileError(path, "is not a regular file, so not a memory file")
        header = os.read(fd, len(SQLITE_HEADER))
    except OSError as error:
        raise MemoryFileError(path, f"cannot read: {error.strerror}") from None
    finally:
        os.close(fd)
    if header and header != SQLITE_HEADER:
        raise MemoryFileError(path, "not a bt-meta memory: not a SQLite database; left untouched")
