"""BehaviorTree.CPP's pre- and post-condition attributes on any node (``tree_node.cpp``'s ``executeTick``).

Pre-conditions, checked in this order before the node's own tick: ``_failureIf``, ``_successIf``, ``_skipIf``
(when true, return FAILURE / SUCCESS / SKIPPED without ticking) and ``_while`` (when false, SKIPPED; if the node is
RUNNING it is halted first). All but ``_while`` are checked only when the node is idle. Post-conditions run after a
tick that finished: ``_onSuccess`` or ``_onFailure``, then ``_post``; ``_onHalted`` runs when the node is halted
while RUNNING.

Offers:

* :data:`PRE_CONDITIONS`, :data:`POST_CONDITIONS` -- the attribute names, in BT.CPP's order
* :class:`Conditions` -- the compiled scripts of one node and the environment they run in
* :func:`attach_conditions` -- give a py_trees behaviour those semantics (wraps its ``tick`` and ``stop``)
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.entries import BlackboardEnvironment
from bt_meta.bt.nodes.status import SKIPPED, Returned, mark
from bt_meta.bt.script import CompiledScript

PRE_CONDITIONS = ("_failureIf", "_successIf", "_skipIf", "_while")
POST_CONDITIONS = ("_onHalted", "_onFailure", "_onSuccess", "_post")


@dataclass
class Conditions:
    scripts: dict[str, CompiledScript] = field(default_factory=dict)
    env: BlackboardEnvironment = field(default_factory=BlackboardEnvironment)

    def __bool__(self) -> bool:
        return bool(self.scripts)

    def run(self, attribute: str) -> None:
        script = self.scripts.get(attribute)
        if script is not None:
            script.run(self.env)

    def pre(self, behaviour: py_trees.behaviour.Behaviour) -> Returned | None:
        """The status a pre-condition imposes, or ``None`` when the node must be ticked."""
        # A finished root counts as idle: BT.CPP resets the root after every tick that finished it.
        idle = behaviour.status == Status.INVALID or (
            getattr(behaviour, "bt_root", False) and behaviour.status in (Status.SUCCESS, Status.FAILURE)
        )
        for attribute in PRE_CONDITIONS:
            script = self.scripts.get(attribute)
            if script is None:
                continue
            if idle:
                holds = script.test(self.env)
                if holds and attribute == "_failureIf":
                    return Status.FAILURE
                if holds and attribute == "_successIf":
                    return Status.SUCCESS
                if holds and attribute == "_skipIf":
                    return SKIPPED
                if not holds and attribute == "_while":
                    return SKIPPED
            elif behaviour.status == Status.RUNNING and attribute == "_while" and not script.test(self.env):
                behaviour.stop(Status.INVALID)
                return SKIPPED
        return None

    def post(self, status: Returned) -> None:
        if status == Status.SUCCESS:
            self.run("_onSuccess")
        elif status == Status.FAILURE:
            self.run("_onFailure")
        self.run("_post")


def attach_conditions(behaviour: py_trees.behaviour.Behaviour, conditions: Conditions) -> None:
    """Wrap ``behaviour.tick`` and ``behaviour.stop`` (on this instance) with the pre/post-condition semantics."""
    inner_tick = behaviour.tick
    inner_stop = behaviour.stop
    behaviour.bt_conditions = conditions

    def tick() -> Iterator[py_trees.behaviour.Behaviour]:
        behaviour.bt_skipped = False  # what the last tick returned is not what this one returns
        imposed = conditions.pre(behaviour)
        if imposed is None:
            for node in inner_tick():
                if node is not behaviour:
                    yield node
            result: Returned = SKIPPED if getattr(behaviour, "bt_skipped", False) else behaviour.status
        else:
            result = imposed
        if result in (Status.SUCCESS, Status.FAILURE):
            conditions.post(result)
        if result is not SKIPPED:
            behaviour.status = result  # type: ignore[assignment]
        mark(behaviour, result)
        yield behaviour

    def stop(new_status: Status = Status.INVALID) -> None:
        was_running = behaviour.status == Status.RUNNING
        inner_stop(new_status)
        if was_running and new_status == Status.INVALID:
            conditions.run("_onHalted")

    behaviour.tick = tick  # type: ignore[method-assign]
    behaviour.stop = stop  # type: ignore[method-assign]
