"""``bt-meta compile``, ``bt-meta tick``, ``bt-meta plugins`` and ``bt-meta bench tick`` end to end."""

from __future__ import annotations

import json

import pytest

from bt_meta.cli import main
from bt_meta.testing import clear_blackboard

TASKS = """
domain:
  name: lamp
  predicates:
    off: []
    on: []
  primitives:
    switch_on:
      parameters: []
      precondition: off()
      add: [on()]
      delete: [off()]
    switch_off:
      parameters: []
      precondition: on()
      add: [off()]
      delete: [on()]
  tasks:
    blink: []
  methods:
    - name: blink_once
      task: blink()
      precondition: off()
      subtasks: [switch_on(), switch_off()]
problems:
  dark:
    init: [off()]
    tasks: [blink()]
  lit:
    init: [on()]
    tasks: [blink()]
"""


@pytest.fixture
def project(tmp_path):
    (tmp_path / "lamp.yaml").write_text(TASKS)
    yield tmp_path
    clear_blackboard()


def test_compile_writes_xml_that_tick_runs(project, capsys):
    out = project / "lamp.xml"
    assert main(["compile", str(project / "lamp.yaml"), "--problem", "dark", "-o", str(out)]) == 0
    text = out.read_text()
    assert 'main_tree_to_execute="Plan_dark"' in text and '<switch_on name="n1 switch_on()"' in text
    assert '<Action ID="switch_on"' in text and "CheckCondition" in text
    capsys.readouterr()
    assert main(["tick", str(out), "--problem", "dark", "--ticks-per-skill", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("tick   1  RUNNING") and "n1 switch_on()=RUNNING" in lines[0]
    assert lines[-1].startswith("SUCCESS after 3 ticks, 0 failures")


def test_compile_policy_to_stdout(project, capsys):
    assert main(["compile", str(project / "lamp.yaml"), "--problem", "dark", "--policy"]) == 0
    out = capsys.readouterr().out
    assert 'main_tree_to_execute="Policy_dark"' in out and "<Fallback" in out


def test_tick_json_with_a_silent_fault_reports_the_mismatch(project, capsys):
    code = main(["tick", str(project / "lamp.yaml"), "--problem", "dark", "--fault", "switch_on=silent", "--json"])
    assert code == 1
    report = json.loads(capsys.readouterr().out)
    assert report["status"] == "FAILURE" and report["mode"] == "plan"
    [failure] = report["failures"]
    assert failure["kind"] == "unexpected_configuration" and failure["node_id"] == "n1" and failure["step"] == 0
    assert report["ticks"][0]["nodes"]["n1 switch_on()"] == "FAILURE"
    assert ["off"] in report["state"]


def test_tick_keep_ticking_reports_precondition_failures(project, capsys):
    code = main(["tick", str(project / "lamp.yaml"), "--problem", "dark", "--ticks", "3", "--keep-ticking"])
    out = capsys.readouterr().out
    assert code == 0  # the first run succeeded; later ticks re-run the plan from a changed world
    assert out.count("tick ") == 3


def test_no_plan_exits_1(project, capsys):
    assert main(["tick", str(project / "lamp.yaml"), "--problem", "lit"]) == 1
    assert "no plan for problem 'lit'" in capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), [
    (["tick", "{p}/missing.yaml"], "missing.yaml: no such file"),
    (["tick", "{p}/lamp.yaml", "--problem", "dark", "--fault", "switch_on=melt"], "unknown fault mode 'melt'"),
    (["tick", "{p}/lamp.yaml", "--problem", "nope"], "no problem named 'nope'"),
    (["tick", "{p}/lamp.yaml", "--problem", "dark", "--ticks", "0"], "--ticks must be at least 1"),
    (["compile", "{p}/lamp.yaml", "--policy", "--depth", "0"], "--depth must be at least 1"),
    (["plugins", "--plugins", "{p}/broken"],
     "broken/bad.py:2:5: plugin file failed to import: SyntaxError: '(' was never closed"),
])
def test_bad_input_exits_2_with_one_line(project, capsys, argv, message):
    (project / "broken").mkdir()
    (project / "broken" / "bad.py").write_text("x = 1\ny = (\n")
    assert main([arg.format(p=project) for arg in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_plugins_lists_hooks_and_project_folder(project, capsys):
    (project / "plugins").mkdir()
    (project / "plugins" / "tracer.py").write_text(
        "from bt_meta.plugins import hookimpl\n\n@hookimpl\ndef bt_meta_trace_event(event):\n    pass\n")
    assert main(["plugins", "--project", str(project / "lamp.yaml"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    names = [p["name"] for p in report["plugins"]]
    assert {"reporting", "symbolic_expectations", "ground_truth_perception", "tracer"} <= set(names)
    assert report["hooks"]["bt_meta_trace_event"] == ["tracer"]
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "symbolic_expectations  [entry point bt_meta_plugins.symbolic_expectations]" in out


def test_bench_tick_small_run_prints_ratio(capsys):
    assert main(["bench", "tick", "--leaves", "40", "--group", "10", "--rounds", "2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report["results"]) == {"plain", "monitored", "monitored-generic", "monitored+checks"}
    assert report["results"]["plain"]["ratio_vs_plain"] == 1.0
    assert report["monitor_overhead_percent"] == pytest.approx(
        (report["results"]["monitored"]["ratio_vs_plain"] - 1) * 100, abs=0.06)
