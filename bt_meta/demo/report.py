"""The demo's report: one self-contained HTML file (images as base64 PNG, pictures as inline SVG, no scripts).

Sections: the summary table, the demonstrations recorded, one section per variant run (top-view camera images
before and after, the behaviour tree of each segment with its node statuses, grid-maps remembered / observed at the
failure / at the end, R_p and R_n over the steps against the remembered traces, the repair log: failure kind,
evidence, proposals, the chosen repair, attempts and time), and the learned refinements as YAML.

Offers:

* :func:`write_report` -- ``report.html`` of a :class:`~bt_meta.demo.runner.DemoResult`
* :func:`render_report` -- the same as a string
* :func:`render_run_report`, :func:`grid_svg` -- one run's page and a grid-map picture, from
  :mod:`bt_meta.runs.report` (shared with the campaigns and ``bt-meta run --report``)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from bt_meta.runs.report import CSS as _CSS
from bt_meta.runs.report import dropped as _dropped
from bt_meta.runs.report import esc as _e
from bt_meta.runs.report import evidence_list as _evidence
from bt_meta.runs.report import grid_svg, gridmaps_html, keypoints_html, render_run_report, trees_html
from bt_meta.runs.report import img as _img
from bt_meta.runs.report import plain as _plain
from bt_meta.runs.report import short as _short
from bt_meta.runs.report import status_pill as _status_pill
from bt_meta.runs.report import truth_cell as _truth

__all__ = ["grid_svg", "render_report", "render_run_report", "write_report"]

# (header, width in % of the page): a fixed layout with these widths keeps the 13 columns inside the page; long
# refinement names and stop reasons wrap inside their cells instead of pushing the table past the right edge.
_SUMMARY_COLUMNS = (
    ("pass", 3.5), ("family", 7.0), ("problem / variant", 11.0), ("status", 6.5), ("attempts", 6.0),
    ("failure kinds seen", 9.0), ("repairs applied", 11.0), ("refinement used", 8.5), ("refinement learned", 8.5),
    ("not repaired because", 12.0), ("task done (simulator)", 8.0), ("ticks", 4.5), ("time (s)", 4.5),
)


def _summary_table(summary: dict[str, Any]) -> str:
    cols = "".join(f'<col style="width:{width}%">' for _, width in _SUMMARY_COLUMNS)
    head = "<tr>" + "".join(f"<th>{_e(name)}</th>" for name, _ in _SUMMARY_COLUMNS) + "</tr>"
    rows = []
    for run in summary["runs"]:
        repairs = "<br>".join(f"#{r['number']} {_e(r['action'])} ({_e(r['plugin'])}) → {_e(r['outcome'])}"
                              for r in run["repairs"]) or "-"
        kinds = ", ".join(sorted({str(k) for k in run["failure_kinds"]})) or "-"
        rows.append(
            f'<tr class="{_e(run["status"])}"><td>{run["pass"]}</td><td>{_e(run["family"])}</td>'
            f'<td>{_e(run["problem"])} / <b>{_e(run["variant"])}</b></td><td>{_status_pill(run["status"])}</td>'
            f'<td>{run["attempts"]}</td><td>{_e(kinds)}</td><td>{repairs}</td>'
            f'<td>{_e(", ".join(run["refinements_used"]) or "-")}</td><td>{_e(run["refinement_saved"] or "-")}</td>'
            f'<td>{_e(run["stop_reason"] or run["error"] or "") if run["status"] != "success" else ""}</td>'
            f'<td>{_truth(run)}</td><td>{run["ticks"]}</td><td>{run["seconds"]}</td></tr>')
    return f'<table class="fit summary"><colgroup>{cols}</colgroup>{head}{"".join(rows)}</table>'


def _demonstrations(summary: dict[str, Any]) -> str:
    rows = "".join(
        f'<tr class="{_e(d["status"])}"><td>{_e(d["task_file"])}</td><td>{_e(d["problem"])}</td><td>{d["seed"]}</td>'
        f'<td>{_status_pill(d["status"])}</td><td>{_e(d["episode_id"])}</td><td>{d["steps"]}</td><td>{d["ticks"]}</td>'
        f'<td>{d["seconds"]}</td><td>{_e(d["message"])}</td></tr>' for d in summary["demonstrations"])
    return ("<table><tr><th>task file</th><th>problem</th><th>seed</th><th>status</th><th>episode</th><th>steps</th>"
            f"<th>ticks</th><th>time (s)</th><th>note</th></tr>{rows}</table>")


def _repair_log(outcome: Any) -> str:
    capture = outcome.capture
    if capture is None or not capture.decisions:
        return "<p class='small'>No failure: the meta-reasoner had nothing to do.</p>"
    attempts = {a.get("number"): a for a in outcome.attempts}
    applied = [a for a in outcome.attempts]
    rows = []
    next_attempt = 0
    for number, decision in enumerate(capture.decisions, 1):
        proposals = "".join(
            f"<li>{_e(p.get('action'))} <b>{p.get('score', 0):.2f}</b> by {_e(p.get('plugin'))}: "
            f"{_e(_short(p.get('description', ''), 200))}"
            f"{' <span class=small>' + _e(_short(p.get('changes'), 200)) + '</span>' if p.get('changes') else ''}"
            f"</li>" for p in decision["proposals"])
        dropped = "".join(f"<li>{_e(_short(d, 200))}</li>" for d in decision.get("dropped") or [])
        if decision["stop"]:
            chosen = f"<b>stop</b>: {_e(decision['reason'])}"
        elif next_attempt < len(applied):
            attempt = applied[next_attempt]
            next_attempt += 1
            proposal = attempt.get("proposal") or {}
            chosen = (f"attempt #{attempt.get('number')}: <b>{_e(proposal.get('action'))}</b> by "
                      f"{_e(proposal.get('plugin'))} -- {_e(attempt.get('change'))}<br>outcome: "
                      f"<b>{_e(attempt.get('outcome'))}</b>, applied in {attempt.get('seconds', 0) * 1000:.1f} ms")
        else:
            chosen = "no proposal could be applied"
        rows.append(
            f"<tr><td>{number}</td><td>{decision.get('segment')}</td><td><b>{_e(decision['kind'])}</b><br>"
            f"<span class=small>by {_e(decision.get('classified_by') or 'monitor')}</span></td>"
            f"<td>{_e(decision.get('step'))} {_e(decision.get('action') or '')}"
            f"({_e(', '.join(decision.get('args') or []))})</td>"
            f"<td>{_e(_short(decision['message'], 400))}{_evidence(decision['evidence'])}</td>"
            f"<td><ol class=small>{proposals or '<li>none</li>'}</ol>"
            f"{_dropped(dropped)}"
            f"</td><td>{chosen}</td></tr>")
    total = sum(float(a.get("seconds") or 0.0) for a in attempts.values())
    return ("<table><tr><th>#</th><th>segment</th><th>failure kind</th><th>step</th><th>evidence</th>"
            "<th>proposals (ranked)</th><th>chosen repair</th></tr>" + "".join(rows) + "</table>"
            f"<p class='small'>{len(attempts)} attempt(s); applying them took {total * 1000:.1f} ms; the whole run "
            f"{outcome.seconds:.2f} s.</p>")


def _keypoints(outcome: Any) -> str:
    return keypoints_html(outcome.keypoints)


def _run_section(outcome: Any) -> str:
    data = outcome.to_dict()
    anchor = f"run-{data['pass']}-{data['family']}-{data['variant']}"
    head = (f"<h3 id='{_e(anchor)}'>Pass {data['pass']}: {_e(data['label'])} {_status_pill(data['status'])}</h3>"
            f"<p class='small'>{_e(data['task_file'])}, problem {_e(data['problem'])}, variant {_e(data['variant'])}, "
            f"seed {data['seed']}: {data['attempts']} repair attempt(s), {data['ticks']} ticks, {data['seconds']} s. ")
    if data["refinements_used"]:
        head += f"Planned with the learned refinement {_e(', '.join(data['refinements_used']))}. "
    if data["refinement_saved"]:
        head += f"Learned the refinement {_e(data['refinement_saved'])}. "
    if data["status"] != "success":
        head += f"<b>Not repaired</b>: {_e(data['stop_reason'] or data['error'])}. "
    if data["achieved"] is not None:
        head += f"Ground truth (simulator): task {'done' if data['achieved'] else '<b>not done</b>'} -- " \
                f"{_e(data['truth'])}."
    head += "</p>"
    if outcome.error:
        return head + f"<pre>{_e(outcome.error)}</pre>"
    plans = (f"<details><summary>Plans</summary><p class='small'>initial: "
             f"{_e(' ; '.join(' '.join(map(str, s)) for s in data['initial_plan']))}</p><p class='small'>final: "
             f"{_e(' ; '.join(' '.join(map(str, s)) for s in data['plan']))}</p></details>")
    images = (f"<div class='row'><div>{_img(outcome.before_png, 'top view before')}<div class='fig'>top view before "
              f"the run</div></div><div>{_img(outcome.after_png, 'top view after')}<div class='fig'>top view after "
              f"the run</div></div></div>")
    reported = ""
    if outcome.report.get("reported"):
        items = "".join(f"<li><b>{_e(r.get('kind'))}</b> at step {_e(r.get('step'))}: "
                        f"{_e(_short(r.get('message', ''), 300))}{_evidence(_plain(r.get('evidence') or {}))}</li>"
                        for r in outcome.report["reported"])
        reported = f"<h4>Reported (not repaired)</h4><ul>{items}</ul>"
    return (head + images + trees_html(outcome.trees) + gridmaps_html(outcome.gridmaps) + _keypoints(outcome) +
            "<h4>Repair log</h4>" +
            _repair_log(outcome) + reported + plans)


def _refinements(summary: dict[str, Any]) -> str:
    if not summary["refinements"]:
        return "<p>No refinement learned (no run was repaired with a changed plan).</p>"
    parts = []
    for refinement in summary["refinements"]:
        method = {"name": refinement["method"], "task": refinement["task"],
                  "precondition": refinement["precondition"], "subtasks": refinement["subtasks"]}
        text = yaml.safe_dump([method], sort_keys=False, width=110)
        parts.append(f"<h4>{_e(refinement['method'])}</h4><p class='small'>domain {_e(refinement['domain'])}, "
                     f"learned from problem {_e(refinement.get('problem'))}, variant {_e(refinement.get('variant'))}, "
                     f"{_e(refinement.get('created'))}</p><pre>{_e(text)}</pre>")
    return "".join(parts)


def render_report(result: Any) -> str:
    summary = result.summary()
    totals = summary["totals"]
    first = [r for r in result.runs if r.pass_number == 1]
    second = [r for r in result.runs if r.pass_number == 2]
    intro = (f"<p>Memory <code>{_e(summary['memory'])}</code> ({'new' if summary['fresh_memory'] else 'reused'}), "
             f"seed {summary['seed']}{', quick' if summary['quick'] else ''}; repair plugins installed: "
             f"{_e(', '.join(summary['repair_plugins']))}; configuration {_e(summary['configuration']['name'])}: "
             f"{_e(summary['configuration']['plugins'])}. Demo {'completed' if summary['completed'] else 'INCOMPLETE'}"
             f" in {summary['seconds']} s.</p><p>First pass: {totals['first_pass_success']}/{totals['variants']} "
             f"variants succeeded ({totals['first_pass_repaired']} after repairs, {totals['first_pass_attempts']} "
             f"attempts in all; the simulator confirms the task done in {totals['first_pass_achieved']}; "
             f"{totals['false_successes']} run(s) of both passes ended success without the task done). "
             f"Second pass: {totals['second_pass_success']}/{len(second)} succeeded, "
             f"{totals['second_pass_zero_attempts']} with zero attempts, {totals['second_pass_using_refinements']} "
             "planned with a learned refinement.</p>")
    if summary["crashed"]:
        intro += "<p><b>Crashed steps of the demo:</b></p><ul>" + "".join(
            f"<li>{_e(c)}</li>" for c in summary["crashed"]) + "</ul>"
    body = [f"<h1>bt-meta demo report</h1>{intro}", "<h2>Summary</h2>", _summary_table(summary),
            "<h2>Demonstrations recorded</h2>", _demonstrations(summary),
            "<h2>First pass: variants with monitors and the meta-reasoner</h2>",
            *(_run_section(o) for o in first),
            "<h2>Second pass: the same variants again</h2>", *(_run_section(o) for o in second),
            "<h2>Learned refinements</h2>", _refinements(summary)]
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>bt-meta demo report</title>"
            f"<style>{_CSS}</style></head><body>{''.join(body)}</body></html>\n")


def write_report(result: Any, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(render_report(result), encoding="utf-8")
    return path
