"""A project's own repair plugin: when a gripper fails to hold an object, use the other arm.

Dropped into the ``plugins/`` folder next to the task file, it is loaded with no code change (the file's stem,
``swap_arm_repair``, is the plugin's name). It answers ``bt_meta_propose_repairs`` with a ``substitute``
proposal: the other arm replaces the failing one in the failed step and every later step. Its score (0.8) ranks it
above the retry baseline (0.3 and lower).
"""

from __future__ import annotations

from typing import Any

from bt_meta.bt.failures import FailureKind, RepairProposal
from bt_meta.plugins import hookimpl

OTHER_ARM = {"left": "right", "right": "left"}


@hookimpl
def bt_meta_propose_repairs(failure: Any, context: Any) -> list[RepairProposal] | None:
    if failure.kind is not FailureKind.PHYSICAL:
        return None
    arm = next((arg for arg in failure.args if arg in OTHER_ARM), None)
    if arm is None:
        return None
    other = OTHER_ARM[arm]
    return [RepairProposal(
        action="substitute",
        score=0.8,
        description=f"the {arm} gripper failed: use the {other} arm",
        changes={"mapping": {arm: other}},
        evidence={"failed_arm": arm},
    )]
