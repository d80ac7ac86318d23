"""What every ROS leaf does the same way: read its ports, fill a message, write its outputs, decide its status,
and say why it failed.

A leaf is a py_trees behaviour (``initialise`` / ``update`` / ``terminate``) built by the registry from a
:class:`~bt_meta.ros2.leaves.registration.LeafSpec`. A failure carries a :class:`~bt_meta.bt.failures.Failure`
in ``failure`` (the Monitor around an action leaf records it): ``evidence`` holds the interface, the server or
topic name and BehaviorTree.ROS2's error name (``SERVER_UNREACHABLE``, ``SEND_GOAL_TIMEOUT``,
``GOAL_REJECTED_BY_SERVER``, ``ACTION_ABORTED``, ``ACTION_CANCELLED``, ``INVALID_GOAL``, ``SERVICE_UNREACHABLE``,
``SERVICE_TIMEOUT``, ``INVALID_REQUEST``, ``RESULT_REFUSED`` when ``success_if`` is false).

Offers:

* :class:`RosLeaf` -- the shared behaviour; each kind's module subclasses it
"""

from __future__ import annotations

import time
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.failures import Failure, FailureKind
from bt_meta.bt.nodes.base import PortValue
from bt_meta.bt.script import DictEnvironment, ScriptRuntimeError
from bt_meta.ros2.leaves.fields import ROS_NAME
from bt_meta.ros2.leaves.runtime import LeafRuntime, runtime

__all__ = ["RosLeaf"]

_PLACEHOLDER = "__default__placeholder__"  # BT.ROS2's "use the registered default" value of a name port


class RosLeaf(py_trees.behaviour.Behaviour):
    waits_on_outside = True
    """Its result comes from another process: ``bt-meta tick`` leaves time between ticks (``--tick-period``)."""
    shown_in_trace = True
    """``bt-meta tick`` prints its status every tick."""

    def __init__(self, name: str, spec: Any, ports: dict[str, PortValue]) -> None:
        super().__init__(name)
        self.spec = spec
        self.ports = ports
        self.failure: Failure | None = None
        self.started = 0.0
        self._runtime: LeafRuntime | None = None
        if self.ports[spec.name_port].key is None:
            # a literal (or registered) name: its client, publisher or subscription is made now, as BT.ROS2's
            # constructor makes it, so discovery runs while the rest of the tree loads
            try:
                name = self.ros_name()
            except ValueError as error:
                if "is not a valid ROS 2 name" in str(error):
                    raise  # the reader locates it: path:line:column, before anything ticks
                return  # an empty name: reported when ticked
            self.connect(name)

    # -- ports ----------------------------------------------------------------------------------------------------

    def value(self, port: str) -> Any:
        return self.ports[port].get()

    def ros_name(self) -> str:
        """The server or topic this tick talks to: the name port, else the registered default."""
        name = self.value(self.spec.name_port)
        if name in (None, "", _PLACEHOLDER):
            name = self.spec.default_name
        if not name:
            raise ValueError(f"{self.spec.name_port} is empty and {self.spec.id} registers no default")
        if not ROS_NAME.match(str(name)):
            raise ValueError(f"{self.spec.name_port} {name!r} is not a valid ROS 2 name")
        return str(name)

    def shared(self) -> LeafRuntime:
        """The runtime this leaf talks through (kept while it closes: a halt at exit cancels through it)."""
        if self._runtime is None or self._runtime.finished:
            self._runtime = runtime()
        return self._runtime

    def connect(self, name: str) -> Any:
        """The client, publisher or subscription for ``name`` (each kind makes its own)."""
        raise NotImplementedError

    def milliseconds(self, port: str) -> float:
        return float(self.value(port)) / 1000.0

    def fill(self, message_class: Any) -> Any:
        """A message with every input port that has a value assigned to its field (raises ValueError)."""
        message = message_class()
        for port, item in self.spec.inputs.items():
            given = self.ports[port]
            if given.text is None:
                continue
            item.field.assign(message, given.get())
        return message

    def outputs(self, message: Any) -> dict[str, Any]:
        """Every output field's value by port; written to the ports that name a blackboard entry."""
        values = {port: field.read(message) for port, field in self.spec.outputs.items()}
        for port, value in values.items():
            if self.ports[port].key is not None:
                self.ports[port].set(value)
        return values

    def accepted(self, values: dict[str, Any]) -> bool:
        if self.spec.success_if is None:
            return True
        try:
            return self.spec.success_if.test(DictEnvironment(dict(values)))
        except ScriptRuntimeError as error:
            raise ValueError(str(error)) from None

    # -- status ---------------------------------------------------------------------------------------------------

    def initialise(self) -> None:
        self.failure = None
        self.started = time.monotonic()

    def elapsed(self) -> float:
        return time.monotonic() - self.started

    def fail(self, error: str, message: str, *, kind: FailureKind = FailureKind.PHYSICAL, name: str | None = None,
             **evidence: Any) -> Status:
        """FAILURE, with the reason in ``failure`` and ``feedback_message``."""
        record = {"interface": self.spec.type_name, "leaf_kind": self.spec.kind, "error": error}
        if name is not None:
            record[self.spec.name_port] = name
        record.update(evidence)
        self.failure = Failure(kind=kind, message=f"{self.spec.id}: {message}", action=self.spec.id,
                               evidence=record, node_name=self.name)
        self.feedback_message = self.failure.message
        return Status.FAILURE

    def finish(self, message: Any, name: str, refused: str) -> Status:
        """SUCCESS or FAILURE from a received ``message``: outputs written, then ``success_if``."""
        try:
            values = self.outputs(message)
            ok = self.accepted(values)
        except ValueError as error:
            return self.fail("RESULT_REFUSED", f"{refused}: {error}", kind=FailureKind.INTERNAL, name=name)
        if ok:
            return Status.SUCCESS
        shown = ", ".join(f"{port}={value!r}" for port, value in values.items())
        return self.fail("RESULT_REFUSED", f"{refused}: success_if [{self.spec.success_if.source}] is false "
                         f"({shown})", name=name, outputs=values)

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING:
            self.halt()

    def halt(self) -> None:
        """Interrupted while RUNNING (BehaviorTree.ROS2's ``halt``)."""
