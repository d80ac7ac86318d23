"""``bt-meta experiment ros2-compare``: the proof by difference of issue 28 -- every variant run in-process and
through ROS 2 against the served simulator in another process ends the same.

Each way has a fresh episodic memory of its own, filled as ``bt-meta demo`` fills it: first the demo's
demonstrations are recorded (``bt-meta record``; through ROS 2 with ``--world ros2``), then the variants run one
after the other with repairs (``bt-meta run --repair --json``), so refinements learned on one variant are used by
the next, in the same order both ways. The variants: the demo's seven (:func:`bt_meta.demo.scenario.variants`) and
``--generated N`` drawn by ``bt-meta campaign generate`` from the shipped families (spread over ``--families``
round-robin), each a scene file with its ``perturbed`` variant. ``--quick``: one demonstration per problem and
the demo's quick variants. Every command is a fresh process; a ROS 2 one runs
against a fresh ``bt-meta sim serve --ros2`` of the same scene, variant, seed and start pose, in a loopback-only
network namespace (:class:`~bt_meta.bench.ros2.Served`).

A variant is **alike** when both ways end with the same status, the same failure kinds in order, the same number of
repair attempts, the same learned refinement (its subtasks, or none) and the same refinements used, and every
object's final position within :data:`POSE_TOLERANCE` of the other's. Ticks are shown and counted but are not part of
the criterion (the issue's); a demonstration is alike when both recordings succeed with the same ticks and steps.
Exit status 0 when every variant and demonstration is alike, 1 otherwise; a command that crashes or hangs is a row
that is not alike (with its error), never the end of the comparison. Needs what ``bench ros2`` needs: the ``[ros2]``
extra and the right to make a network namespace.

Offers:

* :func:`register` -- ``bt-meta experiment ros2-compare [--generated N] [--families F,...] [--variants L,...]
  [--quick] [--seed S] [--out DIR] [--json]``
* :func:`run` -- the comparison as a dict (``demonstrations``, ``variants``, ``summary``)
* :func:`compare` -- one variant's two reports compared
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bt_meta.commands._common import print_json
from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["POSE_TOLERANCE", "compare", "register", "run"]

POSE_TOLERANCE = 1e-3
"""m: the largest difference of an object's final position both ways that still counts as the same."""
BT_META = [sys.executable, "-m", "bt_meta.cli"]
GENERATED_FAMILIES = ("letters_A", "magnetic", "housing")
_TIMEOUT = 900.0
"""s one command may take before the comparison gives up on it."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("ros2-compare",
                                   help="the demo's variants and generated ones, in-process vs through ROS 2")
    parser.add_argument("--generated", type=int, default=20,
                        help="generated variants (campaign generate) besides the demo's (0-200, default 20)")
    parser.add_argument("--families", default=",".join(GENERATED_FAMILIES),
                        help="shipped families the generated variants are drawn from, round-robin "
                             f"(default {','.join(GENERATED_FAMILIES)})")
    parser.add_argument("--variants", default=None,
                        help="only these of the demo's variants, e.g. magnetic/active_on_side (default all; "
                             "'none' for none)")
    parser.add_argument("--quick", action="store_true",
                        help="one demonstration per problem (its first seed) and the demo's quick variants (one "
                             "per family)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the demo's runs and the generated draws")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="keep the memories, generated variants, logs and comparison.json here (default: a "
                             "temporary folder)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from bt_meta.campaign.families import shipped_families
    from bt_meta.demo.scenario import variants

    if not 0 <= args.generated <= 200:
        raise UserInputError("--generated must be between 0 and 200", "--generated")
    families = [f for f in args.families.split(",") if f]
    unknown = sorted(set(families) - set(shipped_families()))
    if unknown or (args.generated and not families):
        raise UserInputError(f"--families: unknown {', '.join(unknown) or 'none given'}; shipped: "
                             f"{', '.join(shipped_families())}", "--families")
    known = [v.label for v in variants(args.seed, quick=args.quick)]
    chosen = None
    if args.variants is not None:
        chosen = [] if args.variants == "none" else [v for v in args.variants.split(",") if v]
        wrong = sorted(set(chosen) - set(known))
        if wrong:
            raise UserInputError(f"--variants: no demo variant {', '.join(wrong)}; known: {', '.join(known)}",
                                 "--variants")
    if args.out is not None and Path(args.out).exists() and any(Path(args.out).iterdir()):
        raise UserInputError(f"--out {args.out} is not empty: the comparison needs fresh memories", "--out")
    result = run(generated=args.generated, families=families, demo_variants=chosen, quick=args.quick,
                 seed=args.seed, out=args.out, progress=not args.json)
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0 if result["summary"]["alike"] == result["summary"]["variants"] and \
        result["summary"]["demonstrations_alike"] == result["summary"]["demonstrations"] else 1


# -- the runs -------------------------------------------------------------------------------------------------------


def _runs(generated: int, families: list[str], demo_variants: list[str] | None, quick: bool, seed: int,
          folder: Path) -> list[dict[str, Any]]:
    """Every variant to compare: ``{label, task_file, problem, scene, variant, seed, expected}``, demo ones first."""
    from bt_meta.demo.scenario import variants
    from bt_meta.resources import trees_dir

    out = []
    for v in variants(seed, quick=quick):
        if demo_variants is None or v.label in demo_variants:
            out.append({"label": v.label, "task_file": str(trees_dir() / v.task_file), "problem": v.problem,
                        "scene": None, "variant": v.variant, "seed": v.seed, "expected": None})
    if generated:
        from bt_meta.campaign.generator import VARIANT_NAME, generate

        counts = {f: generated // len(families) + (k < generated % len(families)) for k, f in enumerate(families)}
        for name, n in counts.items():
            if n == 0:
                continue
            manifest = generate(name, n, seed, folder / "generated" / name)
            for entry in manifest["variants"]:
                out.append({"label": f"generated/{entry['name']}", "task_file": manifest["task_file"],
                            "problem": manifest["problem"],
                            "scene": str(folder / "generated" / name / entry["file"]), "variant": VARIANT_NAME,
                            "seed": seed, "expected": entry["expected"]})
    return out


def _serve_arguments(task_file: str, problem: str, scene: str | None, variant: str | None, seed: int) -> list[str]:
    """``sim serve`` options building what ``bt-meta run`` builds for the same arguments (robot, start pose)."""
    from bt_meta.htn import load_task_file
    from bt_meta.world.simulation.sim_world import load_grounding

    loaded = load_task_file(task_file)
    grounding = load_grounding(loaded.domain.name, task_file, None)
    setup = grounding.problem(loaded.problem(problem).name)
    robot = str(setup.get("robot") or "baxter")
    out = ["--robot", robot, "--scene", scene or str(setup["scene"]), "--seed", str(seed)]
    variant = variant or setup.get("variant")
    if variant:
        out += ["--variant", str(variant)]
    for joint, value in grounding.start_pose(robot).items():
        out += ["--joint", f"{joint}={value}"]
    return out


class _Ways:
    """Runs a bt-meta command in-process and through ROS 2 (a fresh served simulator each time)."""

    def __init__(self, folder: Path, domain: int) -> None:
        self.folder = folder
        self.domain = domain
        self.count = 0
        self.memory = {"in_process": folder / "in_process.sqlite", "ros2": folder / "ros2.sqlite"}

    def both(self, command: list[str], serve: list[str]) -> dict[str, Any]:
        from bt_meta.bench.ros2 import Served

        self.count += 1
        out: dict[str, Any] = {}
        out["in_process"] = self._result([*BT_META, *command, "--memory", str(self.memory["in_process"]), "--json"])
        try:
            served = Served(serve, self.domain, self.folder / "logs" / f"serve-{self.count:03d}.log")
        except BtMetaError as error:  # the served simulator did not start: this row fails, the others still run
            out["ros2"] = {"error": str(error).splitlines()[0][:300]}
            return out
        try:
            out["ros2"] = self._result(served.command(*BT_META, *command, "--memory", str(self.memory["ros2"]),
                                                      "--world", "ros2", "--json"), served.env)
        finally:
            served.stop()
        return out

    @staticmethod
    def _result(argv: list[str], env: dict[str, str] | None = None) -> dict[str, Any]:
        """The command's ``--json`` report, or ``{"error": ...}`` when it crashed, refused or hung."""
        try:
            done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=_TIMEOUT, check=False)
        except subprocess.TimeoutExpired:
            return {"error": f"no result within {_TIMEOUT:g} s"}
        try:
            report = json.loads(done.stdout)
        except json.JSONDecodeError:
            report = None
        if done.returncode not in (0, 1) or not isinstance(report, dict):
            last = done.stderr.strip().splitlines()[-1:] or [""]
            return {"error": f"exit {done.returncode}: {last[0][:300]}"}
        return report


def run(*, generated: int = 20, families: list[str] | tuple[str, ...] = GENERATED_FAMILIES,
        demo_variants: list[str] | None = None, quick: bool = False, seed: int = 0, out: str | Path | None = None,
        progress: bool = False) -> dict[str, Any]:
    """The comparison (see the module docstring); ``demo_variants``: labels of the demo's variants (``None``: all)."""
    from bt_meta.bench.ros2 import check_namespaces
    from bt_meta.demo.scenario import demonstrations

    check_namespaces("experiment ros2-compare")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bt-meta-ros2-compare-") as scratch:
        folder = Path(out) if out is not None else Path(scratch)
        (folder / "logs").mkdir(parents=True, exist_ok=True)
        runs = _runs(generated, list(families), demo_variants, quick, seed, folder)
        task_files = {Path(r["task_file"]).name for r in runs}
        demos = [d for d in demonstrations(seed, quick=quick) if d.task_file in task_files]
        if quick:  # one per problem: without the demo's start-pose noise, more seeds mostly repeat the first
            firsts: dict[tuple[str, str], Any] = {}
            for demo in demos:
                firsts.setdefault((demo.task_file, demo.problem), demo)
            demos = list(firsts.values())
        ways = _Ways(folder, 100 + (seed + int(time.time())) % 100)
        result: dict[str, Any] = {"seed": seed, "quick": quick, "generated": generated, "families": list(families),
                                  "pose_tolerance_m": POSE_TOLERANCE, "demonstrations": [], "variants": []}
        for demo in demos:
            task_file = _task_path(demo.task_file)
            both = ways.both(["record", task_file, "--problem", demo.problem, "--seed", str(demo.seed)],
                             _serve_arguments(task_file, demo.problem, None, None, demo.seed))
            row = _compare_record(f"{demo.task_file}:{demo.problem} seed {demo.seed}", both)
            result["demonstrations"].append(row)
            if progress:
                print(f"record {row['label']}: {'alike' if row['alike'] else 'DIFFERENT: ' + row['why']}",
                      file=sys.stderr, flush=True)
        for entry in runs:
            command = ["run", entry["task_file"], "--problem", entry["problem"], "--variant", entry["variant"],
                       "--seed", str(entry["seed"]), "--repair"]
            if entry["scene"]:
                command += ["--scene", entry["scene"]]
            both = ways.both(command, _serve_arguments(entry["task_file"], entry["problem"], entry["scene"],
                                                       entry["variant"], entry["seed"]))
            row = {"label": entry["label"], "expected": entry["expected"], **compare(both["in_process"], both["ros2"])}
            result["variants"].append(row)
            if progress:
                print(f"run {row['label']}: {row['in_process']['status']} / {row['ros2']['status']}, "
                      f"{'alike' if row['alike'] else 'DIFFERENT: ' + row['why']}", file=sys.stderr, flush=True)
    rows = result["variants"]
    result["summary"] = {
        "variants": len(rows), "alike": sum(r["alike"] for r in rows),
        "demo_variants": sum(not r["label"].startswith("generated/") for r in rows),
        "generated_variants": sum(r["label"].startswith("generated/") for r in rows),
        "same_ticks": sum(r["same_ticks"] for r in rows),
        "repaired": sum(bool(r["in_process"]["attempts"]) and r["in_process"]["status"] == "SUCCESS" for r in rows),
        "success": sum(r["in_process"]["status"] == "SUCCESS" for r in rows),
        "largest_pose_difference_mm": max((r["pose_difference_mm"] for r in rows
                                           if r["pose_difference_mm"] is not None), default=None),
        "demonstrations": len(result["demonstrations"]),
        "demonstrations_alike": sum(r["alike"] for r in result["demonstrations"]),
        "seconds": round(time.perf_counter() - started, 1),
    }
    if out is not None:
        (Path(out) / "comparison.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return result


def _task_path(name: str) -> str:
    from bt_meta.resources import trees_dir

    return str(trees_dir() / name)


# -- comparing ------------------------------------------------------------------------------------------------------


def _outcome(report: dict[str, Any]) -> dict[str, Any]:
    if "error" in report:
        return {"status": "ERROR", "error": report["error"], "failure_kinds": [], "attempts": 0, "refinement": None,
                "refinements_used": [], "ticks": None}
    saved = report.get("refinement_saved") or {}
    return {"status": report.get("status"), "failure_kinds": [f.get("kind") for f in report.get("failures") or []],
            "attempts": len(report.get("attempts") or []),
            "refinement": list(saved["subtasks"]) if saved.get("subtasks") else None,
            "refinements_used": list(report.get("refinements_used") or []), "ticks": report.get("ticks")}


def _pose_difference(first: dict[str, Any], second: dict[str, Any]) -> tuple[float | None, str | None]:
    """The largest distance (m) between an object's final positions both ways and that object, or why there is
    none (``None`` and the reason)."""
    a, b = first.get("objects") or {}, second.get("objects") or {}
    if set(a) != set(b):
        return None, f"objects differ: {sorted(set(a) ^ set(b))}"
    if not a:
        return 0.0, None
    distances = {n: float(np.linalg.norm(np.subtract(a[n]["pose"][:3], b[n]["pose"][:3]))) for n in a}
    worst = max(distances, key=distances.__getitem__)
    return distances[worst], worst


def compare(in_process: dict[str, Any], ros2: dict[str, Any]) -> dict[str, Any]:
    """One variant's ``run --repair --json`` reports, in-process and through ROS 2, compared (``alike``, ``why``)."""
    local, ros = _outcome(in_process), _outcome(ros2)
    reasons = [f"{key}: {local[key]} / {ros[key]}" for key in
               ("status", "failure_kinds", "attempts", "refinements_used") if local[key] != ros[key]]
    if local["refinement"] != ros["refinement"]:
        reasons.append("learned refinements differ")
    for which, outcome in (("in-process", local), ("ROS 2", ros)):
        if "error" in outcome:
            reasons.append(f"{which} run failed: {outcome['error']}")
    worst = which = None
    if "error" not in local and "error" not in ros:
        worst, which = _pose_difference(in_process, ros2)
        if worst is None:
            reasons.append(str(which))
            which = None
        elif worst >= POSE_TOLERANCE:
            reasons.append(f"object poses differ by {worst * 1000:.3f} mm ({which})")
    return {"alike": not reasons, "why": "; ".join(reasons), "in_process": local, "ros2": ros,
            "same_ticks": local["ticks"] is not None and local["ticks"] == ros["ticks"],
            "pose_difference_mm": None if worst is None else round(worst * 1000, 6), "pose_difference_object": which}


def _compare_record(label: str, both: dict[str, Any]) -> dict[str, Any]:
    rows = {}
    for way in ("in_process", "ros2"):
        report = both[way]
        rows[way] = {"recorded": "episode_id" in report, "ticks": report.get("ticks"),
                     "steps": len(report.get("steps") or []), "error": report.get("error")}
    local, ros = rows["in_process"], rows["ros2"]
    reasons = [f"{key}: {local[key]} / {ros[key]}" for key in ("recorded", "ticks", "steps") if local[key] != ros[key]]
    if not local["recorded"]:
        reasons.append(f"in-process recording failed: {local['error']}")
    return {"label": label, "alike": not reasons, "why": "; ".join(reasons), **rows}


def _print(result: dict[str, Any]) -> None:
    s = result["summary"]
    print(f"ROS 2 proof by difference: {s['demo_variants']} demo variant(s) + {s['generated_variants']} generated "
          f"(seed {result['seed']}), in-process vs through ROS 2 against the served simulator")
    print(f"demonstrations recorded both ways: {s['demonstrations_alike']}/{s['demonstrations']} alike")
    header = f"{'variant':<40} {'status in-process / ROS 2':<26} {'kinds':<42} {'att':>5} {'refinement':<10} " \
             f"{'ticks':>11} {'pose mm':>9}  result"
    print(header)
    print("-" * len(header))
    for r in result["variants"]:
        a, b = r["in_process"], r["ros2"]
        kinds = ",".join(a["failure_kinds"]) or "-"
        if a["failure_kinds"] != b["failure_kinds"]:
            kinds += " / " + (",".join(b["failure_kinds"]) or "-")
        attempts = f"{a['attempts']}" if a["attempts"] == b["attempts"] else f"{a['attempts']}/{b['attempts']}"
        learned = ("same" if a["refinement"] == b["refinement"] else "differs") if (a["refinement"] or
                                                                                     b["refinement"]) else "-"
        ticks = f"{a['ticks']}" if a["ticks"] == b["ticks"] else f"{a['ticks']}/{b['ticks']}"
        pose = "-" if r["pose_difference_mm"] is None else f"{r['pose_difference_mm']:.4f}"
        verdict = "alike" if r["alike"] else f"DIFFERENT ({r['why']})"
        print(f"{r['label']:<40} {a['status'] + ' / ' + b['status']:<26} {kinds[:42]:<42} {attempts:>5} "
              f"{learned:<10} {ticks:>11} {pose:>9}  {verdict}")
    largest = s["largest_pose_difference_mm"]
    print(f"alike: {s['alike']}/{s['variants']} variants (status, failure kinds, attempts, learned and used "
          f"refinements, object positions within {result['pose_tolerance_m'] * 1000:g} mm); same ticks "
          f"{s['same_ticks']}/{s['variants']}; largest position difference "
          f"{'-' if largest is None else f'{largest:.6f}'} mm; in-process {s['success']} succeeded, "
          f"{s['repaired']} of them repaired; {s['seconds']:.0f} s")

