"""The numbers of a campaign: per expected outcome x configuration rates with Wilson intervals, and the rest.

The Wilson 95 % interval comes from scipy (``binomtest(...).proportion_ci(method="wilson")``); means get a seeded
percentile-bootstrap 95 % interval (2,000 resamples).

What a row counts (``rows`` are the database's episode rows):

* **success** -- the executor ended ``success`` and the simulator confirms the task done; for a ``limit:*`` or
  ``unrepairable`` variant, success is the *right report*: the run ended failed with the limit's kind among its
  failures (``limit:reachability`` -> ``reachability``) or, unrepairable, failed at all -- a run that claims to
  have done the impossible is not a success
* **loops** -- runs stopped because the attempt budget was spent
* **false alarms** -- runs of a ``nominal_equivalent`` variant with any failure classified
* **second exposure** -- every repaired run run again on the memory its repair wrote (a run whose repair kept no
  refinement too: it repeats its repair): attempts then; it counts as done with zero attempts only when the
  simulator agrees (``false_successes``: ended success, task not done)

Offers:

* :func:`wilson_interval` -- (low, high)
* :func:`correct` -- whether an episode row reached its expected outcome
* :func:`summarise` -- the summary dict (``table``, ``confusion``, ``loops``, ``false_alarms``, ``second_exposure``;
  ``classes`` when given each variant's perturbation classes)
* :func:`perturbation_classes` -- a manifest's variants by perturbation class (shift, turn, on a side, ...)
* :func:`pool_classes` -- class tables of several campaigns added up (the ablation's families)
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from typing import Any

__all__ = ["CLASSES", "correct", "perturbation_classes", "pool_classes", "summarise", "wilson_interval"]

CLASSES = ("none", "shift", "turn", "on a side", "upside down", "colour", "shape replaced", "missing, spare",
           "missing, no spare", "distractor", "obstacle", "out of reach")
"""The perturbation classes a variant is counted under, in the order tables show them."""


def wilson_interval(successes: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of ``successes`` out of ``n`` (``(0, 1)`` when ``n`` is 0)."""
    if n <= 0:
        return 0.0, 1.0
    from scipy.stats import binomtest

    interval = binomtest(int(successes), int(n)).proportion_ci(confidence_level=level, method="wilson")
    return float(interval.low), float(interval.high)


def correct(row: dict[str, Any]) -> bool:
    """Did the episode reach its expected outcome (see the module docstring)?"""
    expected = row.get("expected", "")
    if row.get("status") == "crashed":
        return False
    if expected in ("nominal_equivalent", "repairable"):
        return bool(row.get("success"))
    if expected.startswith("limit:"):
        return row.get("status") != "success" and expected.split(":", 1)[1] in (row.get("kinds") or [])
    if expected == "unrepairable":
        return row.get("status") != "success"
    return False


def _mean(values: Sequence[float], seed: int = 0, resamples: int = 2000) -> dict[str, float]:
    """The mean and its seeded percentile-bootstrap 95 % interval (a single or constant value: a point)."""
    import numpy as np

    data = np.asarray(values, dtype=float)
    if data.size == 0:
        return {"mean": float("nan"), "low": float("nan"), "high": float("nan")}
    mean = float(data.mean())
    if data.size == 1 or np.all(data == data[0]):
        return {"mean": mean, "low": mean, "high": mean}
    means = data[np.random.default_rng(seed).integers(0, data.size, size=(resamples, data.size))].mean(axis=1)
    return {"mean": mean, "low": float(np.quantile(means, 0.025)), "high": float(np.quantile(means, 0.975))}


def perturbation_classes(manifest: dict[str, Any]) -> dict[str, list[str]]:
    """Each variant's perturbation classes, from the changes the generator recorded in the manifest.

    A variant with several changes counts under each of its classes; one with none is ``none``.
    """
    out = {}
    for variant in manifest.get("variants") or []:
        classes = [_change_class(change) for change in variant.get("changes") or []]
        out[variant["name"]] = list(dict.fromkeys(classes)) or ["none"]
    return out


def _change_class(change: dict[str, Any]) -> str:
    kind = change.get("kind")
    if kind == "rotate":
        roll, pitch = (abs(float(a)) % 360.0 for a in (change.get("rpy") or [0, 0, 0])[:2])
        return "upside down" if 135.0 <= max(roll, pitch) <= 225.0 else "on a side"
    if kind == "remove":
        return "missing, spare" if change.get("spare") else "missing, no spare"
    return {"obstacles": "obstacle", "out_of_reach": "out of reach", "replace_shape": "shape replaced"}.get(
        str(kind), str(kind))


def _class_table(rows: list[dict[str, Any]], classes: dict[str, list[str]],
                 configurations: Sequence[str]) -> list[dict[str, Any]]:
    """Per perturbation class x configuration: episodes that reached their expected outcome, Wilson 95 %."""
    seen = {c for names in classes.values() for c in names}
    order = [c for c in CLASSES if c in seen] + sorted(seen - set(CLASSES))
    table = []
    for name in order:
        for configuration in configurations:
            chosen = [r for r in rows if r["configuration"] == configuration and name in classes.get(r["variant"], ())]
            if not chosen:
                continue
            ok = sum(correct(r) for r in chosen)
            low, high = wilson_interval(ok, len(chosen))
            table.append({"class": name, "configuration": configuration, "episodes": len(chosen), "correct": ok,
                          "rate": ok / len(chosen), "wilson95": [low, high],
                          "expected": dict(Counter(r["expected"] for r in chosen))})
    return table


def pool_classes(tables: Iterable[Sequence[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Class tables (``summary["classes"]``) of several campaigns added up, the Wilson interval of the sums."""
    pooled: dict[tuple[str, str], dict[str, Any]] = {}
    for table in tables:
        for r in table:
            row = pooled.setdefault((r["class"], r["configuration"]), {"class": r["class"],
                                    "configuration": r["configuration"], "episodes": 0, "correct": 0,
                                    "expected": Counter()})
            row["episodes"] += r["episodes"]
            row["correct"] += r["correct"]
            row["expected"].update(r.get("expected") or {})
    order = {name: k for k, name in enumerate(CLASSES)}
    out = []
    for row in sorted(pooled.values(), key=lambda r: (order.get(r["class"], len(order)), r["class"])):
        low, high = wilson_interval(row["correct"], row["episodes"])
        out.append({**row, "rate": row["correct"] / row["episodes"], "wilson95": [low, high],
                    "expected": dict(row["expected"])})
    return out


def summarise(rows: Iterable[dict[str, Any]], *, configurations: Sequence[str] | None = None,
              classes: dict[str, list[str]] | None = None) -> dict[str, Any]:
    rows = list(rows)
    if not configurations:  # the paper's order first, then any other, as first seen
        seen = list(dict.fromkeys(r["configuration"] for r in rows))
        configurations = [c for c in ("dual", "symbolic", "low_level", "retry") if c in seen]
        configurations += [c for c in seen if c not in configurations]
    configurations = list(configurations)
    expected_values = [e for e in ("nominal_equivalent", "repairable", "limit:reachability", "limit:collision",
                                   "unrepairable") if any(r["expected"] == e for r in rows)]
    table = []
    for expected in [*expected_values, "all"]:
        for configuration in configurations:
            chosen = [r for r in rows if r["configuration"] == configuration and expected in (r["expected"], "all")]
            if not chosen:
                continue
            ok = sum(correct(r) for r in chosen)
            low, high = wilson_interval(ok, len(chosen))
            table.append({"expected": expected, "configuration": configuration, "episodes": len(chosen),
                          "correct": ok, "rate": ok / len(chosen), "wilson95": [low, high],
                          "attempts": _mean([r["attempts"] for r in chosen]),
                          "seconds": _mean([r["seconds"] for r in chosen]),
                          "loops": sum(bool(r.get("loop")) for r in chosen),
                          "crashed": sum(r["status"] == "crashed" for r in chosen)})
    confusion: dict[str, dict[str, int]] = {}
    for r in rows:
        kinds = r.get("kinds") or (["crashed"] if r["status"] == "crashed" else ["none"])
        counter = confusion.setdefault(r["expected"], Counter())
        for kind in kinds:
            counter[kind] += 1
    nominal = [r for r in rows if r["expected"] == "nominal_equivalent"]
    false_alarms = [r for r in nominal if r.get("kinds")]
    second = [r for r in rows if r.get("second_exposure")]
    return {
        "episodes": len(rows), "configurations": configurations, "table": table,
        "classes": _class_table(rows, classes, configurations) if classes else [],
        "confusion": {k: dict(v) for k, v in confusion.items()},
        "loops": sum(bool(r.get("loop")) for r in rows),
        "false_alarms": {"count": len(false_alarms), "of": len(nominal),
                         "episodes": [_key(r) for r in false_alarms]},
        "second_exposure": {"repaired": len(second),
                            "zero_attempts": sum(_second_done(r["second_exposure"]) and
                                                 r["second_exposure"]["attempts"] == 0 for r in second),
                            "false_successes": sum(r["second_exposure"]["status"] == "success" and
                                                   r["second_exposure"].get("achieved") is False for r in second),
                            "attempts": _mean([r["second_exposure"]["attempts"] for r in second]) if second else None},
        "crashed": sum(r["status"] == "crashed" for r in rows),
        "seconds": sum(float(r["seconds"]) for r in rows),
        "simulated_seconds": sum(float(r.get("simulated_seconds") or 0.0) for r in rows),
    }


def _second_done(second: dict[str, Any]) -> bool:
    """The second exposure succeeded: the executor says so and the simulator does not contradict it."""
    return second.get("status") == "success" and second.get("achieved") is not False


def _key(row: dict[str, Any]) -> str:
    return f"{row['variant']}/{row['configuration']}/{row['seed']}"
