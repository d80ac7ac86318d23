"""``bt-meta bench ipc``: our planner on the IPC-2020 total-order HTN problems, beside the published figures.

Offers:

* :func:`register` -- ``bench ipc --path DIR [--domains A,B] [--timeout S] [--limit N] [--json]``
* :func:`run_ipc` -- the measurement as a dict ``{"domains": {NAME: {"solved", "problems", ...}}, ...}``
* :data:`PUBLISHED` -- HyperTensioN's and Lilotane's IPC-2020 total-order scores per domain, with the source

``DIR`` holds one folder per domain as in https://github.com/panda-planner-dev/ipc2020-domains (its
``total-order`` folder, or the repository itself); the files are not shipped (most domains carry no licence).
Each problem is imported from HDDL, planned with the remaining time of ``--timeout`` seconds (import included,
as in the IPC), and every plan found is checked by :mod:`bt_meta.htn.verify`; an invalid plan counts as not
solved and is reported.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.errors import BtMetaError, UserInputError

# IPC-2020 total-order track, "HyperTensioN (IPC)" and "Lilotane" columns of the table in HyperTensioN's
# docs/IPC.md (https://github.com/Maumagnaguagno/HyperTensioN/blob/master/docs/IPC.md), which reports the
# organisers' fixed results (http://gki.informatik.uni-freiburg.de/competition/results-fixed.pdf). They are IPC
# scores: a solved problem scores up to 1 by plan quality, so a whole number is the coverage when every plan
# scored 1; fractions are scores, not counts. Problems per domain as used in the IPC (Robot 20, Woodworking 30).
PUBLISHED_SOURCE = ("IPC 2020 total-order scores, HyperTensioN docs/IPC.md table (organisers' results-fixed.pdf); "
                    "timeout 1800 s per problem on the IPC machines")
PUBLISHED: dict[str, tuple[int, float, float]] = {  # domain: (problems, HyperTensioN IPC, Lilotane)
    "AssemblyHierarchical": (30, 3, 5),
    "Barman-BDI": (20, 20, 16),
    "Blocksworld-GTOHP": (30, 16, 22.1),
    "Blocksworld-HPDDL": (30, 30, 1),
    "Childsnack": (30, 30, 29),
    "Depots": (30, 24, 23.4),
    "Elevator-Learned-ECAI-16": (147, 147, 147),
    "Entertainment": (12, 0, 4.6),
    "Factories-simple": (20, 3, 4),
    "Freecell-Learned-ECAI-16": (60, 0, 7.7),
    "Hiking": (30, 25, 21.3),
    "Logistics-Learned-ECAI-16": (80, 22, 43.2),
    "Minecraft-Player": (20, 5, 1),
    "Minecraft-Regular": (59, 57.1, 29.2),
    "Monroe-Fully-Observable": (20, 0, 20),
    "Monroe-Partially-Observable": (20, 0, 20),
    "Multiarm-Blocksworld": (74, 8, 4),
    "Robot": (20, 20, 11),
    "Rover-GTOHP": (30, 30, 21.3),
    "Satellite-GTOHP": (20, 20, 15),
    "Snake": (20, 20, 17.1),
    "Towers": (20, 17, 10),
    "Transport": (40, 40, 35),
    "Woodworking": (30, 7, 30),
}


def _domain_root(path: Path) -> Path:
    if (path / "total-order").is_dir():
        return path / "total-order"
    return path


def problem_files(domain_dir: Path) -> list[Path]:
    """The problem files of one IPC domain folder, in name order (domain files and subfolders left out)."""
    found = [*domain_dir.glob("*.hddl"), *domain_dir.glob("*.pddl")]  # IPC 2023 names some problems .pddl
    return sorted(p for p in found if p.name not in ("domain.hddl", "domain.pddl")
                  and not p.name.endswith(("-domain.hddl", "-domain.pddl")) and p.is_file())


def _run_problem(problem_path: Path, timeout: float) -> dict[str, Any]:
    from bt_meta.htn import plan
    from bt_meta.htn.hddl import find_domain_file, load_hddl
    from bt_meta.htn.verify import verify_plan

    started = time.perf_counter()
    try:
        taskfile = load_hddl(find_domain_file(problem_path), [problem_path])
    except BtMetaError as exc:
        return {"problem": problem_path.name, "status": "import_error", "message": str(exc),
                "seconds": round(time.perf_counter() - started, 3)}
    imported = time.perf_counter() - started
    problem = next(iter(taskfile.problems.values()))
    remaining = timeout - imported
    if remaining <= 0:
        return {"problem": problem_path.name, "status": "budget_exhausted", "seconds": round(imported, 3),
                "import_seconds": round(imported, 3)}
    result = plan(taskfile.domain, problem, max_seconds=remaining)
    seconds = time.perf_counter() - started
    row: dict[str, Any] = {"problem": problem_path.name, "status": result.status, "seconds": round(seconds, 3),
                           "import_seconds": round(imported, 3), "expansions": result.stats.get("expansions")}
    if result.ok and result.tree is not None:
        tree = result.tree.to_dict()
        verdict = verify_plan(taskfile.domain, problem, [a.as_list() for a in result.plan], tree)
        row["plan_length"] = len(result.plan)
        row["verified"] = verdict.ok
        if not verdict.ok:
            row["status"] = "invalid"
            row["errors"] = verdict.errors[:3]
    elif result.status == "no_plan":
        row["message"] = result.message
    return row


def run_ipc(path: str | Path, domains: list[str] | None = None, *, timeout: float = 60.0,
            limit: int | None = None, progress: Any = None) -> dict[str, Any]:
    root = _domain_root(Path(path))
    if not root.is_dir():
        raise UserInputError(f"--path {path}: not a folder (expected the IPC-2020 domains, one folder each)")
    available = sorted(d.name for d in root.iterdir() if d.is_dir() and problem_files(d))
    if not available:
        raise UserInputError(f"--path {path}: no domain folders with .hddl problems found")
    chosen = available
    if domains:
        by_key = {name.casefold(): name for name in available}
        chosen = []
        for wanted in domains:
            if wanted.casefold() not in by_key:
                raise UserInputError(f"--domains: no domain {wanted!r} under {root} (found: {', '.join(available)})")
            chosen.append(by_key[wanted.casefold()])
    report: dict[str, Any] = {"path": str(root), "timeout": timeout, "limit": limit,
                              "published_source": PUBLISHED_SOURCE, "domains": {}}
    for name in chosen:
        files = problem_files(root / name)
        if limit is not None:
            files = files[:limit]
        rows = []
        for problem_path in files:
            row = _run_problem(problem_path, timeout)
            rows.append(row)
            if progress is not None:
                progress(name, row)
        solved = [r for r in rows if r["status"] == "success"]
        published = PUBLISHED.get(name)
        report["domains"][name] = {
            "solved": len(solved),
            "problems": len(rows),
            "invalid": sum(1 for r in rows if r["status"] == "invalid"),
            "no_plan": sum(1 for r in rows if r["status"] == "no_plan"),
            "budget_exhausted": sum(1 for r in rows if r["status"] == "budget_exhausted"),
            "import_errors": sum(1 for r in rows if r["status"] == "import_error"),
            "mean_seconds_solved": round(sum(r["seconds"] for r in solved) / len(solved), 3) if solved else None,
            "mean_plan_length": round(sum(r["plan_length"] for r in solved) / len(solved), 1) if solved else None,
            "ipc_problems": published[0] if published else None,
            "hypertension_ipc2020": published[1] if published else None,
            "lilotane_ipc2020": published[2] if published else None,
            "runs": rows,
        }
    return report


def _table(report: dict[str, Any]) -> list[str]:
    lines = [f"IPC-2020 total-order problems under {report['path']}: timeout {report['timeout']:g} s per problem"
             + (f", first {report['limit']} problems per domain" if report["limit"] else ""),
             f"published: {report['published_source']}",
             f"{'domain':<30} {'solved':>9} {'invalid':>7} {'no plan':>7} {'mean s':>8} {'mean len':>9} "
             f"{'HyperTensioN':>12} {'Lilotane':>8}"]
    for name, row in report["domains"].items():
        solved = f"{row['solved']}/{row['problems']}"
        mean_s = f"{row['mean_seconds_solved']:.2f}" if row["mean_seconds_solved"] is not None else "-"
        mean_len = f"{row['mean_plan_length']:.1f}" if row["mean_plan_length"] is not None else "-"
        hyper = f"{row['hypertension_ipc2020']:g}/{row['ipc_problems']}" if row["ipc_problems"] else "-"
        lilo = f"{row['lilotane_ipc2020']:g}" if row["ipc_problems"] else "-"
        lines.append(f"{name:<30} {solved:>9} {row['invalid']:>7} {row['no_plan']:>7} {mean_s:>8} {mean_len:>9} "
                     f"{hyper:>12} {lilo:>8}")
    return lines


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("ipc", help="our planner on the IPC-2020 total-order HDDL problems",
                                   description="Coverage, time and plan length per IPC-2020 total-order domain, "
                                               "every plan verified, next to HyperTensioN's and Lilotane's "
                                               "published IPC-2020 scores.")
    parser.add_argument("--path", required=True, help="folder with one folder per domain (ipc2020-domains)")
    parser.add_argument("--domains", help="comma-separated domain folder names (default: all found)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per problem, import included")
    parser.add_argument("--limit", type=int, default=None, help="only the first N problems of each domain")
    parser.add_argument("--json", action="store_true", help='print {"domains": {NAME: {"solved", ...}}, ...}')
    parser.set_defaults(func=_handle)


def _handle(args: argparse.Namespace) -> int:
    import sys

    if args.timeout <= 0:
        raise UserInputError("--timeout must be positive")
    if args.limit is not None and args.limit < 1:
        raise UserInputError("--limit must be at least 1")
    domains = [d.strip() for d in args.domains.split(",") if d.strip()] if args.domains else None

    def progress(domain: str, row: dict[str, Any]) -> None:
        print(f"{domain} {row['problem']}: {row['status']} {row['seconds']:.2f} s", file=sys.stderr, flush=True)

    report = run_ipc(args.path, domains, timeout=args.timeout, limit=args.limit, progress=progress)
    if args.json:
        print_json(report)
    else:
        print("\n".join(_table(report)))
    invalid = sum(d["invalid"] for d in report["domains"].values())
    return 1 if invalid else 0
