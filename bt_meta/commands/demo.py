"""``bt-meta demo [--out DIR] [--seed S] [--quick] [--robot R] [--json]``: the paper's scenario end to end.

On the memory ``DIR/memory.sqlite`` (new when absent, reused when present) it records the demonstrations, runs the
variants on the simulator with monitors and the meta-reasoner, runs each variant again to show the learned
refinements used with zero repair attempts, and writes ``DIR/report.html`` and ``DIR/summary.json``
(the bt_meta.demo package). Headless; a few minutes on 2 cores (``--quick``: fewer seeds and one variant per family).
``--robot`` runs it all on another robot (scene coordinates follow the robot's workcell offset); a memory is
recorded on one robot, so DIR must not hold one from another. ``--scene`` is refused: the demo builds the
scenes of its three families.

Exit status: 0 when the demo completed -- every demonstration is in memory and every variant run ran to an
outcome, repaired or not (a variant that is not repaired is reported in the summary and the report, not hidden);
1 when a step of the demo itself failed (a demonstration could not be recorded, a run crashed); 2 bad
input (e.g. ``--out`` names a file).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bt_meta.commands._common import print_json
from bt_meta.commands._world_args import add_world_arguments, world_options
from bt_meta.errors import UserInputError
from bt_meta.user_files import make_output_folder

__all__ = ["DemoInputError", "register", "run"]


class DemoInputError(UserInputError):
    """A demo option that cannot be used as given."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo", help="record demonstrations, repair the variants, reuse the repairs; writes DIR/report.html",
        description=__doc__.split("\n\n", 1)[1].replace("``", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="demo-output", metavar="DIR",
                        help="output folder: memory.sqlite, report.html, summary.json (default demo-output)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    parser.add_argument("--quick", action="store_true", help="fewer demonstrations and one variant per family")
    add_world_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print summary.json instead of the progress")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bt_meta.demo.runner import run_demo
    from bt_meta.runs.capture import Progress

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise DemoInputError("--out must be a folder, not a file", path=out)
    if args.scene:
        raise DemoInputError("--scene: the demo builds the scenes of its three families (letters, magnetic "
                             "attach, housing); run a scene of one's own with `bt-meta run TASK --scene FILE`",
                             path="<command line>")
    robot = world_options(args)["robot"]
    name = robot.name if robot is not None else "baxter"
    recorded = _recorded_robot(out)
    if recorded is not None and recorded != name:
        raise DemoInputError(f"--out {out} holds a memory recorded on the {recorded}, not the {name}: give "
                             "another --out folder", path=out / "summary.json")
    make_output_folder(out, "--out folder", DemoInputError)  # before the work: the user asked for this folder
    progress = Progress(sys.stdout, quiet=args.json)
    result = run_demo(out, seed=args.seed, quick=args.quick, progress=progress, robot=robot)
    summary = result.summary()
    if args.json:
        print_json(summary)
    else:
        totals = summary["totals"]
        progress.line(
            f"\ndemo {'completed' if result.completed else 'INCOMPLETE'} in {result.seconds:.1f} s: first pass "
            f"{totals['first_pass_success']}/{totals['variants']} succeeded ({totals['first_pass_repaired']} repaired,"
            f" {totals['first_pass_attempts']} attempts); second pass {totals['second_pass_success']}/"
            f"{totals['variants']} succeeded, {totals['second_pass_zero_attempts']} with zero attempts, "
            f"{totals['second_pass_using_refinements']} with a learned refinement; "
            f"{len(summary['refinements'])} refinement(s) in memory")
        for crash in result.crashed:
            progress.line(f"  crashed: {crash}")
        progress.line(f"report: {out / 'report.html'}\nsummary: {out / 'summary.json'}")
    return 0 if result.completed else 1


def _recorded_robot(out: Path) -> str | None:
    """The robot a previous demo in ``out`` ran on (its summary.json; a summary without one: the Baxter)."""
    import json

    summary = out / "summary.json"
    if not (out / "memory.sqlite").exists() or not summary.is_file():
        return None
    try:
        return str(json.loads(summary.read_text(encoding="utf-8")).get("robot", "baxter"))
    except (OSError, ValueError):
        return None
