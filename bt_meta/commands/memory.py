"""``bt-meta memory ls | show ID | export``: inspect the episodic memory of the current project.

Offers:

* ``bt-meta memory ls [--task T] [--json]`` -- the stored episodes, newest first
* ``bt-meta memory show ID [--json]`` -- one whole trace: steps, symbolic states, object states, grid-maps,
  expectations
* ``bt-meta memory check [--json]`` -- SQLite's integrity check plus the completeness of every trace (exit 1 if not)
* ``bt-meta memory export [--json] [-o FILE]`` -- every trace; JSON Lines (one trace per line, streamable) by
  default, one JSON document with ``--json``; grid-maps as nested lists, crops as base64 PNG

Every subcommand takes ``--memory PATH`` (else ``$BT_META_MEMORY``, else ``./.bt-meta/memory.sqlite``). Reading
never creates a memory file; a missing, corrupt or foreign file is reported with its path.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TextIO

from bt_meta.commands._common import json_stream, print_json
from bt_meta.errors import UserInputError
from bt_meta.memory import (
    SCHEMA_VERSION,
    EpisodicMemory,
    GridMap,
    State,
    Trace,
    add_memory_argument,
    resolve_memory_path,
)
from bt_meta.memory.trace import trace_to_dict

EXPORT_FORMAT = "bt-meta-memory-export"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("memory", help="inspect the episodic memory (ls, show, export)")
    memory_subparsers = parser.add_subparsers(dest="memory_command", metavar="ACTION", parser_class=type(parser))

    ls = memory_subparsers.add_parser("ls", help="list the stored episodes, newest first")
    ls.add_argument("--task", metavar="T", help="only episodes of this root task")
    ls.add_argument("--json", action="store_true", help="print JSON")
    add_memory_argument(ls)
    ls.set_defaults(func=_ls)

    show = memory_subparsers.add_parser("show", help="print one stored trace")
    show.add_argument("id", metavar="ID", type=int, help="episode id (see `bt-meta memory ls`)")
    show.add_argument("--json", action="store_true", help="print JSON")
    add_memory_argument(show)
    show.set_defaults(func=_show)

    export = memory_subparsers.add_parser("export", help="export every trace (JSON Lines, or JSON with --json)")
    export.add_argument("--json", action="store_true", help="one JSON document instead of one trace per line")
    export.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of standard output")
    add_memory_argument(export)
    export.set_defaults(func=_export)

    check = memory_subparsers.add_parser("check", help="verify the file and that every stored trace is complete")
    check.add_argument("--json", action="store_true", help="print JSON")
    add_memory_argument(check)
    check.set_defaults(func=_check)

    parser.set_defaults(func=lambda args: parser.print_help() or 2)


def _open(args: argparse.Namespace, *, sound: bool = True) -> EpisodicMemory:
    """The memory to inspect; unless ``sound=False`` (``memory check``, which reports what it finds) a corrupted
    file is refused at once (exit 2) rather than listed or exported in part."""
    path = resolve_memory_path(args)
    # Inspecting must not create a memory; it may migrate one it can write (migrations only add).
    readonly = path.exists() and not os.access(path, os.W_OK)
    memory = EpisodicMemory.open(path, create=False, readonly=readonly)
    if sound:
        try:
            memory.require_sound()
        except BaseException:
            memory.close()
            raise
    return memory


def _time(stamp: float | None) -> str:
    if stamp is None:
        return "-"
    return datetime.fromtimestamp(stamp, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S")


def _ls(args: argparse.Namespace) -> int:
    with _open(args) as memory:
        summaries = memory.episodes(task=args.task)
        if args.json:
            print_json(
                {
                    "memory": str(memory.path),
                    "schema_version": memory.schema_version,
                    "episodes": [
                        {
                            **trace_to_dict(Trace(s.episode))["episode"],
                            "steps": s.step_count,
                            "object_states": s.object_count,
                            "grid_maps": s.grid_map_count,
                            "expectations": s.expectation_count,
                        }
                        for s in summaries
                    ],
                }
            )
            return 0
        if not summaries:
            which = f" of task {args.task}" if args.task else ""
            print(f"no episodes{which} in {memory.path}")
            return 0
        header = ("ID", "TASK", "PROBLEM", "VARIANT", "OUTCOME", "STEPS", "EXPECT", "STARTED (UTC)")
        rows = [
            (
                str(s.episode.id),
                s.episode.task,
                s.episode.problem,
                s.episode.variant or "-",
                s.episode.outcome,
                str(s.step_count),
                str(s.expectation_count),
                _time(s.episode.started),
            )
            for s in summaries
        ]
        widths = [max(len(row[i]) for row in [header, *rows]) for i in range(len(header))]
        for row in [header, *rows]:
            print("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip())
    return 0


def _show(args: argparse.Namespace) -> int:
    with _open(args) as memory:
        if not memory.has_episode(args.id):
            raise UserInputError(f"no episode {args.id} in this memory (see `bt-meta memory ls`)", path=memory.path)
        trace = memory.trace(args.id)
        if args.json:
            print_json(trace_to_dict(trace))
            return 0
        _print_trace(trace, sys.stdout)
    return 0


def _grid(grid_map: GridMap) -> str:
    rows = "/".join("".join("#" if cell else "." for cell in row) for row in grid_map.occupancy)
    where = f"({grid_map.centroid[0]:.3f}, {grid_map.centroid[1]:.3f})"
    image = f", crop {len(grid_map.image)} B PNG" if grid_map.image is not None else ""
    label = " ".join(v for v in (grid_map.object_name, grid_map.colour, grid_map.shape) if v)
    return f"grid-map {label} at {where}: {rows}{image}"


def _print_state(state: State, out: TextIO, indent: str) -> None:
    if state.facts:
        facts = ", ".join(f"{fact[0]}({', '.join(json.dumps(a) for a in fact[1:])})" for fact in state.facts)
        out.write(f"{indent}facts: {facts}\n")
    for item in state.objects:
        pose = " ".join(f"{v:.4f}" for v in item.pose)
        ap = " ".join(f"{v:.4f}" for v in item.ap)
        an = " ".join(f"{v:.4f}" for v in item.an)
        out.write(f"{indent}{item.name}: pose [{pose}] AP [{ap}] (robot base frame) AN [{an}] (object frame)\n")
    for grid_map in state.grid_maps:
        out.write(f"{indent}{_grid(grid_map)}\n")


def _print_trace(trace: Trace, out: TextIO) -> None:
    episode = trace.episode
    out.write(f"episode {episode.id}: task {episode.task}, problem {episode.problem} ({episode.task_file})\n")
    out.write(f"  variant {episode.variant or '-'}, seed {episode.seed}, outcome {episode.outcome}\n")
    out.write(f"  started {_time(episode.started)}, finished {_time(episode.finished)} UTC\n")
    if episode.config:
        out.write(f"  config {json.dumps(episode.config, sort_keys=True)}\n")
    out.write("  initial state\n")
    _print_state(trace.initial, out, "    ")
    for step in trace.steps:
        args = ", ".join(json.dumps(a) for a in step.args)
        failure = f" ({step.failure_kind})" if step.failure_kind else ""
        parent = f"{step.parent_task or '-'}" + (f" (node {step.parent_node})" if step.parent_node else "")
        where = f"node {step.node_id or '-'}, task {parent}"
        out.write(f"  step {step.index}: {step.action}({args}) [{where}] {step.outcome}{failure}\n")
        _print_state(step.state, out, "    ")
    for expectation in trace.expectations:
        pattern = ", ".join(json.dumps(a) for a in expectation.args_pattern)
        grid = "" if expectation.grid_map_index is None else f", grid-map {expectation.grid_map_index}"
        out.write(
            f"  expectation {expectation.id}: after step {expectation.step_index} {expectation.action}({pattern})"
            f" for task {expectation.parent_task or '-'}, {len(expectation.facts)} facts{grid}\n"
        )


def _export(args: argparse.Namespace) -> int:
    with _open(args) as memory:
        if args.output:
            target = Path(args.output)
            if target.is_dir():
                raise UserInputError("is a folder; give a file name to export to", path=target)
            # Write beside the target and rename, so an interrupted export never leaves half a file behind.
            partial = target.with_name(f".{target.name}.partial")
            try:
                with partial.open("w", encoding="utf-8") as handle:
                    count = _write_export(memory, handle, args.json)
                os.replace(partial, target)
            except OSError as error:
                partial.unlink(missing_ok=True)
                raise UserInputError(f"cannot write the export: {error.strerror}", path=target) from None
            except BaseException:
                partial.unlink(missing_ok=True)
                raise
            print(f"exported {count} episodes to {target}", file=sys.stderr)
        else:
            _write_export(memory, json_stream(), args.json)
    return 0


def _write_export(memory: EpisodicMemory, out: TextIO, as_document: bool) -> int:
    count = 0
    if as_document:
        document: dict[str, Any] = {
            "format": EXPORT_FORMAT,
            "schema_version": SCHEMA_VERSION,
            "memory": str(memory.path),
            "episodes": [trace_to_dict(trace) for trace in memory.traces()],
        }
        count = len(document["episodes"])
        json.dump(document, out, indent=2)
        out.write("\n")
        return count
    for trace in memory.traces():
        out.write(json.dumps(trace_to_dict(trace), separators=(",", ":")))
        out.write("\n")
        count += 1
    return count


def _check(args: argparse.Namespace) -> int:
    with _open(args, sound=False) as memory:
        integrity = memory.integrity_check().replace("\n", "; ")
        # A corrupted file may fail the count queries themselves: SQLite's verdict is then the whole report.
        problems = memory.check() if integrity == "ok" else []
        episodes = len(memory.episodes()) if integrity == "ok" else 0
        ok = integrity == "ok" and not problems
        if args.json:
            print_json(
                {
                    "memory": str(memory.path),
                    "ok": ok,
                    "integrity": integrity,
                    "episodes": episodes,
                    "problems": problems,
                }
            )
        else:
            print(f"{memory.path}: integrity {integrity}; {episodes} episodes; {len(problems)} incomplete traces")
            for problem in problems:
                print(f"  {problem}")
    return 0 if ok else 1
