"""The demo's scenario as data: which demonstrations are recorded and which variants are run.

Offers:

* :class:`Demonstration` -- a nominal problem recorded as the instructor's trace (from :mod:`bt_meta.runs`)
* :class:`VariantRun` -- a variant scene of a problem run with monitors and the meta-reasoner
* :data:`FAMILIES` -- the variant families (letters, magnetic attach, housing) with their keypoint pair
* :func:`demonstrations` / :func:`variants` -- the lists for a seed, full or ``quick``
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bt_meta.runs.demonstrations import Demonstration

__all__ = ["FAMILIES", "Demonstration", "VariantRun", "demonstrations", "variants"]


@dataclass(frozen=True)
class Family:
    name: str
    title: str
    task_file: str
    problem: str
    keypoint_pair: tuple[str, str] | None
    """(active, reference) simulator objects whose R_p / R_n the report plots; ``None``: grid-maps instead."""
    success: str
    """The shipped campaign family file (``trees/families/<success>.yaml``) whose ``success:`` the judge uses."""

    def success_file(self) -> Any:
        from bt_meta.resources import trees_dir

        return trees_dir() / "families" / f"{self.success}.yaml"


FAMILIES = {
    "letters": Family("letters", "Letters (section 6): A with substituted blocks", "letters.yaml", "A", None,
                      "letters_A"),
    "magnetic": Family("magnetic", "MagneticAttach (section 7): variant poses of the active part",
                       "magnetic_attach.yaml", "nominal", ("active", "reference"), "magnetic"),
    "housing": Family("housing", "Housing insertion (section 2): upside-down housing", "housing_insertion.yaml",
                      "nominal", ("housing", "board"), "housing"),
}


@dataclass(frozen=True)
class VariantRun:
    family: str
    task_file: str
    problem: str
    variant: str
    seed: int

    @property
    def label(self) -> str:
        return f"{self.family}/{self.variant}"


_VARIANTS = {
    "letters": ("A_bar_other_colour", "A_two_1x1_same_colour", "A_two_1x1_different_colours"),
    "magnetic": ("active_on_side", "active_upside_down", "active_on_side_turned"),
    "housing": ("housing_upside_down",),
}
_QUICK_VARIANTS = {
    "letters": ("A_two_1x1_same_colour",),
    "magnetic": ("active_on_side",),
    "housing": ("housing_upside_down",),
}


def demonstrations(seed: int = 0, *, quick: bool = False) -> list[Demonstration]:
    """Letters A (several seeds) and H, the magnetic-attach nominal (several seeds), the housing nominal.

    H is the demonstration A's substitution draws on (its bar of two 1x1 blocks); the housing nominal gives the
    upside-down housing an expectation to be compared with."""
    repeats = 2 if quick else 3
    demos = [Demonstration("letters", "letters.yaml", "A", seed + k) for k in range(repeats)]
    demos.append(Demonstration("letters", "letters.yaml", "H", seed))
    demos += [Demonstration("magnetic", "magnetic_attach.yaml", "nominal", seed + k) for k in range(repeats)]
    demos.append(Demonstration("housing", "housing_insertion.yaml", "nominal", seed))
    return demos


def variants(seed: int = 0, *, quick: bool = False, families: tuple[str, ...] = tuple(FAMILIES)) -> list[VariantRun]:
    table = _QUICK_VARIANTS if quick else _VARIANTS
    out = []
    for name in families:
        family = FAMILIES[name]
        out += [VariantRun(name, family.task_file, family.problem, variant, seed) for variant in table[name]]
    return out
