"""What the meta-reasoner knows about the failure taxonomy beyond the kinds themselves.

The kinds live in :class:`bt_meta.bt.failures.FailureKind` (one enum for the whole project); the rules that pick a
kind are a plugin (``bt_meta_plugins.classification_rules``). This module says how the reasoner treats each kind.

Offers:

* :data:`FailureKind`, :func:`parse_kind` -- re-exported from :mod:`bt_meta.bt.failures`
* :data:`MOTION_LIMITS` -- collision and reachability: reported with their evidence, never looped on
* :data:`LOGICAL`, :data:`SOFT`, :data:`HARD` -- the paper's groups (section 6.4, 7.3)
* :func:`is_motion_limit` -- whether a kind is one of :data:`MOTION_LIMITS`
* :func:`motion_evidence` -- the evidence of a motion failure worth reporting (colliding pair, unreachable target)
"""

from __future__ import annotations

from typing import Any

from bt_meta.bt.failures import FailureKind, parse_kind

__all__ = ["HARD", "LOGICAL", "MOTION_LIMITS", "SOFT", "FailureKind", "is_motion_limit", "motion_evidence",
           "parse_kind"]

MOTION_LIMITS: frozenset[FailureKind] = frozenset({FailureKind.COLLISION, FailureKind.REACHABILITY})
"""The paper's two named limits of pose repair (section 7.5.2): a retry of the same motion fails the same way."""

LOGICAL: frozenset[FailureKind] = frozenset({FailureKind.UNKNOWN_ENTITY, FailureKind.UNEXPECTED_CONFIGURATION})
SOFT: frozenset[FailureKind] = frozenset({FailureKind.VERIFICATION})
HARD: frozenset[FailureKind] = frozenset({FailureKind.PRECONDITION})

# Evidence keys skills and plugins use for motion failures, most specific first.
_MOTION_KEYS = ("colliding_pair", "collision", "contacts", "pair", "unreachable_target", "target", "pose",
                "ik", "reason", "error", "residual")


def is_motion_limit(kind: FailureKind | str) -> bool:
    return parse_kind(kind) in MOTION_LIMITS


def motion_evidence(evidence: dict[str, Any]) -> dict[str, Any]:
    """The part of a motion failure's evidence a report should show; everything when no known key is present."""
    picked = {key: evidence[key] for key in _MOTION_KEYS if key in evidence}
    return picked or {key: value for key, value in evidence.items() if key not in ("traceback", "meta")}
