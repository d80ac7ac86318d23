"""``bt-meta memory ls | show | export``, ``--memory`` / ``BT_META_MEMORY`` / the default path, ``bench memory``."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from bt_meta.cli import main
from bt_meta.memory import ENV_VAR, EpisodicMemory, add_memory_argument, resolve_memory_path
from bt_meta.memory.trace import trace_from_dict


@pytest.fixture
def stored(tmp_path, make_trace):
    path = tmp_path / "project" / "mem.sqlite"
    with EpisodicMemory.open(path) as memory:
        ids = [
            memory.write(make_trace(1, started=1.7e9)),
            memory.write(make_trace(2, task="draw_H", started=1.7e9 + 60, outcome="failure")),
            memory.write(make_trace(3, started=1.7e9 + 120)),
        ]
    return path, ids


def test_ls_lists_newest_first_and_filters_by_task(stored, capsys):
    path, ids = stored
    assert main(["memory", "ls", "--memory", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:5] == ["ID", "TASK", "PROBLEM", "VARIANT", "OUTCOME"]
    assert [line.split()[0] for line in lines[1:]] == [str(ids[2]), str(ids[1]), str(ids[0])]
    assert "draw_H" in lines[2] and "failure" in lines[2]
    assert main(["memory", "ls", "--task", "draw_H", "--memory", str(path)]) == 0
    assert [line.split()[0] for line in capsys.readouterr().out.splitlines()[1:]] == [str(ids[1])]
    assert main(["memory", "ls", "--task", "draw_Q", "--memory", str(path)]) == 0
    assert capsys.readouterr().out.strip() == f"no episodes of task draw_Q in {path}"


def test_ls_json(stored, capsys):
    path, ids = stored
    assert main(["memory", "ls", "--json", "--memory", str(path)]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["memory"] == str(path) and document["schema_version"] >= 2
    first = document["episodes"][0]
    assert first["id"] == ids[2] and first["task"] == "draw_A" and first["steps"] == 4
    assert first["expectations"] == 4 and first["grid_maps"] == 4 and first["object_states"] == 10
    assert first["config"]["seed"] == 3


def test_show_text_and_json(stored, make_trace, capsys):
    path, ids = stored
    assert main(["memory", "show", str(ids[1]), "--memory", str(path)]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"episode {ids[1]}: task draw_H")
    assert "step 3: place(" in text and "failure (unknown_entity)" in text
    assert "grid-map b1 " in text and "crop" in text and "AP [" in text
    assert "expectation " in text and "for task place_block" in text
    assert main(["memory", "show", str(ids[0]), "--json", "--memory", str(path)]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["episode"]["id"] == ids[0]
    assert trace_from_dict(document) == make_trace(1, started=1.7e9)
    assert len(document["steps"][0]["state"]["grid_maps"][0]["occupancy"]) == 6


def test_show_unknown_id_is_bad_input(stored, capsys):
    path, _ = stored
    assert main(["memory", "show", "999", "--memory", str(path)]) == 2
    assert capsys.readouterr().err.strip() == f"{path}: no episode 999 in this memory (see `bt-meta memory ls`)"


def test_export_json_lines_json_document_and_file(stored, make_trace, capsys, tmp_path):
    path, _ = stored
    originals = [make_trace(1, started=1.7e9), make_trace(2, task="draw_H", started=1.7e9 + 60, outcome="failure")]
    originals.append(make_trace(3, started=1.7e9 + 120))
    assert main(["memory", "export", "--memory", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [trace_from_dict(json.loads(line)) for line in lines] == originals
    assert main(["memory", "export", "--json", "--memory", str(path)]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["format"] == "bt-meta-memory-export"
    assert [trace_from_dict(e) for e in document["episodes"]] == originals
    target = tmp_path / "out" / "export.json"
    target.parent.mkdir()
    assert main(["memory", "export", "--json", "-o", str(target), "--memory", str(path)]) == 0
    assert "exported 3 episodes" in capsys.readouterr().err
    assert json.loads(target.read_text())["episodes"][2]["episode"]["seed"] == 3
    assert sorted(p.name for p in target.parent.iterdir()) == ["export.json"]
    assert main(["memory", "export", "-o", str(tmp_path), "--memory", str(path)]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_env_var_and_flag_choose_the_memory(stored, monkeypatch, tmp_path, capsys):
    path, _ = stored
    monkeypatch.setenv(ENV_VAR, str(path))
    monkeypatch.chdir(tmp_path)
    assert main(["memory", "ls"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 4
    other = tmp_path / "other.sqlite"
    assert main(["memory", "ls", "--memory", str(other)]) == 2  # the flag wins, and that file does not exist
    err = capsys.readouterr().err
    assert err.startswith(f"{other}: no episodic memory here") and "Traceback" not in err
    assert not other.exists()


def test_default_memory_is_in_the_project_folder(monkeypatch, tmp_path, make_trace, capsys):
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.chdir(tmp_path)
    assert main(["memory", "ls"]) == 2
    assert f"{tmp_path / '.bt-meta' / 'memory.sqlite'}: no episodic memory here" in capsys.readouterr().err
    assert not (tmp_path / ".bt-meta").exists()
    with EpisodicMemory.open(resolve_memory_path()) as memory:
        memory.write(make_trace(7))
    assert (tmp_path / ".bt-meta" / "memory.sqlite").is_file()
    assert main(["memory", "ls", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"][0]["seed"] == 7


def test_resolve_memory_path_precedence(tmp_path):
    parser = argparse.ArgumentParser()
    add_memory_argument(parser)
    home = Path("~").expanduser()
    env = {ENV_VAR: "from-env.sqlite"}
    assert resolve_memory_path(parser.parse_args([]), environ={}, cwd=tmp_path) == tmp_path / ".bt-meta/memory.sqlite"
    assert resolve_memory_path(parser.parse_args([]), environ=env, cwd=tmp_path) == tmp_path / "from-env.sqlite"
    flag = parser.parse_args(["--memory", "/abs/flag.sqlite"])
    assert resolve_memory_path(flag, environ=env, cwd=tmp_path) == Path("/abs/flag.sqlite")
    assert resolve_memory_path(parser.parse_args(["--memory", "~/m.sqlite"]), environ={}) == home / "m.sqlite"
    assert resolve_memory_path(parser.parse_args([]), environ={ENV_VAR: ""}, cwd=tmp_path) == (
        tmp_path / ".bt-meta/memory.sqlite"
    )
    assert resolve_memory_path(None, environ=env, cwd=tmp_path) == tmp_path / "from-env.sqlite"


def test_corrupt_memory_is_one_line_without_traceback(tmp_path):
    path = tmp_path / "broken.sqlite"
    path.write_text("not a database at all\n")
    result = subprocess.run(
        [sys.executable, "-m", "bt_meta.cli", "memory", "ls", "--memory", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    assert result.stderr.strip() == f"{path}: not a bt-meta memory: not a SQLite database; left untouched"
    assert path.read_text() == "not a database at all\n"


def test_bench_memory_runs_small_and_reports_ratios(capsys):
    assert main(["bench", "memory", "--n", "300", "--queries", "5", "--baseline-queries", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["stored_grid_maps"] == 300 and result["query"]["count"] == 5
    assert result["baselines"]["top_k_agree"] is True
    assert result["baselines"]["python_loop"]["ratio"] > 0 and result["write"]["traces_per_s"] > 0
    assert main(["bench", "memory", "--n", "300", "--queries", "5", "--baseline-queries", "2"]) == 0
    text = capsys.readouterr().out
    assert "NN query (vectorised)" in text and "baseline python loop" in text and "trace writes" in text
    assert main(["bench", "memory", "--n", "3"]) == 2
    assert "--n must be >= 10" in capsys.readouterr().err


def test_check_reports_sound_and_incomplete_memories(stored, capsys):
    path, ids = stored
    assert main(["memory", "check", "--memory", str(path)]) == 0
    assert capsys.readouterr().out.strip() == f"{path}: integrity ok; 3 episodes; 0 incomplete traces"
    import sqlite3

    connection = sqlite3.connect(path)
    connection.execute("DELETE FROM object_states WHERE episode_id = ? AND step_index = 2", (ids[1],))
    connection.commit()
    connection.close()
    assert main(["memory", "check", "--json", "--memory", str(path)]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["ok"] is False and report["integrity"] == "ok"
    assert f"episode {ids[1]} step 2 declares 2 object states, has 0" in report["problems"]
