"""Stand-ins for nodes a tree names but nobody implements, so any real tree can be loaded, shown and dry-run.

``--stub-unknown`` on ``show`` and ``tick`` turns every node that is only declared in ``<TreeNodesModel>`` (or not
declared at all) into a :class:`Stub`; ``--stub ID=STATUS[,STATUS...]`` scripts what a stub returns, tick after
tick (the last status repeats; SUCCESS when not given).

Offers:

* :class:`StubPolicy` -- which statuses each stubbed ID returns
* :class:`Stub` -- returns its scripted statuses; a stubbed decorator or control does not tick its children
  (``show`` still draws them)
* :func:`parse_stub` -- ``"Detect=FAILURE,SUCCESS"`` -> (ID, statuses)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import py_trees
from py_trees.common import Status

from bt_meta.errors import UserInputError

_NAMES = {"SUCCESS": Status.SUCCESS, "FAILURE": Status.FAILURE, "RUNNING": Status.RUNNING}


def parse_stub(spec: str) -> tuple[str, list[Status]]:
    node_id, sep, statuses = spec.partition("=")
    node_id = node_id.strip()
    if not sep or not node_id or not statuses.strip():
        raise UserInputError(f"bad --stub {spec!r}: expected ID=STATUS[,STATUS...]")
    result = []
    for word in statuses.split(","):
        word = word.strip().upper()
        if word not in _NAMES:
            raise UserInputError(f"bad --stub {spec!r}: {word!r} is not SUCCESS, FAILURE or RUNNING")
        result.append(_NAMES[word])
    return node_id, result


@dataclass
class StubPolicy:
    statuses: dict[str, list[Status]] = field(default_factory=dict)

    @classmethod
    def from_specs(cls, specs: list[str]) -> StubPolicy:
        return cls(dict(parse_stub(spec) for spec in specs))

    def script(self, node_id: str) -> list[Status]:
        return self.statuses.get(node_id, [Status.SUCCESS])


class Stub(py_trees.behaviour.Behaviour):
    """Returns ``script[k]`` on its k-th tick (the last one from then on)."""

    def __init__(self, name: str, node_id: str, script: list[Status]) -> None:
        super().__init__(name)
        self.node_id = node_id
        self.script = list(script) or [Status.SUCCESS]
        self.ticks = 0

    def update(self) -> Status:
        status = self.script[min(self.ticks, len(self.script) - 1)]
        self.ticks += 1
        return status
