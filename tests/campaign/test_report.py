"""The campaign report links every episode that missed its expected outcome to an HTML run report of its own."""

from __future__ import annotations

import json

from bt_meta.campaign import CAMPAIGN_VERSION
from bt_meta.campaign.database import CampaignDatabase
from bt_meta.campaign.manifest import manifest_digest, write_manifest
from bt_meta.campaign.report import build_report

_REPORT = {
    "status": "failed", "stop_reason": "no applicable repair", "seconds": 3.2, "ticks": 400, "segments": 2,
    "simulated_seconds": 4.0, "achieved": False, "truth": "b2 is not at (0, 2)",
    "failures": [{"kind": "unexpected_configuration", "step": 2, "action": "place", "args": ["b2", "0", "2"],
                  "message": "grid-maps after place(b2, 0, 2): b2: 4 cells differ",
                  "evidence": {"classified_by": "classification_rules", "plan": ["not shown"]}}],
    "attempts": [{"number": 1, "kind": "unexpected_configuration", "failure": {"step": 2, "action": "place",
                  "args": ["b2", "0", "2"]}, "proposal": {"action": "retry", "score": 0.3, "plugin": "retry_repair",
                  "description": "retry step 2 as it is"}, "change": "retry step 2", "outcome": "failed_again"}],
    "reported": [{"kind": "precondition", "step": 2, "action": "place", "args": ["b2", "0", "2"],
                  "message": "precondition available(?b) does not hold",
                  "tried": [{"attempt": None, "action": "replan", "plugin": "retry_repair",
                             "description": "replan from n4", "outcome": "not_applied",
                             "why": "not applicable: every method and binding failed"}]}],
    "executed": [{"segment": 1, "step": 2, "action": "place", "args": ["b2", "0", "2"], "status": "FAILURE"}],
    "initial_plan": [["place", "b2", "0", "2"]], "plan": [["place", "b2", "0", "2"]],
}


def _campaign(folder):
    (folder / "variants").mkdir(parents=True)
    (folder / "episodes").mkdir()
    for name in ("v0", "v1"):
        (folder / "variants" / f"{name}.yaml").write_text("scene: v\n", encoding="utf-8")
    write_manifest(folder, {"campaign_version": CAMPAIGN_VERSION, "family": "letters_H", "task_file": "letters.yaml",
                            "problem": "H", "seed": 0, "spec_file": "x", "spec": {},
                            "variants": [{"name": n, "file": f"variants/{n}.yaml", "expected": "repairable"}
                                         for n in ("v0", "v1")]})
    rows = [{"variant": "v0", "configuration": "dual", "seed": 0, "expected": "repairable", "status": "failed",
             "success": False, "attempts": 1, "seconds": 3.2, "kinds": ["precondition", "unexpected_configuration"],
             "stop_reason": "no applicable repair", "run_report": "episodes/v0__dual__0.json"},
            {"variant": "v1", "configuration": "dual", "seed": 0, "expected": "repairable", "status": "success",
             "success": True, "attempts": 0, "seconds": 2.0, "kinds": [], "run_report": "episodes/v1__dual__0.json"}]
    with CampaignDatabase.open(folder, manifest_digest(folder)) as database:
        for row in rows:
            database.add(row)
            (folder / row["run_report"]).write_text(json.dumps({**row, "report": _REPORT}), encoding="utf-8")


def test_each_failing_episode_gets_an_html_run_report_linked_from_the_report(tmp_path):
    folder = tmp_path / "C"
    _campaign(folder)
    summary = build_report(folder, tmp_path / "out" / "report.html")
    (failing,) = summary["failing"]
    assert failing["variant"] == "v0" and failing["run_report_html"] == "episodes/v0__dual__0.html"
    page = (folder / failing["run_report_html"]).read_text(encoding="utf-8")
    for text in ("v0 / dual / seed 0", "unexpected_configuration", "classification_rules", "retry step 2 as it is",
                 "failed_again", "not applicable: every method and binding failed", "no applicable repair",
                 "b2 is not at (0, 2)", "../../out/report.html"):
        assert text in page, text
    assert "not shown" not in page  # the executor's bookkeeping (the whole plan) is left out of the evidence
    assert not (folder / "episodes" / "v1__dual__0.html").exists()  # reached its outcome: no page
    report = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    assert "href='../C/episodes/v0__dual__0.html'" in report and "href='../C/episodes/v0__dual__0.json'" in report


def test_a_torn_episode_file_keeps_the_json_link_only(tmp_path):
    folder = tmp_path / "C"
    _campaign(folder)
    (folder / "episodes" / "v0__dual__0.json").write_text("{torn", encoding="utf-8")
    summary = build_report(folder, folder / "report.html")
    assert summary["failing"][0]["run_report_html"] is None
