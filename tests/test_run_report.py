"""``bt-meta run --report FILE.html``: the demo's run page for a shipped task and for the tutorial's own task, and
an unwritable report path (exit 2, the run's result still printed and recorded)."""

from __future__ import annotations

import html
import re
import sys
from pathlib import Path

import pytest

from bt_meta.cli import main
from bt_meta.resources import trees_dir

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_tutorial import tutorial_steps  # the tutorial's own files, as the tutorial writes them


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["run", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def facts(page: str) -> dict[str, str]:
    """The report's fact table: header -> cell text (tags stripped)."""
    rows = re.findall(r"<tr><th>([^<]*)</th><td>(.*?)</td></tr>", page)
    return {k: html.unescape(" ".join(re.sub(r"<[^>]+>", " ", v).split())) for k, v in rows}


@pytest.mark.slow
def test_a_shipped_variant_that_is_not_repaired_gets_its_page(tmp_path, capsys):
    page = tmp_path / "run.html"
    code, out, _ = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal", "--variant",
                           "active_on_side", "--repair", "--memory", str(tmp_path / "m.sqlite"), "--report", str(page))
    assert code == 1 and f"report: {page}" in out
    page_text = page.read_text(encoding="utf-8")
    table = facts(page_text)
    assert table["variant"] == "active_on_side" and table["status"] == "failed"
    assert table["description"].endswith("variant active_on_side: The active part lies on its side (magnet facing "
                                         "-y); the nominal grasp and move misalign the magnets")
    assert table["failure kinds"] == "verification"
    assert table["task done (simulator)"].startswith("no")  # the goal checked on the true state, not bookkeeping
    assert "reference" in table["task done (simulator)"]
    assert "Not repaired: what was tried" in page_text and "retry_repair" in page_text
    assert page_text.count("data:image/png;base64,") == 2  # top views before and after
    assert "<svg" in page_text and "MoveTo" in page_text  # the tree as ticked


@pytest.mark.slow
def test_a_nominal_run_page_says_the_goal_holds(tmp_path, capsys):
    page = tmp_path / "nominal.html"
    code, _, _ = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal",
                         "--report", str(page))
    assert code == 0
    table = facts(page.read_text(encoding="utf-8"))
    assert table["status"] == "success" and table["task done (simulator)"].startswith("yes")
    assert table["repair attempts"] == "0" and "1 segment(s)" in table["time"]


def _tutorial_files(folder: Path) -> None:
    for kind, text in tutorial_steps():
        if kind == "file":
            name, body = text.split("\n", 1)
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            (folder / name).write_text(body, encoding="utf-8")


@pytest.mark.slow
def test_the_tutorials_repaired_run_gets_its_page(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("BT_META_MEMORY", raising=False)
    _tutorial_files(tmp_path)
    assert main(["record", "peg.yaml", "--memory", "memory.sqlite"]) == 0
    capsys.readouterr()
    code, out, err = run_cli(capsys, "peg.yaml", "--variant", "peg_on_side", "--repair", "--memory", "memory.sqlite",
                             "--report", "report.html")
    assert code == 0, out[-2000:] + err
    page_text = Path("report.html").read_text(encoding="utf-8")
    table = facts(page_text)
    assert table["status"] == "success" and table["task done (simulator)"].startswith("yes")
    assert int(table["repair attempts"]) >= 1 and "pose_backtracking" in page_text
    assert "unexpected_configuration" in table["failure kinds"]
    assert len(re.findall(r"segment \d+ \(from step \d+\)", page_text)) >= 2  # a tree per segment the executor ran
    # R_p / R_n of the task's pair (its first task's arguments) against the recorded demonstration's band
    assert "Keypoint relations over the executed steps" in page_text and "R_p mean of 1 trace(s)" in page_text


@pytest.mark.slow
def test_an_unwritable_report_path_is_exit_2_and_the_run_is_kept(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("BT_META_MEMORY", raising=False)
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the report's folder should be", encoding="utf-8")
    page = blocker / "run.html"
    memory = tmp_path / "m.sqlite"
    code, out, err = run_cli(capsys, str(trees_dir() / "magnetic_attach.yaml"), "--problem", "nominal", "--record",
                             "--memory", str(memory), "--report", str(page))
    assert code == 2
    assert str(page) in err and "cannot write the report" in err and "Traceback" not in err
    assert "SUCCESS after" in out and "recorded episode" in out  # the result was printed and stored first
    assert main(["memory", "ls", "--memory", str(memory)]) == 0
    assert "nominal" in capsys.readouterr().out


@pytest.mark.slow
def test_a_shipped_task_is_judged_through_its_family_files_success_mapping(tmp_path, capsys):
    """housing_insertion's goal has gripper_open(), which no check is named after: trees/families/housing.yaml
    maps it, as the campaigns and the demo judge it."""
    page = tmp_path / "housing.html"
    code, _, _ = run_cli(capsys, str(trees_dir() / "housing_insertion.yaml"), "--problem", "nominal",
                         "--report", str(page))
    assert code == 0
    verdict = facts(page.read_text(encoding="utf-8"))["task done (simulator)"]
    assert verdict.startswith("yes") and "in board's hole" in verdict and "holds nothing" in verdict


@pytest.mark.slow
def test_record_report_pages_a_stored_and_a_refused_demonstration(tmp_path, capsys):
    task, memory = str(trees_dir() / "housing_insertion.yaml"), str(tmp_path / "m.sqlite")
    stored, refused = tmp_path / "stored.html", tmp_path / "refused.html"
    assert main(["record", task, "--problem", "nominal", "--memory", memory, "--report", str(stored)]) == 0
    assert "recorded episode" in capsys.readouterr().out
    table = facts(stored.read_text(encoding="utf-8"))
    assert table["status"] == "success" and table["task done (simulator)"].startswith("yes")
    code = main(["record", task, "--problem", "nominal", "--variant", "housing_upside_down", "--memory", memory,
                 "--report", str(refused)])
    err = capsys.readouterr().err
    assert code == 1 and "nothing stored" in err and f"report: {refused}" in err
    table = facts(refused.read_text(encoding="utf-8"))
    assert table["status"] == "failed" and table["failure kinds"] == "unexpected_configuration"
    assert table["task done (simulator)"].startswith("no")


@pytest.mark.slow
def test_record_report_to_an_unwritable_path_keeps_the_stored_episode(tmp_path, capsys):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the report's folder should be", encoding="utf-8")
    memory = str(tmp_path / "m.sqlite")
    code = main(["record", str(trees_dir() / "housing_insertion.yaml"), "--problem", "nominal", "--memory", memory,
                 "--report", str(blocker / "page.html")])
    captured = capsys.readouterr()
    assert code == 2 and "cannot write the report" in captured.err and "recorded episode" in captured.out
    assert main(["memory", "ls", "--memory", memory]) == 0 and "nominal" in capsys.readouterr().out


def test_the_page_says_what_the_variant_is():
    """The scene's and the variant's ``description:`` (a generated variant's names its perturbations) head the page;
    the nominal run shows the scene's alone, and a scene without descriptions shows none."""
    from types import SimpleNamespace

    from bt_meta.runs.report import render_run_report, variant_description

    perturbed = SimpleNamespace(description="replace_shape (objects b4 b0, into b4)")
    scene = SimpleNamespace(description="letters_A perturbed (1 change(s))", variants={"perturbed": perturbed})
    world = SimpleNamespace(scene=scene, variant="perturbed")
    text = variant_description(world)
    assert text == "letters_A perturbed (1 change(s)); variant perturbed: replace_shape (objects b4 b0, into b4)"
    assert facts(render_run_report({"variant": "perturbed", "description": text, "report": {}}))["description"] == text
    assert variant_description(SimpleNamespace(scene=scene, variant="nominal")) == "letters_A perturbed (1 change(s))"
    bare = SimpleNamespace(description="", variants={"v": SimpleNamespace(description="b0 turned over")})
    assert variant_description(SimpleNamespace(scene=bare, variant="v")) == "variant v: b0 turned over"
    assert variant_description(SimpleNamespace(scene=SimpleNamespace(description="", variants={}), variant="x")) is None
    assert "description" not in facts(render_run_report({"variant": "x", "description": None, "report": {}}))
