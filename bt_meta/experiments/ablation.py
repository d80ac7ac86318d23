"""``bt-meta experiment ablation``: which expectations and repairs make the variants succeed (issue 6, item 5).

The paper's claim, checked in the simulator: expectations that use both symbolic and low-level information repair
more failures than either alone. The letters (A with substituted blocks), magnetic-attach (variant poses of the
active part) and housing (upside down) variants are run under four plugin configurations
(:mod:`bt_meta.configurations`):

* ``dual`` -- symbolic + low-level expectations (grid-maps, keypoints), every repair plugin
* ``symbolic`` -- symbolic expectations only; object substitution matches symbolically
* ``low_level`` -- grid-map and keypoint expectations only
* ``retry`` -- every expectation, the retry / replan baseline as the only repair plugin

First the demonstrations are recorded into a temporary memory (as ``bt-meta demo`` records them). Then, per seed
(the start poses get seeded noise; the repair plugins' sampling takes the seed), every variant runs once per
configuration with monitors and the meta-reasoner, independently: no learned refinement is used or saved. A run
*succeeds* when it ends verified; success rates get Wilson 95 % intervals, attempts and seconds per run the mean
with a seeded percentile-bootstrap 95 % interval (2,000 resamples).

Offers:

* :func:`register` -- ``bt-meta experiment ablation [--seeds N] [--seed S] [--families F,...]
  [--configurations C,...] [--variants V,...] [--json]``; with ``--generated N [--out DIR] [--workers W]
  [--ray ADDRESS] [--perfect-sensing] [--robot R]`` the experiment runs as campaigns of generated variants instead,
  labelled for and run on the robot
  (:mod:`bt_meta.campaign.ablation`)
* :func:`run` -- the experiment; returns ``{"configurations", "families", "rows", "runs", ...}``
* :func:`wilson` -- Wilson score interval of a proportion
* :func:`bootstrap_mean` -- seeded percentile-bootstrap interval of a mean
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.commands._world_args import add_world_arguments, world_options
from bt_meta.errors import UserInputError

__all__ = ["bootstrap_mean", "register", "run", "wilson"]

Z95 = 1.959963984540054


class AblationInputError(UserInputError):
    """A bad option of ``bt-meta experiment ablation``."""


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of ``successes`` out of ``n`` (``(0, 1)`` when ``n`` is 0)."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denominator = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def bootstrap_mean(values: Sequence[float], *, seed: int = 0, resamples: int = 2000,
                   level: float = 0.95) -> tuple[float, float, float]:
    """(mean, low, high): the mean and its percentile-bootstrap interval (seeded; one value gives a point)."""
    import numpy as np

    data = np.asarray(values, dtype=float)
    if data.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(data.mean())
    if data.size == 1 or np.all(data == data[0]):
        return mean, mean, mean
    rng = np.random.default_rng(seed)
    means = data[rng.integers(0, data.size, size=(resamples, data.size))].mean(axis=1)
    tail = (1.0 - level) / 2.0
    return mean, float(np.quantile(means, tail)), float(np.quantile(means, 1.0 - tail))


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "ablation", help="repair success, attempts and time of the variants under four plugin configurations")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per variant and configuration (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--families", default="letters,magnetic,housing",
                        help="comma-separated variant families (default letters,magnetic,housing)")
    parser.add_argument("--configurations", default="dual,symbolic,low_level,retry",
                        help="comma-separated configurations (default dual,symbolic,low_level,retry; also "
                             "dual_kp_monitor)")
    parser.add_argument("--variants", help="comma-separated variant names to run (default: all of the families)")
    parser.add_argument("--generated", type=int, metavar="N",
                        help="run as campaigns instead: N generated variants per family (letters_A, letters_H, "
                             "magnetic, housing) on the perceived world; see bt_meta.campaign.ablation")
    parser.add_argument("--out", metavar="DIR", help="with --generated: the campaign directories (default "
                                                    "ablation-campaigns; resumed when present)")
    parser.add_argument("--workers", type=int, help="with --generated: local worker processes")
    parser.add_argument("--ray", metavar="ADDRESS", help="with --generated: run the episodes on Ray")
    parser.add_argument("--perfect-sensing", action="store_true",
                        help="with --generated: compare with the bookkept state instead of the perceived one")
    add_world_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _choices(text: str, known: Sequence[str], option: str) -> tuple[str, ...]:
    chosen = tuple(part.strip() for part in text.split(",") if part.strip())
    unknown = [c for c in chosen if c not in known]
    if not chosen or unknown:
        raise AblationInputError(f"{option}: unknown {', '.join(unknown) or 'empty list'}; known: {', '.join(known)}",
                                 path="<command line>")
    return chosen


def _main(args: argparse.Namespace) -> int:
    from bt_meta.configurations import CONFIGURATIONS
    from bt_meta.demo.scenario import FAMILIES, variants

    if not 1 <= args.seeds <= 50:
        raise AblationInputError("--seeds must be between 1 and 50", path="<command line>")
    options = world_options(args)
    if options["scene"] is not None:
        raise AblationInputError("--scene: the ablation runs its families' own scenes and variants (letters, "
                                 "magnetic attach, housing); run a scene of one's own with "
                                 "`bt-meta run TASK --scene FILE`", path="<command line>")
    if args.generated is not None:
        return _generated(args)
    families = _choices(args.families, list(FAMILIES), "--families")
    configurations = _choices(args.configurations, list(CONFIGURATIONS), "--configurations")
    only = None
    if args.variants:
        only = _choices(args.variants, [v.variant for v in variants(0, families=families)], "--variants")
    result = run(seeds=args.seeds, seed=args.seed, families=families, configurations=configurations, only=only,
                 echo=not args.json, robot=options["robot"])
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0 if not result["crashed"] else 1


def _generated(args: argparse.Namespace) -> int:
    """``--generated N``: the ablation as campaigns (:mod:`bt_meta.campaign.ablation`)."""
    from bt_meta.campaign.ablation import ABLATION_FAMILIES, run_ablation

    if args.generated < 1:
        raise AblationInputError("--generated must be at least 1", path="<command line>")
    families = ABLATION_FAMILIES if args.families == "letters,magnetic,housing" else _choices(
        args.families, list(ABLATION_FAMILIES), "--families")
    configurations = _choices(args.configurations, ["dual", "symbolic", "low_level", "retry", "dual_kp_monitor"],
                              "--configurations")
    result = run_ablation(args.out or "ablation-campaigns", n=args.generated, seeds=args.seeds, seed=args.seed,
                          families=families, configurations=configurations, workers=args.workers,
                          ray_address=args.ray, perfect_sensing=args.perfect_sensing, progress=not args.json,
                          robot=args.robot)
    if args.json:
        print_json(result)
        return 0
    from bt_meta.campaign.report import print_class_matrix, print_summary

    for name, entry in result["families"].items():
        print(f"\n== {name} ({result['sensing']} sensing, {args.generated} variants x {args.seeds} seed(s))")
        print_summary(entry["summary"])
        for other, verdict in entry["verdicts"].items():
            word = "beats" if verdict["beats"] else ("is beaten by" if verdict["beaten"] else "overlaps")
            d, o = verdict["dual"], verdict["other"]
            print(f"  dual {d[0]:.2f} [{d[1]:.2f}, {d[2]:.2f}] {word} {other} {o[0]:.2f} [{o[1]:.2f}, {o[2]:.2f}]")
    print("\n== every family, per perturbation class (expected outcome reached, Wilson 95 %, episodes)")
    print_class_matrix(result["classes"], list(configurations))
    return 0


def run(*, seeds: int = 3, seed: int = 0, families: Sequence[str] = ("letters", "magnetic", "housing"),
        configurations: Sequence[str] = ("dual", "symbolic", "low_level", "retry"),
        only: Sequence[str] | None = None, echo: bool = False, robot: Any = None) -> dict[str, Any]:
    """Record the demonstrations, run every variant (or the ``only`` ones) under every configuration for ``seeds``
    seeds, on ``robot`` (a description; default each grounding's); the table."""
    from bt_meta.configurations import CONFIGURATIONS, available_repairs
    from bt_meta.demo.runner import memory_environment, record_demonstration, run_variant
    from bt_meta.demo.scenario import FAMILIES, VariantRun, demonstrations, variants
    from bt_meta.memory import EpisodicMemory
    from bt_meta.runs.capture import Progress
    from bt_meta.world.simulation.sim_world import quiet_stdout

    with quiet_stdout():
        import pybullet  # noqa: F401  (prints its build time on import)
    quiet = Progress(quiet=True)
    started = time.perf_counter()
    runs: list[dict[str, Any]] = []
    crashed: list[str] = []
    with tempfile.TemporaryDirectory(prefix="bt_meta_ablation_") as folder:
        path = Path(folder) / "memory.sqlite"
        with memory_environment(path), EpisodicMemory.open(path) as memory:
            demos = [d for d in demonstrations(seed) if d.family in families]
            for demo in demos:
                record = record_demonstration(demo, memory, quiet, robot=robot)
                if record.status == "failed":
                    crashed.append(f"record {demo.label}: {record.message}")
            if echo:
                print(f"recorded {len(demos) - len(crashed)}/{len(demos)} demonstrations "
                      f"({time.perf_counter() - started:.1f} s); repair plugins: "
                      f"{', '.join(['retry_repair', *available_repairs()])}", flush=True)
            for k in range(seeds):
                for base in variants(seed + k, families=tuple(families)):
                    if only is not None and base.variant not in only:
                        continue
                    for configuration in configurations:
                        variant = VariantRun(base.family, base.task_file, base.problem, base.variant, seed + k)
                        outcome = run_variant(variant, memory, None, quiet, configuration=configuration,
                                              save_refinements=False, pictures=False, robot=robot)
                        entry = {"configuration": configuration, "family": variant.family,
                                 "variant": variant.variant, "seed": variant.seed, "status": outcome.status,
                                 "achieved": outcome.achieved, "truth": outcome.truth,
                                 "success": outcome.status == "success" and outcome.achieved is not False,
                                 "attempts": len(outcome.attempts), "seconds": round(outcome.seconds, 4),
                                 "kinds": sorted({str(f.get("kind")) for f in outcome.report.get("failures") or []}),
                                 "repairs": [(a.get("proposal") or {}).get("plugin") for a in outcome.attempts],
                                 "stop_reason": outcome.report.get("stop_reason", ""), "error": outcome.error}
                        if outcome.error:
                            crashed.append(f"{variant.label} {configuration} seed {variant.seed}: "
                                           f"{outcome.error.splitlines()[0]}")
                        runs.append(entry)
                        if echo:
                            print(f"  seed {variant.seed} {configuration:<15} {variant.label:<40} {entry['status']:<8}"
                                  f" {entry['attempts']} attempt(s) {entry['seconds']:.2f} s; {entry['truth']}",
                                  flush=True)
    rows = []
    for configuration in configurations:
        for family in [*families, "all"]:
            chosen = [r for r in runs if r["configuration"] == configuration and family in (r["family"], "all")]
            if not chosen:
                continue
            successes = sum(r["success"] for r in chosen)
            false_successes = sum(r["status"] == "success" and not r["success"] for r in chosen)
            low, high = wilson(successes, len(chosen))
            attempts = bootstrap_mean([r["attempts"] for r in chosen], seed=seed)
            seconds = bootstrap_mean([r["seconds"] for r in chosen], seed=seed)
            rows.append({"configuration": configuration, "family": family, "runs": len(chosen),
                         "successes": successes, "false_successes": false_successes,
                         "rate": successes / len(chosen), "rate_ci": [low, high],
                         "attempts": attempts[0], "attempts_ci": list(attempts[1:]),
                         "seconds": seconds[0], "seconds_ci": list(seconds[1:])})
    return {"seeds": seeds, "seed": seed, "families": list(families),
            "configurations": {name: CONFIGURATIONS[name] for name in configurations},
            "family_titles": {name: FAMILIES[name].title for name in families},
            "repair_plugins": ["retry_repair", *available_repairs()], "rows": rows, "runs": runs,
            "crashed": crashed, "seconds": round(time.perf_counter() - started, 3)}


def _print(result: dict[str, Any]) -> None:
    print(f"\nablation: {result['seeds']} seed(s) from {result['seed']}, {len(result['runs'])} runs in "
          f"{result['seconds']:.1f} s; repair plugins: {', '.join(result['repair_plugins'])}")
    for name, text in result["configurations"].items():
        print(f"  {name:<10} {text}")
    print(f"\n{'configuration':<15} {'family':<9} {'runs':>4} {'success':>7} {'false':>5} {'rate [Wilson 95%]':>19} "
          f"{'attempts [95% CI]':>21} {'seconds [95% CI]':>21}")
    for row in result["rows"]:
        rate = f"{row['rate']:.2f} [{row['rate_ci'][0]:.2f}, {row['rate_ci'][1]:.2f}]"
        attempts = f"{row['attempts']:.2f} [{row['attempts_ci'][0]:.2f}, {row['attempts_ci'][1]:.2f}]"
        seconds = f"{row['seconds']:.2f} [{row['seconds_ci'][0]:.2f}, {row['seconds_ci'][1]:.2f}]"
        print(f"{row['configuration']:<15} {row['family']:<9} {row['runs']:>4} {row['successes']:>7} "
              f"{row['false_successes']:>5} {rate:>19} {attempts:>21} {seconds:>21}")
    print("success: the executor ended verified AND the simulator confirms the task done; false: ended 'success' "
          "but the task is not done (e.g. a 1x1 block where A's bar belongs)")
    kinds: dict[tuple[str, str], set[str]] = {}
    for entry in result["runs"]:
        kinds.setdefault((entry["configuration"], entry["variant"]), set()).update(entry["kinds"])
    print("\nper variant (status over seeds; failure kinds seen):")
    variants_seen = list(dict.fromkeys(e["variant"] for e in result["runs"]))
    for variant in variants_seen:
        parts = []
        for configuration in result["configurations"]:
            chosen = [e for e in result["runs"] if e["variant"] == variant and e["configuration"] == configuration]
            ok = sum(e["success"] for e in chosen)
            seen = ", ".join(sorted(kinds[(configuration, variant)])) or "-"
            parts.append(f"{configuration} {ok}/{len(chosen)} ({seen})")
        print(f"  {variant:<28} " + "; ".join(parts))
    for crash in result["crashed"]:
        print(f"  crashed: {crash}")
