"""``campaign report``: the campaign database as numbers (JSON) and as an HTML page with matplotlib plots.

Per expected outcome and configuration: rate of the expected outcome reached with its Wilson 95 % interval,
attempts and seconds (bootstrap intervals), loops; the confusion table of expected outcome against the failure
kinds classified; false alarms on ``nominal_equivalent`` variants; second-exposure attempts; every episode that
did not reach its expected outcome linked to its own run report: ``episodes/<episode>.html``, rendered from the
episode's JSON by the shared run-report code (:func:`bt_meta.runs.report.render_run_report`: the failure, its
kinds, the attempts, what was tried and why each proposal failed), beside the JSON it came from.

Offers:

* :func:`build_report` -- read ``DIR``, write the HTML, return the summary (``--json``)
* :func:`print_summary` -- the text table
"""

from __future__ import annotations

import html
import os
from pathlib import Path
from typing import Any

from bt_meta.campaign.stats import correct, perturbation_classes, summarise

__all__ = ["build_report", "print_class_matrix", "print_summary"]


def build_report(folder: str | Path, out: str | Path) -> dict[str, Any]:
    from bt_meta.campaign.database import CampaignDatabase
    from bt_meta.campaign.manifest import manifest_digest, read_manifest

    folder, out = Path(folder), Path(out)
    manifest = read_manifest(folder)
    with CampaignDatabase.open(folder, manifest_digest(folder), create=False) as database:
        rows = database.rows()
    summary = summarise(rows, classes=perturbation_classes(manifest))
    summary["family"] = manifest["family"]
    summary["variants"] = len(manifest["variants"])
    summary["failing"] = [{"variant": r["variant"], "configuration": r["configuration"], "seed": r["seed"],
                           "expected": r["expected"], "status": r["status"], "kinds": r.get("kinds"),
                           "stop_reason": r.get("stop_reason"), "run_report": r.get("run_report")}
                          for r in rows if not correct(r)]
    out.parent.mkdir(parents=True, exist_ok=True)
    for r in summary["failing"]:
        r["run_report_html"] = _episode_page(folder, r, out)
    out.write_text(_html(summary, manifest, folder, out), encoding="utf-8")
    return summary


def _episode_page(folder: Path, row: dict[str, Any], out: Path) -> str | None:
    """Render an episode's JSON run report as HTML beside it; its path relative to ``folder`` (None without one)."""
    import json

    from bt_meta.runs.report import render_run_report

    if not row.get("run_report"):
        return None
    source = folder / str(row["run_report"])
    try:
        run = json.loads(source.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # the link to the JSON stays; a missing or torn file is not the report's to mend
    page = source.with_suffix(".html")
    title = f"{row['variant']} / {row['configuration']} / seed {row['seed']}"
    page.write_text(render_run_report(run, title=title, back=os.path.relpath(out, page.parent)), encoding="utf-8")
    return str(page.relative_to(folder))


def _html(summary: dict[str, Any], manifest: dict[str, Any], folder: Path, out: Path) -> str:
    from bt_meta.plotting import heatmap, rate_bars

    e = html.escape
    table = summary["table"]
    groups = list(dict.fromkeys(r["expected"] for r in table))
    configurations = summary["configurations"]
    rates = {(r["expected"], r["configuration"]): r["rate"] for r in table}
    intervals = {(r["expected"], r["configuration"]): tuple(r["wilson95"]) for r in table}
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>campaign {e(manifest['family'])}</title>",
             "<style>body{font-family:sans-serif;margin:2em;max-width:75em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#eee}"
             "td:first-child,td:nth-child(2){text-align:left}</style></head><body>",
             f"<h1>Campaign: {e(manifest['family'])}, {summary['variants']} variants, {summary['episodes']} "
             "episodes</h1>",
             f"<p>Task file {e(manifest['task_file'])}, problem {e(manifest['problem'])}, generator seed "
             f"{manifest['seed']}, spec {e(str(manifest['spec_file']))}. Wall time of the episodes "
             f"{summary['seconds']:.0f} s for {summary['simulated_seconds']:.0f} s simulated.</p>"]
    if table:
        parts.append("<h2>Expected outcome reached, per configuration (Wilson 95 % interval)</h2>")
        parts.append(rate_bars(groups, configurations, rates, intervals, ylabel="expected outcome reached"))
        parts.append("<table><tr><th>expected</th><th>configuration</th><th>episodes</th><th>reached</th>"
                     "<th>rate [Wilson 95 %]</th><th>attempts [95 % CI]</th><th>seconds [95 % CI]</th>"
                     "<th>loops</th><th>crashed</th></tr>")
        for r in table:
            a, s = r["attempts"], r["seconds"]
            parts.append(f"<tr><td>{e(r['expected'])}</td><td>{e(r['configuration'])}</td><td>{r['episodes']}</td>"
                         f"<td>{r['correct']}</td><td>{r['rate']:.2f} [{r['wilson95'][0]:.2f}, "
                         f"{r['wilson95'][1]:.2f}]</td><td>{a['mean']:.2f} [{a['low']:.2f}, {a['high']:.2f}]</td>"
                         f"<td>{s['mean']:.1f} [{s['low']:.1f}, {s['high']:.1f}]</td><td>{r['loops']}</td>"
                         f"<td>{r['crashed']}</td></tr>")
        parts.append("</table><p>Reached: <code>nominal_equivalent</code> / <code>repairable</code> -- ended "
                     "success and the simulator confirms the task done; <code>limit:KIND</code> -- ended failed "
                     "with KIND classified; <code>unrepairable</code> -- ended failed.</p>")
    confusion = summary["confusion"]
    if confusion:
        kinds = sorted({k for counts in confusion.values() for k in counts})
        rows = [g for g in groups if g in confusion]
        parts.append("<h2>Confusion: expected outcome x failure kinds classified (episodes)</h2>")
        parts.append(heatmap(rows, kinds, {(r, k): confusion[r].get(k, 0) for r in rows for k in kinds}))
        parts.append("<table><tr><th>expected</th>" + "".join(f"<th>{e(k)}</th>" for k in kinds) + "</tr>")
        for r in rows:
            parts.append(f"<tr><td>{e(r)}</td>" + "".join(f"<td>{confusion[r].get(k, 0)}</td>" for k in kinds)
                         + "</tr>")
        parts.append("</table>")
    fa, second = summary["false_alarms"], summary["second_exposure"]
    parts.append(f"<h2>Loops, false alarms, second exposure</h2><ul><li>loops (attempt budget spent): "
                 f"{summary['loops']}</li><li>false alarms (any failure on a nominal_equivalent variant): "
                 f"{fa['count']} of {fa['of']}</li><li>second exposure: {second['repaired']} repaired runs run "
                 f"again on the memory their repair wrote, {second['zero_attempts']} succeeded with zero attempts"
                 + (f", {second['false_successes']} ended success with the task not done"
                    if second.get("false_successes") else "")
                 + (f", mean attempts {second['attempts']['mean']:.2f}" if second["attempts"] else "")
                 + "</li></ul>")
    if summary["failing"]:
        parts.append("<h2>Episodes that did not reach their expected outcome</h2><table><tr><th>variant</th>"
                     "<th>configuration</th><th>seed</th><th>expected</th><th>status</th><th>kinds</th>"
                     "<th>stop reason</th><th>run report</th></tr>")
        for r in summary["failing"]:
            links = []
            for key in ("run_report_html", "run_report"):
                if r.get(key):
                    link = os.path.relpath(folder / str(r[key]), out.parent)
                    links.append(f"<a href='{e(link)}'>{'HTML' if key.endswith('html') else 'JSON'}</a>")
            parts.append(f"<tr><td>{e(r['variant'])}</td><td>{e(r['configuration'])}</td><td>{r['seed']}</td>"
                         f"<td>{e(r['expected'])}</td><td>{e(str(r['status']))}</td>"
                         f"<td>{e(', '.join(r.get('kinds') or []))}</td><td>{e(str(r.get('stop_reason') or ''))}"
                         f"</td><td>{' '.join(links)}</td></tr>")
        parts.append("</table>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def print_summary(summary: dict[str, Any]) -> None:
    print(f"{'expected':<20} {'configuration':<15} {'episodes':>8} {'reached':>7} {'rate [Wilson 95%]':>19} "
          f"{'attempts':>8} {'seconds':>8} {'loops':>5}")
    for r in summary["table"]:
        rate = f"{r['rate']:.2f} [{r['wilson95'][0]:.2f}, {r['wilson95'][1]:.2f}]"
        print(f"{r['expected']:<20} {r['configuration']:<15} {r['episodes']:>8} {r['correct']:>7} {rate:>19} "
              f"{r['attempts']['mean']:>8.2f} {r['seconds']['mean']:>8.1f} {r['loops']:>5}")
    print("confusion (expected: kinds): " + "; ".join(
        f"{k}: " + ", ".join(f"{kind} {n}" for kind, n in sorted(v.items())) for k, v in summary["confusion"].items()))
    if summary.get("classes"):
        print(f"{'perturbation class':<20} {'configuration':<15} {'episodes':>8} {'reached':>7} "
              f"{'rate [Wilson 95%]':>19}")
        for r in summary["classes"]:
            rate = f"{r['rate']:.2f} [{r['wilson95'][0]:.2f}, {r['wilson95'][1]:.2f}]"
            print(f"{r['class']:<20} {r['configuration']:<15} {r['episodes']:>8} {r['correct']:>7} {rate:>19}")
    fa, second = summary["false_alarms"], summary["second_exposure"]
    print(f"loops {summary['loops']}; false alarms {fa['count']}/{fa['of']}; second exposure: "
          f"{second['zero_attempts']}/{second['repaired']} repaired runs with zero attempts; crashed "
          f"{summary['crashed']}")


def print_class_matrix(classes: list[dict[str, Any]], configurations: list[str]) -> None:
    """A class table as rows of perturbation classes and a column per configuration: rate [Wilson 95 %] (n)."""
    cells = {(r["class"], r["configuration"]): r for r in classes}
    names = list(dict.fromkeys(r["class"] for r in classes))
    print(f"{'perturbation class':<18}" + "".join(f" {c:>24}" for c in configurations))
    for name in names:
        line = f"{name:<18}"
        for configuration in configurations:
            r = cells.get((name, configuration))
            text = "-" if r is None else (f"{r['rate']:.2f} [{r['wilson95'][0]:.2f}, {r['wilson95'][1]:.2f}] "
                                          f"({r['episodes']})")
            line += f" {text:>24}"
        print(line)
