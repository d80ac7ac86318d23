"""Symbolic expectations: after a primitive succeeds, its add effects hold and its delete effects do not.

The post-condition of a step is its primitive's ground effects (under the binding the monitor checked the
precondition with), compared with the observed symbolic state (``observations["symbolic_state"]``, supplied by a
perception plugin such as ``ground_truth_perception``). A mismatch suggests ``unexpected_configuration``; the
classification hook may decide otherwise.

Offers:

* :func:`bt_meta_expectations` -- one ``"symbolic"`` expectation per primitive step with effects
* :func:`bt_meta_compare` -- compares ``"symbolic"`` expectations; ``None`` without a symbolic observation
"""

from __future__ import annotations

from typing import Any

from bt_meta.bt.expectations import Comparison, Expectation
from bt_meta.bt.failures import FailureKind
from bt_meta.htn.state import atom_text
from bt_meta.plugins import hookimpl

KIND = "symbolic"


def _effects(context: Any) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]] | None:
    if context.effects is not None:
        return context.effects
    primitive = context.primitive
    if primitive is None or context.state_before is None:
        return None
    env = next(iter(primitive.satisfiers(context.state_before, context.args)), None)
    return None if env is None else primitive.effects(env)


@hookimpl
def bt_meta_expectations(context: Any) -> list[Expectation] | None:
    effects = _effects(context)
    if effects is None or not (effects[0] or effects[1]):
        return None
    add, delete = effects
    added = set(add)
    delete = [atom for atom in delete if atom not in added]  # STRIPS: add wins
    call = atom_text((context.action, *context.args))
    return [Expectation(
        kind=KIND,
        description=f"effects of {call}",
        data={"add": list(add), "delete": delete},
        failure_kind=FailureKind.UNEXPECTED_CONFIGURATION,
    )]


@hookimpl
def bt_meta_observation_needs(context: Any) -> list[str] | None:
    """The observed symbolic state."""
    return ["symbolic_state"]


@hookimpl
def bt_meta_compare(expectation: Expectation, observations: dict[str, Any], context: Any) -> Comparison | None:
    if expectation.kind != KIND:
        return None
    observed = observations.get("symbolic_state")
    if observed is None:
        return None
    missing = [atom for atom in expectation.data["add"] if atom not in observed]
    remaining = [atom for atom in expectation.data["delete"] if atom in observed]
    if not missing and not remaining:
        return Comparison(matched=True)
    parts = []
    if missing:
        parts.append("expected but not observed: " + ", ".join(atom_text(a) for a in missing))
    if remaining:
        parts.append("expected gone but still observed: " + ", ".join(atom_text(a) for a in remaining))
    return Comparison(
        matched=False,
        message=f"{expectation.description}: " + "; ".join(parts),
        evidence={"missing": [atom_text(a) for a in missing], "not_deleted": [atom_text(a) for a in remaining]},
    )
