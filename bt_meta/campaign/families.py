"""The variant families a campaign generates from: which task file, problem and scene, and what the goal needs.

A family is data: the task file and problem whose nominal plan is run, the shipped scene the variants perturb,
the ground-truth check of :mod:`bt_meta.demo.truth` that says whether the task is really done, the objects the
robot must pick up (``grasped``), the fixtures whose pose the nominal plan's absolute poses depend on
(``absolute_fixtures``: the magnetic attach's instructor poses are absolute, the housing's hole pose is relative
to the board), and the demonstrations recorded once per campaign.

Offers:

* :class:`CampaignFamily` and :data:`FAMILIES` -- ``letters_A``, ``letters_H``, ``magnetic``, ``housing``
* :func:`family` -- a family by name (a :class:`~bt_meta.errors.UserInputError` naming the known ones)
* :func:`needed_objects` -- the simulator objects the problem names (task-file symbols and features mapped)
* :func:`default_spec_path` -- the shipped default perturbation spec of a family
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bt_meta.errors import UserInputError

__all__ = ["FAMILIES", "CampaignFamily", "default_spec_path", "family", "needed_objects"]


@dataclass(frozen=True)
class CampaignFamily:
    name: str
    task_file: str
    """Shipped task file (under ``trees/``)."""
    problem: str
    scene: str
    """Shipped scene the variants perturb (``trees/scenes/<scene>.yaml``)."""
    truth: str
    """Family name of :func:`bt_meta.demo.truth.achieved` (``letters``, ``magnetic``, ``housing``)."""
    grasped: tuple[str, ...] | None
    """Objects the robot picks up; ``None``: every needed object (the letters' blocks)."""
    absolute_fixtures: tuple[str, ...] = ()
    demonstrations: tuple[tuple[str, int], ...] = ()
    """(problem, repeats) recorded before the episodes, from seeds ``seed .. seed + repeats - 1``."""

    def task_path(self) -> Path:
        from bt_meta.resources import trees_dir

        return trees_dir() / self.task_file


FAMILIES: dict[str, CampaignFamily] = {
    # A's substitutions draw on H's decomposition (two 1x1 for a 1x2): both letters are demonstrated.
    "letters_A": CampaignFamily("letters_A", "letters.yaml", "A", "letters_A", "letters", None,
                                demonstrations=(("A", 3), ("H", 1))),
    "letters_H": CampaignFamily("letters_H", "letters.yaml", "H", "letters_H", "letters", None,
                                demonstrations=(("H", 3), ("A", 1))),
    "magnetic": CampaignFamily("magnetic", "magnetic_attach.yaml", "nominal", "magnetic_attach", "magnetic",
                               ("active",), absolute_fixtures=("reference",),
                               demonstrations=(("nominal", 3),)),
    "housing": CampaignFamily("housing", "housing_insertion.yaml", "nominal", "housing_insertion", "housing",
                              ("housing",), demonstrations=(("nominal", 1),)),
}


def family(name: str) -> CampaignFamily:
    try:
        return FAMILIES[name]
    except KeyError:
        raise UserInputError(f"unknown family {name!r}; known: {', '.join(FAMILIES)}", "<command line>") from None


def needed_objects(problem: Any, grounding: Any) -> list[str]:
    """The simulator objects a problem names: its non-pose objects through the grounding's ``objects:`` map, and
    the objects its features belong to."""
    objects = getattr(problem, "objects", None) or {}
    groups = objects.items() if isinstance(objects, Mapping) else [("object", objects)]
    out: list[str] = []
    for kind, group in groups:
        if kind == "pose":
            continue
        for symbol in group:
            if symbol in grounding.features:
                name = str(grounding.features[symbol]["object"])
            else:
                name = grounding.objects.get(symbol, symbol)
            if name not in out:
                out.append(name)
    return out


def default_spec_path(name: str) -> Path:
    """``bt_meta/campaign/specs/<family>.yaml``: the shipped default perturbations."""
    return Path(__file__).parent / "specs" / f"{family(name).name}.yaml"
