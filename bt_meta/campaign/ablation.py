"""The paper's ablation as campaigns: dual, symbolic, low_level and retry on generated variants of every family.

For each family a campaign directory ``OUT/<family>`` is generated (``n`` variants from ``seed``; an existing one is
resumed, not regenerated) and run under the configurations for ``seeds`` seeds, on the perceived world unless
``perfect_sensing``. Per family the verdict compares the rate of expected outcomes reached over all variants:
dual *beats* another configuration when its Wilson 95 % interval lies wholly above the other's.

Offers:

* :func:`run_ablation` -- ``{"families": {family: {"summary", "verdicts"}}, "classes": [...], ...}``
* :func:`verdicts` -- dual against each other configuration, from a campaign summary
* :data:`ABLATION_FAMILIES`
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["ABLATION_FAMILIES", "run_ablation", "verdicts"]

ABLATION_FAMILIES = ("letters_A", "letters_H", "magnetic", "housing")


def verdicts(summary: dict[str, Any], reference: str = "dual") -> dict[str, dict[str, Any]]:
    rows = {r["configuration"]: r for r in summary["table"] if r["expected"] == "all"}
    if reference not in rows:
        return {}
    mine = rows[reference]
    out = {}
    for name, row in rows.items():
        if name == reference:
            continue
        out[name] = {"dual": [mine["rate"], *mine["wilson95"]], "other": [row["rate"], *row["wilson95"]],
                     "beats": mine["wilson95"][0] > row["wilson95"][1],
                     "beaten": row["wilson95"][0] > mine["wilson95"][1]}
    return out


def run_ablation(out: str | Path, *, n: int, seeds: int = 3, seed: int = 0,
                 families: Sequence[str] = ABLATION_FAMILIES,
                 configurations: Sequence[str] = ("dual", "symbolic", "low_level", "retry"),
                 workers: int | None = None, ray_address: str | None = None, perfect_sensing: bool = False,
                 progress: bool = True, echo: Callable[[str], None] | None = None,
                 robot: str | None = None) -> dict[str, Any]:
    """Generate (once) and run a campaign per family under ``out``, labelled for and run on ``robot`` (default the
    grounding's); a folder generated for another robot is refused."""
    from bt_meta.campaign.generator import generate
    from bt_meta.campaign.runner import run_campaign
    from bt_meta.campaign.stats import pool_classes

    out = Path(out)
    result: dict[str, Any] = {"out": str(out), "n": n, "seeds": seeds, "seed": seed, "robot": robot,
                              "sensing": "perfect" if perfect_sensing else "perceived",
                              "configurations": list(configurations), "families": {}}
    for name in families:
        folder = out / name
        if not (folder / "campaign.json").is_file():
            generate(name, n, seed, folder, robot=robot)
        run = run_campaign(folder, configurations=configurations, seeds=seeds, workers=workers,
                           ray_address=ray_address, perfect_sensing=perfect_sensing, progress=progress, echo=echo,
                           robot=robot)
        result["families"][name] = {"summary": run["summary"], "verdicts": verdicts(run["summary"])}
    result["classes"] = pool_classes(entry["summary"]["classes"] for entry in result["families"].values())
    return result
