"""``bt-meta campaign generate|run|report``: generated variant populations, run and reported with intervals.

* ``campaign generate FAMILY|--family FILE|--task FILE --problem P --n N --seed S -o DIR [--spec FILE]
  [--scene FILE] [--robot R]`` -- variant scene files with their expected outcomes for the robot, and
  ``DIR/campaign.json``; FAMILY is a shipped family's name (a shortcut for its file in ``trees/families/``)
* ``campaign run DIR [--configurations dual,symbolic,low_level,retry] [--seeds K] [--workers N]
  [--ray ADDRESS|auto] [--perfect-sensing] [--json]`` -- every episode, resumable (``DIR/campaign.sqlite``);
  monitors compare with the state perceived through noisy sensing unless ``--perfect-sensing``
* ``campaign report DIR [-o report.html] [--json]`` -- rates with Wilson 95 % intervals, the confusion table,
  loops, false alarms, second exposure, plots

Exit status: 0 done; 1 an episode crashed; 2 bad input (an unknown family, a family file or success check with an
unknown key, object or predicate, a perturbation or object in a spec, a half-written or other-version campaign
directory, a campaign of another robot, a demonstration that fails, a Ray address that does not answer).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bt_meta.commands._common import print_json
from bt_meta.errors import UserInputError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("campaign", help="generate, run and report populations of scene variants")
    sub = parser.add_subparsers(dest="campaign_command", metavar="COMMAND", parser_class=type(parser))

    generate = sub.add_parser("generate", help="draw variants of a family's scene with expected outcomes")
    generate.add_argument("family", nargs="?", help="a shipped family (letters_A, letters_H, magnetic, housing) or a "
                                                    "family file")
    generate.add_argument("--family", dest="family_file", metavar="FILE",
                          help="family file (with --task: adds demonstrations, perturbations and checks to it)")
    generate.add_argument("--task", metavar="FILE", help="a task file as it stands (with --problem)")
    generate.add_argument("--problem", help="the problem of --task")
    generate.add_argument("--robot", help="robot the labels are for (shipped name or YAML; default the grounding's)")
    generate.add_argument("--n", type=int, default=20, help="number of variants (default 20)")
    generate.add_argument("--seed", type=int, default=0, help="seed of every draw (default 0)")
    generate.add_argument("-o", "--out", required=True, metavar="DIR", help="campaign directory to write")
    generate.add_argument("--spec", help="perturbation spec (default: the family's shipped one)")
    generate.add_argument("--scene", help="scene file to perturb instead of the family's shipped scene")
    generate.add_argument("--json", action="store_true", help="print the manifest")
    generate.set_defaults(func=_generate)

    run = sub.add_parser("run", help="run every (variant, configuration, seed) episode; resumes")
    run.add_argument("dir", help="campaign directory")
    run.add_argument("--configurations", default="dual,symbolic,low_level,retry",
                     help="comma-separated (default dual,symbolic,low_level,retry)")
    run.add_argument("--seeds", type=int, default=1, help="seeds per variant and configuration (default 1)")
    run.add_argument("--workers", type=int, help="local worker processes (default: the core count)")
    run.add_argument("--ray", metavar="ADDRESS", help="run the episodes as Ray tasks: auto (a local instance) or "
                                                     "HOST:PORT of a cluster (pip install 'bt-meta[ray]')")
    run.add_argument("--perfect-sensing", action="store_true",
                     help="monitors compare with the simulator's bookkept state instead of the perceived one "
                          "(noisy camera and pose sensing; the default)")
    run.add_argument("--robot", help="the campaign's robot (checked: a campaign of another robot is refused)")
    run.add_argument("--json", action="store_true", help="print {episodes, summary}")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.set_defaults(func=_run)

    report = sub.add_parser("report", help="rates with Wilson intervals, confusion table, plots")
    report.add_argument("dir", help="campaign directory")
    report.add_argument("-o", "--out", help="HTML report to write (default DIR/report.html)")
    report.add_argument("--json", action="store_true", help="print the summary as JSON")
    report.set_defaults(func=_report)
    parser.set_defaults(func=lambda args: parser.print_help() or 2)


class CampaignInputError(UserInputError):
    """A bad option of ``bt-meta campaign``."""


def _generate(args: argparse.Namespace) -> int:
    from bt_meta.campaign.generator import generate

    if not 1 <= args.n <= 100_000:
        raise CampaignInputError("--n must be between 1 and 100000", "<command line>")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CampaignInputError("-o must be a folder, not a file", out)
    if (out / "campaign.json").exists():
        raise CampaignInputError("already holds a campaign; choose another -o or remove it", out)

    chosen = _family(args)
    bar = None
    if not args.json:
        from tqdm import tqdm

        bar = tqdm(total=args.n, unit="variant", desc="labelling", file=sys.stderr, dynamic_ncols=True)

    def progress(k: int, n: int) -> None:
        if bar is not None:
            bar.update(1)

    try:
        manifest = generate(chosen, args.n, args.seed, out, spec_path=args.spec,
                            scene_path=args.scene if args.task is None else None, progress=progress,
                            robot=args.robot)
    finally:
        if bar is not None:
            bar.close()
    if args.json:
        print_json(manifest)
    else:
        from collections import Counter

        counts = Counter(v["expected"] for v in manifest["variants"])
        print(f"{len(manifest['variants'])} variants of {chosen.name} for the {manifest['robot']} in {out}: "
              + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0


def _family(args: argparse.Namespace) -> object:
    """The family to generate from: a shipped name, a family file, or a task file and problem (+ a family file)."""
    from bt_meta.campaign.families import family, load_family, task_family

    if args.task is not None or args.problem is not None:
        if args.task is None or args.problem is None:
            raise CampaignInputError("--task FILE and --problem P go together", "<command line>")
        if args.family is not None:
            raise CampaignInputError("give a family or --task, not both (--family FILE adds to --task)",
                                     "<command line>")
        return task_family(args.task, args.problem, scene=args.scene, family_file=args.family_file)
    if args.family is not None and args.family_file is not None:
        raise CampaignInputError("give FAMILY or --family FILE, not both", "<command line>")
    name = args.family or args.family_file
    if name is None:
        raise CampaignInputError("give a family (a shipped name or a family file) or --task FILE --problem P",
                                 "<command line>")
    if Path(name).suffix in (".yaml", ".yml"):
        return load_family(name)
    return family(name)


def _configurations(text: str) -> list[str]:
    from bt_meta.configurations import CONFIGURATIONS

    chosen = [c.strip() for c in text.split(",") if c.strip()]
    unknown = [c for c in chosen if c not in CONFIGURATIONS]
    if not chosen or unknown:
        raise CampaignInputError(f"--configurations: unknown {', '.join(unknown) or 'empty list'}; known: "
                                 f"{', '.join(CONFIGURATIONS)}", "<command line>")
    return chosen


def _run(args: argparse.Namespace) -> int:
    from bt_meta.campaign.runner import run_campaign

    configurations = _configurations(args.configurations)
    if not 1 <= args.seeds <= 100:
        raise CampaignInputError("--seeds must be between 1 and 100", "<command line>")
    if args.workers is not None and args.workers < 1:
        raise CampaignInputError("--workers must be at least 1", "<command line>")
    result = run_campaign(args.dir, configurations=configurations, seeds=args.seeds, workers=args.workers,
                          ray_address=args.ray, perfect_sensing=args.perfect_sensing,
                          progress=not args.no_progress, robot=args.robot)
    if args.json:
        print_json(result)
    else:
        from bt_meta.campaign.report import print_summary

        print_summary(result["summary"])
    return 1 if result["summary"]["crashed"] else 0


def _report(args: argparse.Namespace) -> int:
    from bt_meta.campaign.report import build_report

    out = Path(args.out) if args.out else Path(args.dir) / "report.html"
    summary = build_report(args.dir, out)
    if args.json:
        print_json(summary)
    else:
        from bt_meta.campaign.report import print_summary

        print_summary(summary)
        print(f"report: {out}")
    return 0
