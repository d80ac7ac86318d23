"""Schema versions: fresh files, forward migration of a hand-made v1 file, refusals that leave files untouched."""

from __future__ import annotations

import os
import sqlite3

import pytest

from bt_meta.memory import SCHEMA_VERSION, EpisodicMemory, MemoryStoreError
from bt_meta.memory import schema as schema_module
from bt_meta.memory.schema import APPLICATION_ID, MIGRATIONS, Migration


def _pragma(path, name):
    connection = sqlite3.connect(path)
    try:
        return connection.execute(f"PRAGMA {name}").fetchone()[0]
    finally:
        connection.close()


def _make_v1(path):
    """A v1 memory as bt-meta 0.1 would have left it: v1 tables only, one two-task episode, user_version 1."""
    connection = sqlite3.connect(path, isolation_level=None)
    MIGRATIONS[0].apply(connection)
    connection.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    connection.execute("PRAGMA user_version = 1")
    connection.execute(
        "INSERT INTO episodes (id, task, task_file, problem, variant, seed, started, finished, outcome, config,"
        " initial_facts, step_count, object_count, grid_map_count, expectation_count, recorded)"
        " VALUES (1, 'MagneticAttach', 'attach.yaml', 'nominal', NULL, 7, 100.0, 110.0, 'success', '{\"n\": 1}',"
        " '[[\"open\"]]', 4, 1, 0, 1, 111.0)"
    )
    for index, (action, parent) in enumerate(
        [("MoveTo", "approach"), ("Grasp", "approach"), ("MoveTo", "attach"), ("Grasp", "attach")]
    ):
        connection.execute(
            "INSERT INTO steps (episode_id, step_index, action, args, node_id, parent_task, facts, outcome,"
            " failure_kind, duration, object_count, grid_map_count) VALUES (1, ?, ?, '[1.5]', ?, ?, '[[\"held\"]]',"
            " 'success', NULL, 0.5, ?, 0)",
            (index, action, f"n{index}", parent, 1 if index == 3 else 0),
        )
    connection.execute(
        "INSERT INTO object_states (episode_id, step_index, ord, name, x, y, z, roll, pitch, yaw, ap_x, ap_y, ap_z,"
        " an_x, an_y, an_z) VALUES (1, 3, 0, 'housing', 0.5, 0.1, 0.2, 0, 0, 1.57, 0, 0, 0.03, 0, 0, 1)"
    )
    connection.execute(
        "INSERT INTO expectations (episode_id, ord, step_index, action, args_pattern, parent_task, facts,"
        " grid_map_id) VALUES (1, 0, 3, 'Grasp', '[]', 'attach', '[[\"attached\"]]', NULL)"
    )
    connection.close()


def test_fresh_file_has_the_current_version_and_our_application_id(tmp_path):
    path = tmp_path / "m.sqlite"
    with EpisodicMemory.open(path) as memory:
        assert memory.schema_version == SCHEMA_VERSION == MIGRATIONS[-1].version
    assert _pragma(path, "user_version") == SCHEMA_VERSION
    assert _pragma(path, "application_id") == APPLICATION_ID
    assert [m.version for m in MIGRATIONS] == list(range(1, SCHEMA_VERSION + 1))


def test_hand_made_v1_file_is_migrated_forward_on_open(tmp_path):
    path = tmp_path / "v1.sqlite"
    _make_v1(path)
    assert _pragma(path, "user_version") == 1
    with EpisodicMemory.open(path) as memory:
        assert memory.schema_version == SCHEMA_VERSION
        trace = memory.trace(1)
        assert trace.episode.task == "MagneticAttach" and trace.episode.config == {"n": 1}
        assert [s.action for s in trace.steps] == ["MoveTo", "Grasp", "MoveTo", "Grasp"]
        assert trace.steps[3].state.object("housing").pose[5] == pytest.approx(1.57)
        # v2 backfilled task_index and added the P_a / E_db views.
        assert [s.task_index for s in trace.steps] == [0, 1, 0, 1]
        assert [p.task_index for p in memory.plan_executions("MagneticAttach")] == [0, 1, 0, 1]
        assert [r.step.index for r in memory.expected_states("attach", 1, by="parent")] == [3]
        assert [x.action for x in memory.expectation_of("attach")] == ["Grasp"]
        assert memory.check() == []
    assert _pragma(path, "user_version") == SCHEMA_VERSION


def test_a_failing_migration_leaves_the_file_at_its_old_version(tmp_path, monkeypatch):
    path = tmp_path / "v1.sqlite"
    _make_v1(path)

    def half_then_fail(connection):
        connection.execute("ALTER TABLE steps ADD COLUMN task_index INTEGER")
        raise sqlite3.OperationalError("simulated failure in the middle of a migration")

    monkeypatch.setattr(schema_module, "MIGRATIONS", (MIGRATIONS[0], Migration(2, "boom", half_then_fail)))
    with pytest.raises(MemoryStoreError, match="migrating the memory schema from v1 failed: simulated"):
        EpisodicMemory.open(path)
    assert _pragma(path, "user_version") == 1
    connection = sqlite3.connect(path)
    columns = [row[1] for row in connection.execute("PRAGMA table_info(steps)")]
    connection.close()
    assert "task_index" not in columns


def test_newer_schema_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "future.sqlite"
    with EpisodicMemory.open(path):
        pass
    connection = sqlite3.connect(path)
    connection.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 5}")
    connection.close()
    before = path.read_bytes()
    with pytest.raises(MemoryStoreError) as raised:
        EpisodicMemory.open(path)
    message = str(raised.value)
    assert message.startswith(f"{path}: ")
    assert f"memory schema version {SCHEMA_VERSION + 5} is newer than this bt-meta understands" in message
    assert path.read_bytes() == before


def test_non_sqlite_file_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "notes.sqlite"
    path.write_bytes(b"these are my notes, not a database\n" * 20)
    before = path.read_bytes()
    with pytest.raises(MemoryStoreError, match="not a bt-meta memory: not a SQLite database") as raised:
        EpisodicMemory.open(path)
    assert str(path) in str(raised.value)
    assert path.read_bytes() == before
    assert not (tmp_path / "notes.sqlite-wal").exists()


def test_corrupt_sqlite_file_is_refused(tmp_path):
    path = tmp_path / "corrupt.sqlite"
    path.write_bytes(b"SQLite format 3\x00" + os.urandom(4000))
    before = path.read_bytes()
    with pytest.raises(MemoryStoreError, match="not a bt-meta memory: not a readable SQLite database") as raised:
        EpisodicMemory.open(path)
    assert str(path) in str(raised.value)
    assert path.read_bytes() == before


def test_another_programs_database_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "other.sqlite"
    connection = sqlite3.connect(path)
    connection.execute("CREATE TABLE invoices (id INTEGER PRIMARY KEY, amount REAL)")
    connection.execute("INSERT INTO invoices (amount) VALUES (12.5)")
    connection.commit()
    connection.close()
    before = path.read_bytes()
    with pytest.raises(MemoryStoreError, match="a SQLite database of another program; left untouched"):
        EpisodicMemory.open(path)
    assert path.read_bytes() == before
    connection = sqlite3.connect(path)
    connection.execute("PRAGMA application_id = 1234")
    connection.close()
    with pytest.raises(MemoryStoreError, match="application id 0x4d2 belongs to another program"):
        EpisodicMemory.open(path)


def test_empty_file_becomes_a_memory(tmp_path):
    path = tmp_path / "empty.sqlite"
    path.touch()
    with EpisodicMemory.open(path) as memory:
        assert memory.schema_version == SCHEMA_VERSION


def test_folder_that_cannot_be_created(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    path = blocker / "sub" / "memory.sqlite"
    with pytest.raises(MemoryStoreError, match="cannot create the folder") as raised:
        EpisodicMemory.open(path)
    assert str(raised.value).startswith(f"{path}: ")


def test_path_that_is_a_folder(tmp_path):
    with pytest.raises(MemoryStoreError, match="is a folder, not a memory file"):
        EpisodicMemory.open(tmp_path)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root ignores permission bits")
def test_unwritable_folder(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(MemoryStoreError, match="is not writable"):
            EpisodicMemory.open(folder / "memory.sqlite")
    finally:
        folder.chmod(0o700)


def test_unwritable_system_folder(tmp_path):
    # Works as root too: /proc refuses new entries whatever the permissions.
    path = "/proc/bt-meta-test/memory.sqlite"
    with pytest.raises(MemoryStoreError) as raised:
        EpisodicMemory.open(path)
    assert str(raised.value).startswith(f"{path}: ")
    assert "cannot create the folder" in str(raised.value) or "not writable" in str(raised.value)
