"""The versioned SQLite schema of the episodic memory and its forward migrations.

Offers:

* :data:`APPLICATION_ID` -- the ``PRAGMA application_id`` that marks a file as a bt-meta memory
* :data:`MIGRATIONS` -- the ordered list of :class:`Migration` steps; version N is reached by applying 1..N
* :data:`SCHEMA_VERSION` -- the version this bt-meta writes (the last migration's)
* :func:`migrate` -- bring an open connection's schema up to :data:`SCHEMA_VERSION`, in one transaction
* :class:`MemoryStoreError` -- a memory file that cannot be used (corrupt, not ours, too new, unwritable)

The version lives in ``PRAGMA user_version``. A file written by a newer bt-meta is refused, never downgraded; a
file that is a SQLite database but not a bt-meta memory (foreign application id, or tables and no id) is refused,
never written to. Migrations only ever add: user data is never dropped or rewritten in place.

Tables (v4; ``refinements`` since v3, its robot, refined plan, status and replay counts since v4):

* ``episodes`` -- one row per trace, with the declared ``step_count``, ``object_count``, ``grid_map_count`` and
  ``expectation_count`` so a reader can prove the trace is complete
* ``steps`` -- one row per executed primitive; ``facts`` is the symbolic state after it (JSON list of atoms);
  each step declares its own ``object_count`` and ``grid_map_count``
* ``object_states`` and ``grid_maps`` -- keyed by ``(episode_id, step_index, ord)``; ``step_index`` -1 is the
  initial state
* ``expectations`` -- E_db rows, pointing at a grid-map row when they have one
* views ``p_a`` (steps of successful episodes: the annotated plan executions) and ``e_db`` (expectations with
  their grid-map and episode)
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from bt_meta.errors import BtMetaError, UserInputError

#: "BTMM" -- marks a SQLite file as a bt-meta memory.
APPLICATION_ID = 0x42544D4D


class MemoryStoreError(BtMetaError):
    """A memory file that cannot be opened or written; the message names the path and what to do."""

    def __init__(self, path: str | Path, message: str) -> None:
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")


class MemoryFileError(MemoryStoreError, UserInputError):
    """The memory file the user chose is not usable as it is: not SQLite, another program's, of a newer schema,
    corrupted, locked by another process, read-only, or in a folder that does not exist. Bad input: exit 2."""

    def __init__(self, path: str | Path, message: str) -> None:
        UserInputError.__init__(self, message, str(path))


_CORRUPT = ("malformed", "not a database", "file is encrypted", "disk image", "database corrupt")


def sqlite_failure(path: str | Path, error: sqlite3.Error, doing: str) -> MemoryStoreError:
    """The error to raise for ``error`` met while ``doing``: a :class:`MemoryFileError` when the file itself is the
    problem (corrupted, locked, read-only, unopenable), else a :class:`MemoryStoreError` with SQLite's words."""
    text = str(error)
    lowered = text.lower()
    if "locked" in lowered or "busy" in lowered:
        return MemoryFileError(path, f"{doing}: the database is locked by another process; try again when it is done")
    if "readonly" in lowered or "read-only" in lowered:
        return MemoryFileError(path, f"{doing}: the memory file is read-only")
    if any(word in lowered for word in _CORRUPT):
        return MemoryFileError(path, f"{doing}: the memory file is corrupted ({text}); restore it from a backup or "
                                     "choose another file with --memory")
    if "unable to open" in lowered:
        return MemoryFileError(path, f"{doing}: {text}")
    return MemoryStoreError(path, f"{doing}: {text}")


@dataclass(frozen=True)
class Migration:
    """One forward step of the schema: ``apply`` runs inside the migration transaction."""

    version: int
    description: str
    apply: Callable[[sqlite3.Connection], None]


def _run(connection: sqlite3.Connection, statements: tuple[str, ...]) -> None:
    # One statement at a time: executescript() would commit the surrounding transaction.
    for statement in statements:
        connection.execute(statement)


_V1 = (
    """CREATE TABLE episodes (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        task TEXT NOT NULL,
        task_file TEXT NOT NULL,
        problem TEXT NOT NULL,
        variant TEXT,
        seed INTEGER,
        started REAL NOT NULL,
        finished REAL,
        outcome TEXT NOT NULL CHECK (outcome IN ('success', 'failure', 'aborted')),
        config TEXT NOT NULL,
        initial_facts TEXT NOT NULL,
        step_count INTEGER NOT NULL,
        object_count INTEGER NOT NULL,
        grid_map_count INTEGER NOT NULL,
        expectation_count INTEGER NOT NULL,
        recorded REAL NOT NULL
    )""",
    """CREATE TABLE steps (
        id INTEGER PRIMARY KEY,
        episode_id INTEGER NOT NULL REFERENCES episodes(id) ON DELETE CASCADE,
        step_index INTEGER NOT NULL,
        action TEXT NOT NULL,
        args TEXT NOT NULL,
        node_id TEXT,
        parent_task TEXT,
        parent_node TEXT,
        facts TEXT NOT NULL,
        outcome TEXT NOT NULL CHECK (outcome IN ('success', 'failure', 'aborted')),
        failure_kind TEXT,
        duration REAL,
        object_count INTEGER NOT NULL,
        grid_map_count INTEGER NOT NULL,
        UNIQUE (episode_id, step_index)
    )""",
    """CREATE TABLE object_states (
        id INTEGER PRIMARY KEY,
        episode_id INTEGER NOT NULL REFERENCES episodes(id) ON DELETE CASCADE,
        step_index INTEGER NOT NULL,
        ord INTEGER NOT NULL,
        name TEXT NOT NULL,
        x REAL NOT NULL, y REAL NOT NULL, z REAL NOT NULL,
        roll REAL NOT NULL, pitch REAL NOT NULL, yaw REAL NOT NULL,
        ap_x REAL NOT NULL, ap_y REAL NOT NULL, ap_z REAL NOT NULL,
        an_x REAL NOT NULL, an_y REAL NOT NULL, an_z REAL NOT NULL,
        UNIQUE (episode_id, step_index, ord)
    )""",
    """CREATE TABLE grid_maps (
        id INTEGER PRIMARY KEY,
        episode_id INTEGER NOT NULL REFERENCES episodes(id) ON DELETE CASCADE,
        step_index INTEGER NOT NULL,
        ord INTEGER NOT NULL,
        object_name TEXT,
        rows INTEGER NOT NULL,
        cols INTEGER NOT NULL,
        occupancy BLOB NOT NULL,
        image_png BLOB,
        colour TEXT,
        shape TEXT,
        cx REAL NOT NULL,
        cy REAL NOT NULL,
        UNIQUE (episode_id, step_index, ord)
    )""",
    """CREATE TABLE expectations (
        id INTEGER PRIMARY KEY,
        episode_id INTEGER NOT NULL REFERENCES episodes(id) ON DELETE CASCADE,
        ord INTEGER NOT NULL,
        step_index INTEGER NOT NULL,
        action TEXT NOT NULL,
        args_pattern TEXT NOT NULL,
        parent_task TEXT,
        facts TEXT NOT NULL,
        grid_map_id INTEGER REFERENCES grid_maps(id),
        UNIQUE (episode_id, ord)
    )""",
    "CREATE INDEX episodes_task ON episodes (task, id)",
    "CREATE INDEX steps_action ON steps (action)",
    "CREATE INDEX expectations_action ON expectations (action)",
)


def _v1(connection: sqlite3.Connection) -> None:
    _run(connection, _V1)


def _v2(connection: sqlite3.Connection) -> None:
    """Task-relative step positions (section 7.4's "task-step i") and the paper's P_a and E_db views."""
    connection.execute("ALTER TABLE steps ADD COLUMN task_index INTEGER")
    rows = connection.execute(
        "SELECT id, episode_id, parent_task, parent_node FROM steps ORDER BY episode_id, step_index"
    )
    updates = []
    previous: tuple[int, str | None, str | None] | None = None
    position = 0
    for step_id, episode_id, parent_task, parent_node in rows.fetchall():
        key = (episode_id, parent_task, parent_node)
        position = position + 1 if key == previous else 0
        previous = key
        updates.append((position, step_id))
    connection.executemany("UPDATE steps SET task_index = ? WHERE id = ?", updates)
    _run(
        connection,
        (
            "CREATE INDEX steps_parent_task ON steps (parent_task, task_index)",
            """CREATE VIEW p_a AS
               SELECT e.id AS episode_id, e.task, e.problem, e.variant, s.step_index, s.task_index, s.action,
                      s.args, s.node_id, s.parent_task, s.parent_node, s.facts, s.outcome
               FROM steps s JOIN episodes e ON e.id = s.episode_id
               WHERE e.outcome = 'success'""",
            """CREATE VIEW e_db AS
               SELECT x.id AS expectation_id, x.episode_id, e.task, x.step_index, x.action, x.args_pattern,
                      x.parent_task, x.facts, x.grid_map_id, g.rows, g.cols, g.occupancy, g.colour, g.shape,
                      g.cx, g.cy, e.outcome AS episode_outcome
               FROM expectations x JOIN episodes e ON e.id = x.episode_id
               LEFT JOIN grid_maps g ON g.id = x.grid_map_id""",
        ),
    )


def _v3(connection: sqlite3.Connection) -> None:
    """Learned method refinements (bt_meta.meta.refinements): a repaired plan saved as a method of its task."""
    _run(
        connection,
        (
            """CREATE TABLE refinements (
                 id INTEGER PRIMARY KEY,
                 created TEXT NOT NULL,
                 domain TEXT NOT NULL,
                 domain_path TEXT,
                 task TEXT NOT NULL,
                 method TEXT NOT NULL UNIQUE,
                 precondition TEXT NOT NULL,
                 subtasks TEXT NOT NULL,
                 poses TEXT NOT NULL,
                 tolerance TEXT NOT NULL,
                 problem TEXT,
                 variant TEXT,
                 repair TEXT NOT NULL
               )""",
            "CREATE INDEX refinements_task ON refinements (domain, task, id)",
        ),
    )


def _v4(connection: sqlite3.Connection) -> None:
    """Refinements record the robot that learned them, the plan they refined, and how their replays went (a
    refinement that fails on replay is demoted); rows of v3 keep everything, with no robot and status active."""
    _run(
        connection,
        (
            "ALTER TABLE refinements ADD COLUMN robot TEXT",
            "ALTER TABLE refinements ADD COLUMN refines TEXT",
            "ALTER TABLE refinements ADD COLUMN status TEXT NOT NULL DEFAULT 'active'",
            "ALTER TABLE refinements ADD COLUMN status_reason TEXT",
            "ALTER TABLE refinements ADD COLUMN replays INTEGER NOT NULL DEFAULT 0",
            "ALTER TABLE refinements ADD COLUMN failures INTEGER NOT NULL DEFAULT 0",
        ),
    )


MIGRATIONS: tuple[Migration, ...] = (
    Migration(1, "episodes, steps, object states, grid-maps, expectations", _v1),
    Migration(2, "steps.task_index (backfilled), views p_a and e_db", _v2),
    Migration(3, "refinements: learned method refinements", _v3),
    Migration(4, "refinements: robot, the plan refined, status and replay counts", _v4),
)

SCHEMA_VERSION = MIGRATIONS[-1].version


def read_version(connection: sqlite3.Connection, path: str | Path) -> int:
    """The file's schema version, after checking that it is (or may become) a bt-meta memory."""
    try:
        version = connection.execute("PRAGMA user_version").fetchone()[0]
        application_id = connection.execute("PRAGMA application_id").fetchone()[0]
        tables = connection.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
    except sqlite3.DatabaseError as error:
        lowered = str(error).lower()
        if any(word in lowered for word in ("locked", "busy", "readonly", "malformed", "disk image")):
            raise sqlite_failure(path, error, "cannot open the memory") from None
        raise MemoryFileError(path, f"not a bt-meta memory: not a readable SQLite database ({error})") from None
    if application_id not in (0, APPLICATION_ID):
        raise MemoryFileError(
            path, f"not a bt-meta memory: SQLite application id {application_id:#x} belongs to another program"
        )
    if application_id == 0 and (version != 0 or tables):
        raise MemoryFileError(path, "not a bt-meta memory: a SQLite database of another program; left untouched")
    if version > SCHEMA_VERSION:
        raise MemoryFileError(
            path,
            f"memory schema version {version} is newer than this bt-meta understands ({SCHEMA_VERSION}); "
            "upgrade bt-meta or choose another file with --memory",
        )
    return int(version)


def migrate(connection: sqlite3.Connection, path: str | Path) -> int:
    """Apply every missing migration in one IMMEDIATE transaction; returns the version found before."""
    found = read_version(connection, path)
    if found == SCHEMA_VERSION:
        return found
    try:
        connection.execute("BEGIN IMMEDIATE")
    except sqlite3.OperationalError as error:
        raise sqlite_failure(path, error, f"cannot migrate the memory schema from v{found}") from None
    try:
        # Another process may have migrated between our read and our lock.
        current = read_version(connection, path)
        for migration in MIGRATIONS:
            if migration.version > current:
                migration.apply(connection)
        connection.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        connection.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        connection.execute("COMMIT")
    except BaseException as error:
        connection.execute("ROLLBACK")
        if isinstance(error, sqlite3.Error):
            raise sqlite_failure(path, error, f"migrating the memory schema from v{found} failed") from None
        raise
    return found
