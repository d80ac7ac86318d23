"""The demo's report: one self-contained HTML file (images as base64 PNG, pictures as inline SVG, no scripts).

Sections: the summary table, the demonstrations recorded, one section per variant run (top-view camera images
before and after, the behaviour tree of each segment with its node statuses, grid-maps remembered / observed at the
failure / at the end, R_p and R_n over the steps against the remembered traces, the repair log: failure kind,
evidence, proposals, the chosen repair, attempts and time), and the learned refinements as YAML.

Offers:

* :func:`write_report` -- ``report.html`` of a :class:`~bt_meta.demo.runner.DemoResult`
* :func:`render_report` -- the same as a string
* :func:`render_run_report` -- one run's report page from its JSON (an executor report and what the caller knows
  of the run: a campaign episode's variant, configuration, seed, expected outcome): the failures with their kinds
  and evidence, each repair attempt, what was tried for what was not repaired and why each proposal failed
* :func:`grid_svg` -- a grid-map (the ``render`` text of :mod:`bt_meta.perception.gridmap`) as coloured cells
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any

import yaml

from bt_meta.demo.svg import TreeNode, tree_svg
from bt_meta.plotting import line_plot

__all__ = ["grid_svg", "render_report", "render_run_report", "write_report"]

_CELL_COLOURS = {".": "#ffffff", "b": "#1e63d6", "r": "#d62f2f", "g": "#2e9d44", "y": "#e8c619", "#": "#777777"}

_CSS = """
body{font-family:system-ui,sans-serif;margin:24px;max-width:1250px;color:#263238}
h1{font-size:24px}h2{font-size:19px;border-bottom:2px solid #cfd8dc;padding-bottom:4px;margin-top:36px}
h3{font-size:16px;margin:18px 0 6px}h4{font-size:14px;margin:12px 0 4px}
table{border-collapse:collapse;font-size:13px;margin:6px 0;max-width:100%}td,th{border:1px solid #cfd8dc;
padding:3px 7px;vertical-align:top;text-align:left}th{background:#eceff1}td{overflow-wrap:anywhere}
table.fit{width:100%;table-layout:fixed}
.success{background:#e8f5e9}.failed,.crashed,.no_plan{background:#ffebee}.reused{background:#f3e5f5}
.pill{display:inline-block;border-radius:9px;padding:0 7px;font-size:12px;color:#fff;white-space:nowrap}
.ok{background:#43a047}.bad{background:#e53935}.neutral{background:#78909c}
.row{display:flex;flex-wrap:wrap;gap:18px;align-items:flex-start}.fig{font-size:12px;color:#546e7a}
pre{background:#f5f5f5;padding:8px;font-size:12px;overflow-x:auto;max-height:420px}
details{margin:6px 0}summary{cursor:pointer;font-weight:600}.small{font-size:12px;color:#607d8b}
"""


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _img(png: bytes | None, alt: str, width: int = 320) -> str:
    if not png:
        return f'<div class="small">({_e(alt)}: no image)</div>'
    data = base64.b64encode(png).decode("ascii")
    return f'<img alt="{_e(alt)}" width="{width}" src="data:image/png;base64,{data}">'


def grid_svg(grid: str | None, *, cell: int = 14, title: str = "") -> str:
    """A grid-map drawn from its text rendering (``.`` empty, a colour's first letter otherwise)."""
    if not grid:
        return '<div class="small">(no map)</div>'
    rows = grid.splitlines()
    cols = max(len(r) for r in rows)
    width = max(cols * cell + 2, int(len(title) * 6.2) + 4)
    height = len(rows) * cell + 2 + (14 if title else 0)
    top = 14 if title else 0
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-size="11" '
           f'font-family="sans-serif">']
    if title:
        out.append(f'<text x="1" y="11">{_e(title)}</text>')
    for r, row in enumerate(rows):
        for c, char in enumerate(row):
            colour = _CELL_COLOURS.get(char, "#777777")
            out.append(f'<rect x="{1 + c * cell}" y="{top + 1 + r * cell}" width="{cell}" height="{cell}" '
                       f'fill="{colour}" stroke="#b0bec5" stroke-width="0.5"/>')
    out.append("</svg>")
    return "".join(out)


def _status_pill(status: str) -> str:
    css = "ok" if status in ("success", "recorded", "reused") else "bad" if status in (
        "failed", "crashed", "no_plan") else "neutral"
    return f'<span class="pill {css}">{_e(status)}</span>'


def _truth(run: dict[str, Any]) -> str:
    if run.get("achieved") is None:
        return f"<span class=small>{_e(run.get('truth') or 'unknown')}</span>"
    pill = '<span class="pill ok">yes</span>' if run["achieved"] else '<span class="pill bad">no</span>'
    return f"{pill} <span class=small>{_e(run.get('truth'))}</span>"


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


def _short(value: Any, limit: int = 600) -> str:
    text = json.dumps(value, default=str) if not isinstance(value, str) else value
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _evidence(evidence: dict[str, Any]) -> str:
    items = []
    for key, value in evidence.items():
        if key == "mismatches":
            for mismatch in value or []:
                if isinstance(mismatch, dict):
                    items.append(f"<li><b>mismatch</b> {_e(mismatch.get('kind') or mismatch.get('expectation', ''))}"
                                 f": {_e(_short(mismatch.get('message', '')))}</li>")
            continue
        items.append(f"<li><b>{_e(key)}</b>: {_e(_short(value, 300))}</li>")
    return f"<ul class='small'>{''.join(items)}</ul>" if items else ""


def _dropped(items: str) -> str:
    if not items:
        return ""
    return f"<details><summary class=small>dropped</summary><ul class=small>{items}</ul></details>"


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


def _what(title: str, grid: dict[str, Any]) -> str:
    return f"{title} ({grid.get('colour') or 'nothing'} {grid.get('shape') or ''})".replace(" )", ")")


def _gridmaps(outcome: Any) -> str:
    if not outcome.gridmaps:
        return ""
    cells = []
    for entry in outcome.gridmaps:
        expected, observed = entry.get("expected") or {}, entry.get("observed") or {}
        cells.append(
            f"<div><div class='fig'>step {_e(entry['step'])}, {_e(entry['object'])}: {entry['cells']} cells differ "
            f"({_e(entry['kind'])})</div><div class='row'>"
            f"{grid_svg(expected.get('grid'), title=_what('remembered', expected))}"
            f"{grid_svg(observed.get('grid'), title=_what('at the failure', observed))}"
            f"{grid_svg(entry.get('after'), title='end of the run')}</div></div>")
    return "<h4>Grid-maps: remembered, observed at the failure, at the end of the run</h4><div class='row'>" + \
        "".join(cells) + "</div>"


def _keypoints(outcome: Any) -> str:
    data = outcome.keypoints
    if not data:
        return ""
    observed = data["observed"]
    expected = data["expected"]
    markers = []
    for index, entry in enumerate(observed):
        if entry["status"] != "SUCCESS":
            markers.append((float(index), f"{entry['status'].lower()} step {entry['step']}"))
    plots = []
    for key, unit, name in (("r_p_mm", "mm", "R_p"), ("r_n_deg", "deg", "R_n")):
        series = {f"{name} this run": [(float(i), e[key]) for i, e in enumerate(observed)]}
        band: list[tuple[float, float, float]] = []
        mean: list[tuple[float, float | None]] = []
        for i, entry in enumerate(observed):
            remembered = expected.get(str(entry["step"])) if entry.get("segment") == 1 else None
            if remembered is None and entry.get("step") is not None:
                remembered = expected.get(str(entry["step"]))
            if remembered is None:
                mean.append((float(i), None))
                continue
            mean.append((float(i), remembered[key]["mean"]))
            band.append((float(i), remembered[key]["min"], remembered[key]["max"]))
        label = f"{name} mean of {data['traces']} trace(s)"
        series[label] = mean
        plots.append(line_plot(series, title=f"{name} ({data['active']} vs {data['reference']})",
                               x_label="executed step (in order, repairs included)", y_label=f"{name} ({unit})",
                               bands={label: band}, markers=markers))
    calls = ", ".join(f"{i}: {e['call']}" for i, e in enumerate(observed))
    return ("<h4>Keypoint relations over the executed steps</h4><div class='row'>" + "".join(plots) +
            f"</div><p class='small'>Executed steps: {_e(calls)}. The band is the min..max over the remembered traces "
            "at the same plan step.</p>")


def _trees(outcome: Any) -> str:
    if not outcome.trees:
        return ""
    parts = []
    for entry in outcome.trees:
        if entry.get("tree") is None:
            parts.append(f"<p class='small'>segment {entry['segment']}: no tree ({_e(entry.get('error'))})</p>")
            continue
        tree = TreeNode.from_dict(entry["tree"])
        title = f"segment {entry['segment']} (from step {entry['cursor']})"
        parts.append(f"<div>{tree_svg(tree, title=title)}</div>")
    open_attr = " open" if len(parts) <= 2 else ""
    return (f"<details{open_attr}><summary>Behaviour tree{'s' if len(parts) > 1 else ''} as ticked "
            f"({len(parts)} segment(s))</summary><div class='row'>{''.join(parts)}</div></details>")


def _plain(evidence: dict[str, Any]) -> dict[str, Any]:
    """Evidence without the executor's bookkeeping (the whole plan, the repair history, the localisation)."""
    return {k: v for k, v in evidence.items() if k not in ("plan", "repair_history", "localisation")}


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
    return (head + images + _trees(outcome) + _gridmaps(outcome) + _keypoints(outcome) + "<h4>Repair log</h4>" +
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


def _step(entry: dict[str, Any]) -> str:
    args = ", ".join(str(a) for a in entry.get("args") or [])
    return f"{entry.get('step')} {entry.get('action') or ''}({args})"


def _failures(failures: list[dict[str, Any]]) -> str:
    if not failures:
        return "<p class='small'>No failure was classified.</p>"
    rows = "".join(
        f"<tr><td>{number}</td><td>{_e(_step(f))}</td><td><b>{_e(f.get('kind'))}</b><br><span class=small>by "
        f"{_e((f.get('evidence') or {}).get('classified_by') or 'monitor')}</span></td>"
        f"<td>{_e(_short(f.get('message', ''), 400))}{_evidence(_plain(f.get('evidence') or {}))}</td></tr>"
        for number, f in enumerate(failures, 1))
    return f"<table class='fit'><tr><th style='width:3%'>#</th><th style='width:17%'>step</th><th style='width:14%'>" \
           f"kind</th><th>message and evidence</th></tr>{rows}</table>"


def _attempts(attempts: list[dict[str, Any]]) -> str:
    if not attempts:
        return "<p class='small'>No repair was attempted.</p>"
    rows = []
    for attempt in attempts:
        proposal = attempt.get("proposal") or {}
        failure = attempt.get("failure") or {}
        rows.append(
            f"<tr><td>{_e(attempt.get('number'))}</td><td><b>{_e(attempt.get('kind'))}</b> at "
            f"{_e(_step(failure))}</td><td><b>{_e(proposal.get('action'))}</b> "
            f"{float(proposal.get('score') or 0.0):.2f} by {_e(proposal.get('plugin'))}: "
            f"{_e(_short(proposal.get('description', ''), 200))}</td><td>{_e(attempt.get('change'))}</td>"
            f"<td>{_status_pill(str(attempt.get('outcome')))}</td></tr>")
    return ("<table><tr><th>#</th><th>failure</th><th>proposal applied</th><th>change</th><th>outcome</th></tr>"
            + "".join(rows) + "</table>")


def _tried(reported: list[dict[str, Any]]) -> str:
    if not reported:
        return ""
    parts = ["<h2>Not repaired: what was tried</h2>"]
    for entry in reported:
        rows = "".join(
            f"<tr><td>{_e(t.get('attempt') if t.get('attempt') is not None else '-')}</td><td><b>"
            f"{_e(t.get('action'))}</b> by {_e(t.get('plugin'))}: {_e(_short(t.get('description', ''), 200))}</td>"
            f"<td>{_status_pill(str(t.get('outcome')))}</td><td>{_e(_short(t.get('why', ''), 500))}</td></tr>"
            for t in entry.get("tried") or [])
        parts.append(f"<h3><b>{_e(entry.get('kind'))}</b> at step {_e(_step(entry))}</h3><p>"
                     f"{_e(_short(entry.get('message', ''), 400))}</p>{_evidence(_plain(entry.get('evidence') or {}))}"
                     + (f"<table class='fit'><tr><th style='width:5%'>attempt</th><th style='width:35%'>proposal</th>"
                        f"<th style='width:10%'>outcome</th><th>why it failed</th></tr>{rows}</table>" if rows else
                        "<p class='small'>Nothing was proposed.</p>"))
    return "".join(parts)


def render_run_report(run: dict[str, Any], *, title: str = "run report", back: str | None = None) -> str:
    """A run's report page: ``run`` holds ``report`` (an executor report's dict) and what the caller knows of the
    run (``variant``, ``configuration``, ``seed``, ``expected``, ``status``, ``kinds``, ``error``, ...)."""
    report = run.get("report") or {}
    known = [(key, run[key]) for key in ("family", "variant", "configuration", "seed", "sensing", "expected")
             if run.get(key) is not None]
    status = str(run.get("status") or report.get("status"))
    facts = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in known)
    facts += (f"<tr><th>status</th><td>{_status_pill(status)}</td></tr>"
              f"<tr><th>failure kinds</th><td>{_e(', '.join(run.get('kinds') or []) or '-')}</td></tr>"
              f"<tr><th>repair attempts</th><td>{len(report.get('attempts') or [])}</td></tr>"
              f"<tr><th>stop reason</th><td>{_e(report.get('stop_reason') or run.get('stop_reason') or '-')}</td></tr>"
              f"<tr><th>task done (simulator)</th><td>{_truth(report if 'achieved' in report else run)}</td></tr>"
              f"<tr><th>time</th><td>{_e(run.get('seconds', report.get('seconds')))} s wall, "
              f"{_e(report.get('simulated_seconds', run.get('simulated_seconds')))} s simulated, "
              f"{_e(report.get('ticks'))} ticks, {_e(report.get('segments'))} segment(s)</td></tr>")
    body = [f"<h1>{_e(title)}</h1>"]
    if back:
        body.append(f"<p class='small'><a href='{_e(back)}'>back to the campaign report</a></p>")
    body.append(f"<table>{facts}</table>")
    if run.get("error"):
        body.append(f"<h2>Error</h2><pre>{_e(run['error'])}</pre>")
    body += ["<h2>Failures classified</h2>", _failures(list(report.get("failures") or [])),
             "<h2>Repair attempts</h2>", _attempts(list(report.get("attempts") or [])),
             _tried(list(report.get("reported") or []))]
    executed = report.get("executed") or []
    if executed:
        rows = "".join(f"<tr><td>{_e(e.get('segment'))}</td><td>{_e(_step(e))}</td>"
                       f"<td>{_status_pill('success' if e.get('status') == 'SUCCESS' else 'failed')}</td></tr>"
                       for e in executed)
        body.append(f"<h2>Executed steps</h2><table><tr><th>segment</th><th>step</th><th>status</th></tr>{rows}"
                    "</table>")
    plans = "".join(f"<p class='small'>{name}: {_e(' ; '.join(' '.join(map(str, s)) for s in report[key]))}</p>"
                    for key, name in (("initial_plan", "initial"), ("plan", "final")) if report.get(key))
    if plans:
        body.append(f"<details><summary>Plans</summary>{plans}</details>")
    second = run.get("second_exposure")
    if second:
        body.append(f"<h2>Second exposure</h2><pre>{_e(json.dumps(second, indent=1, default=str))}</pre>")
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{_e(title)}</title>"
            f"<style>{_CSS}</style></head><body>{''.join(body)}</body></html>\n")


def write_report(result: Any, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(render_report(result), encoding="utf-8")
    return path
