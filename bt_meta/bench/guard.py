"""``bt-meta bench guard``: the outcome guard -- a fixed population of variants whose outcomes must not change.

A change meant to make episodes cheaper (or any change not meant to alter repair outcomes) runs this before it
lands: every variant of the population (``tests/data/guard/population.json``: 40 variants over the four families,
their scene files kept in the repository) is run as a campaign episode (:func:`bt_meta.campaign.episode.run_episode`,
the population's configuration, seed and sensing) on a demonstration memory recorded afresh, and its outcome is
compared with ``baseline.json`` beside it. A changed status, failure kind, attempt count, repair plugin list,
ground-truth verdict or second exposure is a difference: printed, exit status 1. The simulated seconds are printed
when they change but do not fail the guard (they are not an outcome). ``--update`` records the outcomes as the new
baseline, on purpose, when a change of outcomes is intended. Detail: docs/campaigns.md, "The outcome guard".

Offers:

* :func:`register` -- ``bt-meta bench guard [--update] [--only NAME ...] [--workers N] [--population DIR] [--json]``
* :func:`run_population` -- run (part of) a population; returns ``{key: outcome}``
* :func:`differences` -- what changed between a baseline and observed outcomes
* :func:`load_population` / :func:`load_baseline` -- the population and its baseline
* :func:`default_population` -- the repository's population folder; :data:`COMPARED` -- the fields that fail the guard
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.errors import ConfigError, UserInputError

__all__ = ["COMPARED", "POPULATION", "default_population", "differences", "load_baseline", "load_population",
           "register", "run_population"]

POPULATION = Path("tests") / "data" / "guard"
"""Where the population is kept in the repository, relative to its root."""
COMPARED = ("status", "success", "achieved", "kinds", "attempts", "repairs", "second_exposure")
"""Outcome fields that fail the guard when they change."""
NOTED = ("simulated_seconds",)
"""Fields printed when they change, without failing the guard."""
BASELINE = "baseline.json"


def default_population() -> Path:
    """The population of the source checkout bt-meta runs from, else of the current directory.

    An installed wheel carries no tests/ folder, so a guard run from a clone of the repository finds it there.
    """
    checkout = Path(__file__).resolve().parents[2] / POPULATION
    return checkout if checkout.is_dir() else Path.cwd() / POPULATION


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "guard", help="the outcome guard: run a fixed population of variants, exit 1 if an outcome changed",
        description="Run the outcome guard's population (40 variants over letters_A, letters_H, magnetic and "
                    "housing, kept in tests/data/guard) as campaign episodes and compare each variant's status, "
                    "failure kinds, attempt count, repair plugins, ground truth and second exposure with "
                    "baseline.json. Exit 0 when nothing changed, 1 when something did (the differences are "
                    "printed), 2 on bad arguments. --update records the outcomes as the new baseline instead.")
    parser.add_argument("--update", action="store_true", help="record the outcomes as the new baseline (on purpose)")
    parser.add_argument("--only", action="append", metavar="NAME", default=None,
                        help="run only this variant (FAMILY/VARIANT or VARIANT; repeatable)")
    parser.add_argument("--workers", type=int, default=1, help="processes running episodes (default 1)")
    parser.add_argument("--population", type=Path, default=None,
                        help=f"population folder (default {POPULATION} of the source checkout, or of the "
                             "current directory when bt-meta is installed from a wheel)")
    parser.add_argument("--json", action="store_true", help="print JSON (outcomes and differences)")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    folder = args.population or default_population()
    population = load_population(folder)
    if not 1 <= args.workers <= 64:
        raise UserInputError("--workers must be between 1 and 64", "<command line>")
    keys = select(population, args.only)
    if args.update and args.only:
        raise UserInputError("--update records the whole population; leave out --only", "<command line>")
    echo = (lambda text: None) if args.json else print
    observed = run_population(folder, population, keys, workers=args.workers, echo=echo)
    if args.update:
        write_baseline(folder, observed)
        echo(f"recorded the outcomes of {len(observed)} variant(s) into {Path(folder) / BASELINE}")
        if args.json:
            print_json({"updated": True, "outcomes": observed})
        return 0
    baseline = load_baseline(folder)
    failing, noted = differences(baseline, observed)
    if args.json:
        print_json({"variants": len(observed), "failing": failing, "noted": noted, "outcomes": observed})
    else:
        for line in noted:
            print(f"  (noted, not failing) {line}")
        for line in failing:
            print(f"  CHANGED {line}")
        print(f"outcome guard: {len(observed)} variant(s), {len(failing)} changed outcome(s)"
              + ("" if not failing else "; if intended, re-record with `bt-meta bench guard --update`"))
    return 1 if failing else 0


def load_population(folder: str | Path) -> dict[str, Any]:
    path = Path(folder) / "population.json"
    if not path.is_file():
        raise ConfigError("no outcome-guard population here (population.json); give --population", path)
    try:
        population = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ConfigError(f"not valid JSON: {error.msg}", path, error.lineno, error.colno) from None
    for variant in population.get("variants", []):
        if not (Path(folder) / variant["file"]).is_file():
            raise ConfigError(f"variant file {variant['file']} is missing", path)
    return population


def load_baseline(folder: str | Path) -> dict[str, Any]:
    path = Path(folder) / BASELINE
    if not path.is_file():
        raise ConfigError("no baseline recorded; record one with `bt-meta bench guard --update`", path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))["outcomes"]
    except (json.JSONDecodeError, KeyError) as error:
        raise ConfigError(f"not a guard baseline: {error}", path) from None


def write_baseline(folder: str | Path, outcomes: dict[str, Any]) -> Path:
    path = Path(folder) / BASELINE
    recorded = {"commit": _commit(), "command": "bt-meta bench guard --update",
                "outcomes": dict(sorted(outcomes.items()))}
    path.write_text(json.dumps(recorded, indent=1) + "\n", encoding="utf-8")
    return path


def key(variant: dict[str, Any]) -> str:
    return f"{variant['family']}/{variant['name']}"


def select(population: dict[str, Any], only: Sequence[str] | None) -> list[str]:
    """The keys to run: all, or those named by ``only`` (``FAMILY/VARIANT`` or ``VARIANT``)."""
    keys = [key(v) for v in population["variants"]]
    if not only:
        return keys
    chosen = []
    for name in only:
        matches = [k for k in keys if name in (k, k.split("/", 1)[1])]
        if not matches:
            raise UserInputError(f"--only {name!r}: no such variant in the population", "<command line>")
        chosen.extend(m for m in matches if m not in chosen)
    return chosen


def outcome(row: dict[str, Any]) -> dict[str, Any]:
    """What the guard keeps of an episode's row: the compared fields and the noted ones."""
    second = row.get("second_exposure")
    return {"status": row["status"], "success": row["success"], "achieved": row.get("achieved"),
            "kinds": list(row["kinds"]), "attempts": row["attempts"], "repairs": list(row.get("repairs") or []),
            "second_exposure": None if second is None else {"status": second["status"],
                                                             "attempts": second["attempts"]},
            "simulated_seconds": row.get("simulated_seconds"),
            **({"error": row["error"].splitlines()[0]} if row.get("error") else {})}


def run_population(folder: str | Path, population: dict[str, Any], keys: Sequence[str], *, workers: int = 1,
                   echo: Callable[[str], None] = print) -> dict[str, dict[str, Any]]:
    """Run the variants ``keys`` of the population, one memory recorded per family; ``{key: outcome}``."""
    from bt_meta.campaign.episode import episode_task
    from bt_meta.campaign.runner import _pool_results, ensure_memory

    folder = Path(folder).resolve()
    wanted = [v for v in population["variants"] if key(v) in set(keys)]
    results: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="bt_meta_guard_") as scratch:
        tasks = []
        for name in sorted({v["family"] for v in wanted}):
            (Path(scratch) / name).mkdir()
            memory = ensure_memory(Path(scratch) / name, {"family": name, "seed": population["memory_seed"]},
                                   echo=echo)
            manifest = {"family": name, **population["families"][name]}
            for variant in (v for v in wanted if v["family"] == name):
                task = episode_task(folder, manifest, variant, population["configuration"], population["seed"],
                                    perfect_sensing=population["sensing"] == "perfect")
                task["memory"] = str(memory)
                tasks.append(task)
        for row in _pool_results(tasks, workers):
            done = outcome(row)
            results[f"{row['family']}/{row['variant']}"] = done
            echo(f"{row['family']}/{row['variant']}: {done['status']}, {done['attempts']} attempt(s)"
                 + (f", kinds {', '.join(done['kinds'])}" if done["kinds"] else "")
                 + f" ({row['seconds']:.1f} s)")
    return dict(sorted(results.items()))


def differences(baseline: dict[str, Any], observed: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(failing, noted) lines: every compared field that changed, and every noted one."""
    failing, noted = [], []
    for name, now in observed.items():
        before = baseline.get(name)
        if before is None:
            failing.append(f"{name}: not in the baseline (re-record it with --update)")
            continue
        for field in COMPARED:
            if before.get(field) != now.get(field):
                failing.append(f"{name}: {field} {before.get(field)!r} -> {now.get(field)!r}"
                               + (f" ({now['error']})" if now.get("error") else ""))
        for field in NOTED:
            if before.get(field) != now.get(field):
                noted.append(f"{name}: {field} {before.get(field)!r} -> {now.get(field)!r}")
    return failing, noted


def _commit() -> str | None:
    try:
        done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).parent,
                              capture_output=True, text=True, check=False, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() or None
