"""One run's HTML report page, and the pieces the demo's report shares with it (one self-contained file: images
as base64 PNG, pictures as inline SVG, no scripts).

The campaign report renders a page per episode from its JSON, ``bt-meta run --report`` one for a user's run and
the demo one per variant, so the page lives below all three.

Offers:

* :func:`render_run_report` / :func:`write_run_report` -- a run's page: facts, the ground truth, failures with
  their kind and evidence, repair attempts, what was tried and why it failed, executed steps, plans, pictures
* :class:`RunPage` -- watches a command's run (``bt-meta run`` / ``record --report``) and writes its page, the
  task's goal checked on the simulator's true state
* :func:`judge_world` -- the task's goal on the true state; :func:`shipped_family_file` -- a shipped task's family
  file, whose ``success:`` maps goal predicates no check is named after
* :func:`run_pictures` -- what a watched run shows: top views before and after, trees as ticked, grid-maps
* :func:`keypoint_pair`, :func:`keypoint_series`, :func:`keypoints_html` -- R_p / R_n of a pair over the run
* :func:`tree_pictures`, :func:`gridmap_pictures` -- the trees and grid-map mismatches of a
  :class:`~bt_meta.runs.capture.RunCapture`
* :func:`grid_svg` -- a grid-map (the ``render`` text of :mod:`bt_meta.perception.gridmap`) as coloured cells
* the shared markup: :data:`CSS`, :func:`esc`, :func:`img`, :func:`status_pill`, :func:`truth_cell`,
  :func:`short`, :func:`evidence_list`, :func:`dropped`, :func:`plain`, :func:`trees_html`, :func:`gridmaps_html`
"""

from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path
from typing import Any

from bt_meta.plotting import line_plot
from bt_meta.runs.svg import TreeNode, tree_svg

__all__ = [
    "CSS",
    "dropped",
    "esc",
    "evidence_list",
    "grid_svg",
    "gridmap_pictures",
    "gridmaps_html",
    "img",
    "keypoint_pair",
    "keypoint_series",
    "keypoints_html",
    "plain",
    "render_run_report",
    "run_pictures",
    "short",
    "status_pill",
    "tree_pictures",
    "trees_html",
    "truth_cell",
    "write_run_report",
]

_CELL_COLOURS = {".": "#ffffff", "b": "#1e63d6", "r": "#d62f2f", "g": "#2e9d44", "y": "#e8c619", "#": "#777777"}

CSS = """
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


def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def img(png: bytes | None, alt: str, width: int = 320) -> str:
    if not png:
        return f'<div class="small">({esc(alt)}: no image)</div>'
    data = base64.b64encode(png).decode("ascii")
    return f'<img alt="{esc(alt)}" width="{width}" src="data:image/png;base64,{data}">'


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
        out.append(f'<text x="1" y="11">{esc(title)}</text>')
    for r, row in enumerate(rows):
        for c, char in enumerate(row):
            colour = _CELL_COLOURS.get(char, "#777777")
            out.append(f'<rect x="{1 + c * cell}" y="{top + 1 + r * cell}" width="{cell}" height="{cell}" '
                       f'fill="{colour}" stroke="#b0bec5" stroke-width="0.5"/>')
    out.append("</svg>")
    return "".join(out)


def status_pill(status: str) -> str:
    css = "ok" if status in ("success", "recorded", "reused") else "bad" if status in (
        "failed", "crashed", "no_plan") else "neutral"
    return f'<span class="pill {css}">{esc(status)}</span>'


def truth_cell(run: dict[str, Any]) -> str:
    if run.get("achieved") is None:
        return f"<span class=small>{esc(run.get('truth') or 'unknown')}</span>"
    pill = '<span class="pill ok">yes</span>' if run["achieved"] else '<span class="pill bad">no</span>'
    return f"{pill} <span class=small>{esc(run.get('truth'))}</span>"


def short(value: Any, limit: int = 600) -> str:
    text = json.dumps(value, default=str) if not isinstance(value, str) else value
    return text if len(text) <= limit else text[: limit - 3] + "..."


def evidence_list(evidence: dict[str, Any]) -> str:
    items = []
    for key, value in evidence.items():
        if key == "mismatches":
            for mismatch in value or []:
                if isinstance(mismatch, dict):
                    items.append(f"<li><b>mismatch</b> {esc(mismatch.get('kind') or mismatch.get('expectation', ''))}"
                                 f": {esc(short(mismatch.get('message', '')))}</li>")
            continue
        items.append(f"<li><b>{esc(key)}</b>: {esc(short(value, 300))}</li>")
    return f"<ul class='small'>{''.join(items)}</ul>" if items else ""


def dropped(items: str) -> str:
    if not items:
        return ""
    return f"<details><summary class=small>dropped</summary><ul class=small>{items}</ul></details>"


def plain(evidence: dict[str, Any]) -> dict[str, Any]:
    """Evidence without the executor's bookkeeping (the whole plan, the repair history, the localisation)."""
    return {k: v for k, v in evidence.items() if k not in ("plan", "repair_history", "localisation")}


def step_text(entry: dict[str, Any]) -> str:
    args = ", ".join(str(a) for a in entry.get("args") or [])
    return f"{entry.get('step')} {entry.get('action') or ''}({args})"


def failures_html(failures: list[dict[str, Any]]) -> str:
    if not failures:
        return "<p class='small'>No failure was classified.</p>"
    rows = "".join(
        f"<tr><td>{number}</td><td>{esc(step_text(f))}</td><td><b>{esc(f.get('kind'))}</b><br><span class=small>by "
        f"{esc((f.get('evidence') or {}).get('classified_by') or 'monitor')}</span></td>"
        f"<td>{esc(short(f.get('message', ''), 400))}{evidence_list(plain(f.get('evidence') or {}))}</td></tr>"
        for number, f in enumerate(failures, 1))
    return f"<table class='fit'><tr><th style='width:3%'>#</th><th style='width:17%'>step</th><th style='width:14%'>" \
           f"kind</th><th>message and evidence</th></tr>{rows}</table>"


def attempts_html(attempts: list[dict[str, Any]]) -> str:
    if not attempts:
        return "<p class='small'>No repair was attempted.</p>"
    rows = []
    for attempt in attempts:
        proposal = attempt.get("proposal") or {}
        failure = attempt.get("failure") or {}
        rows.append(
            f"<tr><td>{esc(attempt.get('number'))}</td><td><b>{esc(attempt.get('kind'))}</b> at "
            f"{esc(step_text(failure))}</td><td><b>{esc(proposal.get('action'))}</b> "
            f"{float(proposal.get('score') or 0.0):.2f} by {esc(proposal.get('plugin'))}: "
            f"{esc(short(proposal.get('description', ''), 200))}</td><td>{esc(attempt.get('change'))}</td>"
            f"<td>{status_pill(str(attempt.get('outcome')))}</td></tr>")
    return ("<table><tr><th>#</th><th>failure</th><th>proposal applied</th><th>change</th><th>outcome</th></tr>"
            + "".join(rows) + "</table>")


def tried_html(reported: list[dict[str, Any]]) -> str:
    if not reported:
        return ""
    parts = ["<h2>Not repaired: what was tried</h2>"]
    for entry in reported:
        rows = "".join(
            f"<tr><td>{esc(t.get('attempt') if t.get('attempt') is not None else '-')}</td><td><b>"
            f"{esc(t.get('action'))}</b> by {esc(t.get('plugin'))}: {esc(short(t.get('description', ''), 200))}</td>"
            f"<td>{status_pill(str(t.get('outcome')))}</td><td>{esc(short(t.get('why', ''), 500))}</td></tr>"
            for t in entry.get("tried") or [])
        parts.append(f"<h3><b>{esc(entry.get('kind'))}</b> at step {esc(step_text(entry))}</h3><p>"
                     f"{esc(short(entry.get('message', ''), 400))}</p>"
                     f"{evidence_list(plain(entry.get('evidence') or {}))}"
                     + (f"<table class='fit'><tr><th style='width:5%'>attempt</th><th style='width:35%'>proposal</th>"
                        f"<th style='width:10%'>outcome</th><th>why it failed</th></tr>{rows}</table>" if rows else
                        "<p class='small'>Nothing was proposed.</p>"))
    return "".join(parts)


def render_run_report(run: dict[str, Any], *, title: str = "run report", back: str | None = None,
                      pictures: dict[str, Any] | None = None) -> str:
    """A run's report page: ``run`` holds ``report`` (an executor report's dict) and what the caller knows of the
    run (``variant``, ``configuration``, ``seed``, ``expected``, ``status``, ``kinds``, ``error``, ...);
    ``pictures`` (from :func:`run_pictures`) adds the top views, the ticked trees and the grid-maps."""
    report = run.get("report") or {}
    known = [(key, run[key]) for key in ("file", "problem", "scene", "robot", "family", "variant", "description",
                                         "configuration", "seed", "sensing", "expected")
             if run.get(key) is not None]
    status = str(run.get("status") or report.get("status"))
    facts = "".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in known)
    facts += (f"<tr><th>status</th><td>{status_pill(status)}</td></tr>"
              f"<tr><th>failure kinds</th><td>{esc(', '.join(run.get('kinds') or []) or '-')}</td></tr>"
              f"<tr><th>repair attempts</th><td>{len(report.get('attempts') or [])}</td></tr>"
              f"<tr><th>stop reason</th><td>{esc(report.get('stop_reason') or run.get('stop_reason') or '-')}</td></tr>"
              f"<tr><th>task done (simulator)</th><td>{truth_cell(report if 'achieved' in report else run)}</td></tr>"
              f"<tr><th>time</th><td>{esc(run.get('seconds', report.get('seconds')))} s wall, "
              f"{esc(report.get('simulated_seconds', run.get('simulated_seconds')))} s simulated, "
              f"{esc(report.get('ticks'))} ticks, {esc(report.get('segments'))} segment(s)</td></tr>")
    body = [f"<h1>{esc(title)}</h1>"]
    if back:
        body.append(f"<p class='small'><a href='{esc(back)}'>back to the campaign report</a></p>")
    body.append(f"<table>{facts}</table>")
    if run.get("error"):
        body.append(f"<h2>Error</h2><pre>{esc(run['error'])}</pre>")
    if pictures:
        before = img(pictures.get("before_png"), "top view before")
        after = img(pictures.get("after_png"), "top view after")
        body.append(
            f"<h2>The scene and the trees</h2><div class='row'><div>{before}<div class='fig'>top view before the run"
            f"</div></div><div>{after}<div class='fig'>top view after the run</div></div></div>"
            + trees_html(pictures.get("trees") or []) + gridmaps_html(pictures.get("gridmaps") or [])
            + keypoints_html(pictures.get("keypoints")))
    body += ["<h2>Failures classified</h2>", failures_html(list(report.get("failures") or [])),
             "<h2>Repair attempts</h2>", attempts_html(list(report.get("attempts") or [])),
             tried_html(list(report.get("reported") or []))]
    executed = report.get("executed") or []
    if executed:
        rows = "".join(f"<tr><td>{esc(e.get('segment'))}</td><td>{esc(step_text(e))}</td>"
                       f"<td>{status_pill('success' if e.get('status') == 'SUCCESS' else 'failed')}</td></tr>"
                       for e in executed)
        body.append(f"<h2>Executed steps</h2><table><tr><th>segment</th><th>step</th><th>status</th></tr>{rows}"
                    "</table>")
    plans = "".join(f"<p class='small'>{name}: {esc(' ; '.join(' '.join(map(str, s)) for s in report[key]))}</p>"
                    for key, name in (("initial_plan", "initial"), ("plan", "final")) if report.get(key))
    if plans:
        body.append(f"<details><summary>Plans</summary>{plans}</details>")
    second = run.get("second_exposure")
    if second:
        body.append(f"<h2>Second exposure</h2><pre>{esc(json.dumps(second, indent=1, default=str))}</pre>")
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{esc(title)}</title>"
            f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>\n")


def trees_html(trees: list[dict[str, Any]]) -> str:
    """The behaviour tree of each segment as ticked (``tree_pictures`` entries), as inline SVG."""
    if not trees:
        return ""
    parts = []
    for entry in trees:
        if entry.get("tree") is None:
            parts.append(f"<p class='small'>segment {entry['segment']}: no tree ({esc(entry.get('error'))})</p>")
            continue
        tree = TreeNode.from_dict(entry["tree"])
        title = f"segment {entry['segment']} (from step {entry['cursor']})"
        parts.append(f"<div>{tree_svg(tree, title=title)}</div>")
    open_attr = " open" if len(parts) <= 2 else ""
    return (f"<details{open_attr}><summary>Behaviour tree{'s' if len(parts) > 1 else ''} as ticked "
            f"({len(parts)} segment(s))</summary><div class='row'>{''.join(parts)}</div></details>")


def _what(title: str, grid: dict[str, Any]) -> str:
    return f"{title} ({grid.get('colour') or 'nothing'} {grid.get('shape') or ''})".replace(" )", ")")


def gridmaps_html(gridmaps: list[dict[str, Any]]) -> str:
    """Each grid-map mismatch (``gridmap_pictures`` entries): remembered, at the failure, at the end of the run."""
    if not gridmaps:
        return ""
    cells = []
    for entry in gridmaps:
        expected, observed = entry.get("expected") or {}, entry.get("observed") or {}
        cells.append(
            f"<div><div class='fig'>step {esc(entry['step'])}, {esc(entry['object'])}: {entry['cells']} cells differ "
            f"({esc(entry['kind'])})</div><div class='row'>"
            f"{grid_svg(expected.get('grid'), title=_what('remembered', expected))}"
            f"{grid_svg(observed.get('grid'), title=_what('at the failure', observed))}"
            f"{grid_svg(entry.get('after'), title='end of the run')}</div></div>")
    return "<h4>Grid-maps: remembered, observed at the failure, at the end of the run</h4><div class='row'>" + \
        "".join(cells) + "</div>"


def write_run_report(run: dict[str, Any], path: str | Path, *, title: str = "run report",
                     pictures: dict[str, Any] | None = None) -> Path:
    """Write :func:`render_run_report` to ``path`` (an :class:`OSError` is the caller's to report)."""
    path = Path(path)
    path.write_text(render_run_report(run, title=title, pictures=pictures), encoding="utf-8")
    return path


def run_pictures(capture: Any, before_png: bytes | None, after: tuple[bytes | None, Any]) -> dict[str, Any]:
    """The pictures of a watched run: ``after`` is :func:`~bt_meta.runs.capture.top_view_png` of its end."""
    after_png, after_view = after
    return {"before_png": before_png, "after_png": after_png, "trees": tree_pictures(capture),
            "gridmaps": gridmap_pictures(capture, after_view)}


def tree_pictures(capture: Any) -> list[dict[str, Any]]:
    """Each segment's compiled tree with the statuses its steps reported, as :class:`TreeNode` dicts."""
    from bt_meta.runs.svg import tree_from_behaviour

    out = []
    for segment in capture.segments:
        if segment.tree is None or isinstance(segment.tree, Exception):
            out.append({"segment": segment.number, "cursor": segment.cursor, "tree": None,
                        "error": None if segment.tree is None else str(segment.tree)})
            continue
        tree = tree_from_behaviour(segment.tree, segment.statuses, segment.guards)
        out.append({"segment": segment.number, "cursor": segment.cursor, "tree": tree.to_dict()})
    return out


def gridmap_pictures(capture: Any, after_view: Any) -> list[dict[str, Any]]:
    """For each grid-map mismatch: the remembered map, the map observed at the failure and, at the end of the run,
    the map at the same place (after the repair, when there was one)."""
    from bt_meta.perception.gridmap import render

    out = []
    seen: set[tuple[Any, Any]] = set()
    for failure in capture.failures:
        for mismatch in (failure.get("evidence") or {}).get("mismatches") or []:
            evidence = mismatch.get("evidence") if isinstance(mismatch, dict) else None
            maps = (evidence or {}).get("maps") or []
            for entry in maps:
                key = (failure.get("step"), entry.get("object"))
                if key in seen or not entry.get("cells"):
                    continue
                seen.add(key)
                centroid = entry.get("expected", {}).get("centroid")
                after = None
                if after_view is not None and centroid is not None:
                    block = after_view.block_near(centroid, 0.25 * 0.061)
                    if block is not None and block.shape != "unknown":
                        after = render(after_view.grid_map_at(block.centroid, z=block.top_z))
                    else:
                        after = render(after_view.grid_map_at(centroid))
                out.append({"step": failure.get("step"), "object": entry.get("object"), "cells": entry.get("cells"),
                            "kind": failure.get("kind"), "segment": failure.get("segment"),
                            "expected": entry.get("expected"), "observed": entry.get("observed"), "after": after})
    return out


class RunPage:
    """A command's run watched for its page: register :attr:`capture` as a plugin before the run, :meth:`start`
    once the world is built, :meth:`finish` while it is still open, :meth:`write` after the result is shown (so an
    unwritable path loses nothing of the run)."""

    def __init__(self, command: str) -> None:
        from bt_meta.runs.capture import Progress, RunCapture

        self.command = command
        self.capture = RunCapture(Progress(quiet=True), echo=False)
        self.before_png: bytes | None = None
        self.run: dict[str, Any] = {}
        self.pictures: dict[str, Any] = {}
        self.title = command

    def start(self, world: Any) -> None:
        from bt_meta.runs.capture import top_view_png

        self.capture.world = world
        self.before_png, _ = top_view_png(world)

    def finish(self, task_path: str | Path, task_file: Any, problem: Any, world: Any, out: dict[str, Any],
               memory: Any = None) -> None:
        """Judge the world and keep the page's data: ``out`` is the command's outcome (``status`` SUCCESS or
        FAILURE, ``failures``, ``plan`` and ``initial_plan`` as "name arg ..." lines, ``attempts``, ...);
        ``memory``'s traces give the R_p / R_n plots their remembered band."""
        from bt_meta.runs.capture import top_view_png

        achieved, truth = judge_world(Path(task_path), task_file, problem, world)
        status = "success" if out.get("status") == "SUCCESS" else "failed"
        report = {key: out.get(key) for key in ("attempts", "failures", "reported", "stop_reason", "ticks")}
        report.update({"status": status, "achieved": achieved, "truth": truth, "executed": self.capture.steps,
                       "segments": out.get("segments") or len(self.capture.segments),
                       "initial_plan": [line.split() for line in out.get("initial_plan") or []],
                       "plan": [line.split() for line in out.get("plan") or []],
                       "simulated_seconds": round(world.sim.steps * world.sim.time_step, 3)})
        self.run = {key: out.get(key) for key in ("file", "problem", "scene", "robot", "variant", "seed")}
        self.run["description"] = variant_description(world)
        self.run.update({"status": status, "kinds": sorted({str(f.get("kind")) for f in out.get("failures") or []}),
                         "seconds": out.get("run_seconds"), "report": report})
        self.pictures = run_pictures(self.capture, self.before_png, top_view_png(world))
        pair = keypoint_pair(problem, world)
        if pair is not None:
            self.pictures["keypoints"] = keypoint_series(self.capture, memory, problem, pair, report)
        self.title = f"{self.command} {Path(task_path).name} {problem.name} ({world.variant})"

    @property
    def verdict(self) -> str:
        report = self.run.get("report") or {}
        return f"task done in the simulator: {report.get('achieved')}; {report.get('truth')}"

    def write(self, path: str | Path) -> Path:
        """The page at ``path``; a path that cannot be written is a :class:`~bt_meta.errors.UserInputError`."""
        from bt_meta.errors import UserInputError

        try:
            return write_run_report(self.run, path, title=self.title, pictures=self.pictures)
        except OSError as error:
            raise UserInputError(f"cannot write the report: {error.strerror or error} (the result above stands)",
                                 str(path)) from None


def variant_description(world: Any) -> str | None:
    """What the run's scene and variant are, as their file describes them (``description:`` of the scene and of
    the variant; a generated variant's says which perturbations made it), or ``None`` when neither has one: the
    page's reader sees what was changed without opening the scene file."""
    scene = getattr(world, "scene", None)
    if scene is None:
        return None
    variant = getattr(world, "variant", None)
    chosen = (getattr(scene, "variants", None) or {}).get(variant) if variant not in (None, "nominal") else None
    parts = [str(text).strip() for text in (getattr(scene, "description", ""), getattr(chosen, "description", ""))
             if text and str(text).strip()]
    if not parts:
        return None
    if len(parts) == 2:
        return f"{parts[0]}; variant {variant}: {parts[1]}"
    return parts[0] if chosen is None or not getattr(chosen, "description", "") else f"variant {variant}: {parts[0]}"


def judge_world(task_path: Path, task_file: Any, problem: Any, world: Any) -> tuple[bool | None, str]:
    """The task's goal on ``world``'s true state (a shipped task through its family file's ``success:``, as its
    campaigns and the demo judge it); ``None`` with the reason when a goal predicate has no check."""
    from bt_meta.judge.success import SuccessError, success_check, success_check_file

    objects = [o.name for o in world.scene.objects]
    try:
        family = shipped_family_file(task_path, problem.name)
        judge = (success_check(task_file, problem, world.grounding, scene_objects=objects) if family is None
                 else success_check_file(family, task_file, problem, world.grounding, scene_objects=objects))
        return judge.evaluate(world)
    except SuccessError as error:  # a goal predicate no geometric check covers: unknown, not failed
        return None, f"not checked: {error}"


def shipped_family_file(task: Path, problem: str) -> Path | None:
    """The shipped campaign family file (``trees/families/*.yaml``) of ``task``'s ``problem``, or ``None``."""
    import yaml

    from bt_meta.resources import trees_dir

    for path in sorted((trees_dir() / "families").glob("*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
        if (isinstance(data, dict) and data.get("problem") == problem and data.get("task")
                and (path.parent / str(data["task"])).resolve() == task.resolve()):
            return path
    return None


def keypoints_html(data: dict[str, Any] | None) -> str:
    """R_p and R_n of the keypoint pair over the executed steps (:func:`keypoint_series`), against the remembered
    traces' mean and min..max band, each plot with a line saying what it measures."""
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
            f"</div><p class='small'>Executed steps: {esc(calls)}. The band is the min..max over the remembered traces "
            "at the same plan step. R_p: the distance between the two parts' attachment points (0 when joined); R_n: "
            "the angle between their attachment normals (180 deg when they face each other).</p>")


def keypoint_series(capture: Any, memory: Any, problem: Any, pair: tuple[str, str],
                     report: dict[str, Any]) -> dict[str, Any] | None:
    """R_p (mm) and R_n (deg) of ``pair`` after each executed step of this run, and their means (with min/max) over
    the remembered nominal traces at the same plan step (none without a ``memory``)."""
    from bt_meta.errors import BtMetaError
    from bt_meta.memory.recorder import root_task_name
    from bt_meta.perception.keypoints import KeypointError, relation

    active, reference = pair
    observed: list[dict[str, Any]] = []
    for index, step in enumerate(capture.steps):
        objects = step.get("objects") or {}
        if active not in objects or reference not in objects:
            continue
        try:
            rel = relation(objects[active], objects[reference])
        except KeypointError:
            continue
        observed.append({"index": index, "step": step.get("step"), "segment": step.get("segment"),
                         "call": f"{step.get('action')}({', '.join(step.get('args') or ())})",
                         "status": step.get("status"), "r_p_mm": rel.r_p * 1000.0, "r_n_deg": math.degrees(rel.r_n)})
    expected: dict[int, dict[str, Any]] = {}
    try:
        traces = [] if memory is None else memory.last_traces(root_task_name(problem), 5)
    except BtMetaError:
        traces = []
    for trace in traces:
        for step in trace.steps:
            names = {o.name for o in step.state.objects}
            if active not in names or reference not in names:
                continue
            rel = relation(step.state.object(active), step.state.object(reference))
            entry = expected.setdefault(step.index, {"r_p_mm": [], "r_n_deg": []})
            entry["r_p_mm"].append(rel.r_p * 1000.0)
            entry["r_n_deg"].append(math.degrees(rel.r_n))
    if not observed and not expected:
        return None
    return {"active": active, "reference": reference, "observed": observed, "traces": len(traces),
            "expected": {str(k): {name: {"mean": sum(v) / len(v), "min": min(v), "max": max(v)}
                                  for name, v in entry.items()} for k, entry in sorted(expected.items())},
            "failed_steps": [f.get("step") for f in (report.get("failures") or []) if f.get("step") is not None]}


def keypoint_pair(problem: Any, world: Any) -> tuple[str, str] | None:
    """The pair whose R_p / R_n a run's page plots: the first two arguments of the problem's first task, as world
    objects (the pair the keypoint expectations watch by default); ``None`` when they are not two scene objects."""
    tasks = list(getattr(problem, "tasks", None) or [])
    if not tasks or len(tasks[0]) < 3:
        return None
    to_world = getattr(world, "object_name", lambda symbol: symbol)
    try:
        pair = (str(to_world(str(tasks[0][1]))), str(to_world(str(tasks[0][2]))))
    except Exception:  # a symbol the world does not ground: no pair to plot
        return None
    present = {o.name for o in world.scene.objects}
    return pair if pair[0] != pair[1] and set(pair) <= present else None
