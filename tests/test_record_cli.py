"""``bt-meta record`` and the memory options of ``bt-meta run``: demonstrations stored, inspected, used, refused."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main
from bt_meta.memory import EpisodicMemory
from bt_meta.resources import trees_dir

LETTERS = str(trees_dir() / "letters.yaml")
MAGNETIC = str(trees_dir() / "magnetic_attach.yaml")


def cli(capsys, *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope="module")
def recorded_a(tmp_path_factory):
    """Nominal A recorded with ``bt-meta record`` (the JSON answer and the memory file)."""
    path = tmp_path_factory.mktemp("record") / "memory.sqlite"
    code = main(["record", LETTERS, "--problem", "A", "--memory", str(path), "--json"])
    assert code == 0
    return path


def test_record_input_errors(capsys, tmp_path):
    code, _, err = cli(capsys, "record", LETTERS, "--problem", "Z", "--memory", str(tmp_path / "m.sqlite"))
    assert code == 2 and "Z" in err and "A" in err
    code, _, err = cli(capsys, "record", LETTERS, "--problem", "A", "--max-ticks", "0")
    assert code == 2 and "--max-ticks must be at least 1" in err
    assert not (tmp_path / "m.sqlite").exists()


def test_run_with_a_missing_explicit_memory_is_an_error(capsys, tmp_path):
    missing = tmp_path / "absent.sqlite"
    code, _, err = cli(capsys, "run", LETTERS, "--problem", "A", "--memory", str(missing))
    assert code == 2 and "absent.sqlite" in err and "no episodic memory here" in err
    assert not missing.exists()
    code, _, err = cli(capsys, "run", LETTERS, "--problem", "A", "--repair", "--max-attempts", "-1")
    assert code == 2 and "--max-attempts must be at least 0" in err


@pytest.mark.slow
def test_record_prints_the_episode_and_memory_ls_show_find_it(capsys, tmp_path):
    memory = tmp_path / "memory.sqlite"
    code, out, _ = cli(capsys, "record", LETTERS, "--problem", "A", "--memory", str(memory))
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "recorded episode 1: draw_A (problem A, variant nominal, seed 0), 6 steps, outcome success"
    assert "place(b5, 1.5, 1)" in lines[5] and "in draw_A_bar" in lines[5] and "grid-map b5 blue 1x2" in lines[5]
    assert lines[-1].startswith("6 expectations in E_db;")
    code, out, _ = cli(capsys, "memory", "ls", "--memory", str(memory))
    assert code == 0 and out.splitlines()[1].split()[:6] == ["1", "draw_A", "A", "nominal", "success", "6"]
    code, out, _ = cli(capsys, "memory", "show", "1", "--memory", str(memory), "--json")
    trace = json.loads(out)
    assert [s["parent_task"] for s in trace["steps"]][4] == "draw_A_bar"
    assert trace["steps"][4]["state"]["grid_maps"][0]["shape"] == "1x2"
    assert len(trace["expectations"]) == 6


@pytest.mark.slow
def test_record_json(recorded_a):
    with EpisodicMemory.open(recorded_a, readonly=True) as memory:
        (summary,) = memory.episodes()
        assert summary.episode.task == "draw_A" and summary.step_count == 6 and summary.grid_map_count == 6


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["A_two_1x1_same_colour", "A_two_1x1_different_colours"])
def test_run_with_the_recorded_memory_flags_the_substituted_bar(capsys, recorded_a, variant):
    code, out, _ = cli(capsys, "run", LETTERS, "--problem", "A", "--variant", variant, "--memory", str(recorded_a),
                       "--json")
    result = json.loads(out)
    assert code == 1 and result["status"] == "FAILURE"
    (failure,) = result["failures"]
    assert (failure["step"], failure["action"], failure["args"]) == (4, "place", ["b5", "1.5", "1"])
    assert "b5: 4 cells differ (expected blue 1x2, seen red 1x1)" in failure["message"]
    assert failure["evidence"]["mismatches"][0]["kind"] == "gridmap"


@pytest.mark.slow
def test_nominal_run_with_record_stores_a_second_episode(capsys, tmp_path, recorded_a):
    memory = tmp_path / "copy.sqlite"
    memory.write_bytes(recorded_a.read_bytes())
    code, out, _ = cli(capsys, "run", LETTERS, "--problem", "A", "--memory", str(memory), "--record", "--json")
    result = json.loads(out)
    assert code == 0 and result["failures"] == [] and result["episode_id"] == 2 and result["recording"] == "stored"
    with EpisodicMemory.open(memory, readonly=True) as opened:
        assert opened.episode(2).config["command"] == "bt-meta run" and opened.episode(2).outcome == "success"
        assert len(opened.expected_states("draw_A", 4)) == 2


@pytest.mark.slow
def test_a_failed_demonstration_is_refused(capsys, tmp_path):
    memory = tmp_path / "memory.sqlite"
    code, out, err = cli(capsys, "record", MAGNETIC, "--problem", "nominal", "--variant", "active_on_side",
                         "--memory", str(memory))
    assert code == 1 and out == ""
    assert "demonstration of nominal (active_on_side) failed, nothing stored: verification failure at step 12" in err
    with EpisodicMemory.open(memory, readonly=True) as opened:
        assert opened.episodes() == []


@pytest.mark.slow
def test_repair_run_reports_attempts_and_records_a_failed_run_when_asked(capsys, tmp_path, recorded_a):
    memory = tmp_path / "copy.sqlite"
    memory.write_bytes(recorded_a.read_bytes())
    code, out, _ = cli(capsys, "run", LETTERS, "--problem", "A", "--variant", "A_two_1x1_same_colour", "--memory",
                       str(memory), "--repair", "--max-attempts", "1", "--record-failed", "--json")
    result = json.loads(out)
    assert set(result) >= {"attempts", "repairs", "refinement_saved", "refinements_used", "stop_reason"}
    assert result["failures"][0]["step"] == 4 and result["failures"][0]["action"] == "place"
    assert len(result["attempts"]) <= 1 and result["repairs"] == [a["proposal"] for a in result["attempts"]]
    assert result["initial_plan"][4] == "place b5 1.5 1"
    with EpisodicMemory.open(memory, readonly=True) as opened:
        stored = opened.trace(result["episode_id"])
    if code == 0:  # a repair plugin fixed it: the trace is a success of the repaired plan
        assert stored.episode.outcome == "success" and result["status"] == "SUCCESS"
    else:
        assert stored.episode.outcome == "failure" and stored.steps[4].failure_kind == result["failures"][0]["kind"]
        assert result["stop_reason"]


@pytest.mark.slow
def test_demonstrate_runs_without_the_memory_expectations_unless_asked(tmp_path, recorded_a):
    import bt_meta_plugins.camera_perception as camera_plugin
    import bt_meta_plugins.gridmap_expectations as gridmap_plugin

    from bt_meta.commands.record import DemonstrationFailed, demonstrate
    from bt_meta.plugins import create_plugin_host

    memory_path = tmp_path / "copy.sqlite"
    memory_path.write_bytes(recorded_a.read_bytes())
    host = create_plugin_host(entry_points=False, plugins=[("camera_perception", camera_plugin),
                                                            ("gridmap_expectations", gridmap_plugin)])
    names = sorted(host.plugin_names())
    with EpisodicMemory.open(memory_path) as memory:
        # checked against nominal A, the bar drawn with a 1x1 is a mismatch: the demonstration is refused
        with pytest.raises(DemonstrationFailed, match="nothing stored: unknown_entity failure at step 4"):
            demonstrate(LETTERS, "A", memory, variant="A_two_1x1_same_colour", plugins=host,
                        check_expectations=True)
        assert sorted(host.plugin_names()) == names and len(memory.episodes()) == 1
        # a demonstration teaches: by default it is not judged by what the memory expects
        shown = demonstrate(LETTERS, "A", memory, variant="A_two_1x1_same_colour", plugins=host)
        assert sorted(host.plugin_names()) == names
        assert shown.episode_id == 2 and shown.trace.episode.variant == "A_two_1x1_same_colour"
        assert shown.trace.steps[4].state.grid_maps[0].shape == "1x1" and shown.recording_seconds > 0


def test_repair_progress_lines(capsys):
    from bt_meta.commands.run import _Progress

    progress = _Progress()
    progress.bt_meta_trace_event({"type": "step_end", "tick": 225, "step": 4, "node_id": "n8", "action": "place",
                                  "args": ["b5", "1.5", "1"], "status": "FAILURE"})
    progress.bt_meta_trace_event({"type": "failure", "tick": 225, "failure": {"kind": "unknown_entity",
                                                                              "message": "b5: 4 cells differ"}})
    progress.bt_meta_trace_event({"type": "repair", "tick": 225, "outcome": "applied",
                                  "attempt": {"change": "retry step 4",
                                              "proposal": {"action": "retry", "plugin": "retry_repair"}}})
    progress.bt_meta_trace_event({"type": "repair", "tick": 225, "outcome": "stopped", "reason": "budget spent"})
    progress.bt_meta_trace_event({"type": "tick", "tick": 226, "status": "RUNNING"})
    assert capsys.readouterr().out.splitlines() == [
        "tick  225  step 4 n8 place(b5, 1.5, 1) FAILURE",
        "           failure [unknown_entity] b5: 4 cells differ",
        "           repair applied: retry by retry_repair: retry step 4",
        "           repair stopped: budget spent",
    ]
