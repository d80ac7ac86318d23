"""Python functions and classes as tree nodes: one decorator, no plugin hook to write.

A module that a project loads as a plugin (a file in its ``plugins/`` folder, ``--plugins DIR``, or an installed
entry point) only has to decorate its functions; every registry built for a tree (``domain_registry``) then knows
them, with the ports they declare::

    from bt_meta.bt.python_nodes import action, condition

    @action(inputs={"goal": str, "speed": float}, defaults={"speed": "0.5"}, outputs={"eta": float})
    def MoveBase(goal: str, speed: float) -> dict:
        return {"eta": 3.0 / speed}          # SUCCESS, and {eta} written

    @condition(inputs={"target": str})
    def IsVisible(target: str) -> bool:
        return target == "cup"

A function returns a bool (SUCCESS / FAILURE), a py_trees ``Status``, ``None`` (SUCCESS), or a dict of output
values (SUCCESS). A decorated class is instantiated once per node; its ``tick(**inputs)`` returns the same things,
RUNNING included for an action, and its optional ``halt()`` is called when the node is halted while RUNNING.

Offers:

* :func:`action`, :func:`condition` -- the decorators
* :func:`registered_node_types` -- the node types decorated so far in this process
* :func:`register_node_type` -- add a ready-made node type to them (ROS leaves declared in Python use it)
* :class:`PythonNode` -- the behaviour that calls the function or object
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import py_trees
from py_trees.common import Status

from bt_meta.bt.nodes.base import PortValue
from bt_meta.bt.registry import NodeType, PortSpec, RegistryError

_REGISTERED: dict[str, NodeType] = {}
_TYPE_NAMES = {str: "std::string", int: "int", float: "double", bool: "bool"}


class PythonNode(py_trees.behaviour.Behaviour):
    """Calls ``target(**inputs)`` on each tick and turns what it returns into a status (and output writes)."""

    def __init__(
        self,
        name: str,
        target: Callable[..., Any],
        inputs: dict[str, PortValue],
        outputs: dict[str, PortValue],
        *,
        condition: bool,
        halt: Callable[[], Any] | None = None,
    ) -> None:
        super().__init__(name)
        self.target = target
        self.inputs = inputs
        self.outputs = outputs
        self.condition = condition
        self.halt_target = halt

    def update(self) -> Status:
        values = {port: value.get() for port, value in self.inputs.items() if value.text is not None}
        result = self.target(**values)
        if isinstance(result, dict):
            for port, value in result.items():
                if port not in self.outputs:
                    raise RegistryError(f"{self.name}: returned output {port!r}, which it does not declare")
                if self.outputs[port].key is not None:
                    self.outputs[port].set(value)
            return Status.SUCCESS
        if result is None or result is True:
            return Status.SUCCESS
        if result is False:
            return Status.FAILURE
        if isinstance(result, Status) and result != Status.INVALID:
            if result == Status.RUNNING and self.condition:
                raise RegistryError(f"{self.name}: a condition cannot return RUNNING")
            return result
        raise RegistryError(f"{self.name}: returned {result!r}; expected a bool, a Status, None or a dict of outputs")

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING and self.halt_target is not None:
            self.halt_target()


def _ports(inputs: dict[str, Any], outputs: dict[str, Any], defaults: dict[str, str]) -> list[PortSpec]:
    specs = []
    for name, kind in inputs.items():
        specs.append(PortSpec(name, "input", _TYPE_NAMES.get(kind, str(kind)), defaults.get(name)))
    for name, kind in outputs.items():
        specs.append(PortSpec(name, "output", _TYPE_NAMES.get(kind, str(kind))))
    return specs


def _register(
    target: Any, category: str, name: str | None, inputs: dict[str, Any] | None, outputs: dict[str, Any] | None,
    defaults: dict[str, str] | None, description: str,
) -> Any:
    inputs, outputs, defaults = dict(inputs or {}), dict(outputs or {}), dict(defaults or {})
    node_id = name or target.__name__
    specs = _ports(inputs, outputs, defaults)
    by_name = {spec.name: spec for spec in specs}
    is_class = inspect.isclass(target)

    def factory(*, name: str, ports: dict[str, str], children: list[py_trees.behaviour.Behaviour]) -> PythonNode:
        values = {port: PortValue(by_name[port], ports.get(port)) for port in inputs}
        outs = {port: PortValue(by_name[port], ports.get(port)) for port in outputs}
        if is_class:
            instance = target()
            return PythonNode(name, instance.tick, values, outs, condition=category == "Condition",
                              halt=getattr(instance, "halt", None))
        return PythonNode(name, target, values, outs, condition=category == "Condition")

    doc = description or (inspect.getdoc(target) or "").split("\n")[0]
    _REGISTERED[node_id] = NodeType(node_id, category, specs, factory, doc)  # type: ignore[arg-type]
    return target


def action(
    target: Any = None,
    *,
    name: str | None = None,
    inputs: dict[str, Any] | None = None,
    outputs: dict[str, Any] | None = None,
    defaults: dict[str, str] | None = None,
    description: str = "",
) -> Any:
    """Register a function or class as an Action node (``@action`` or ``@action(inputs=..., ...)``)."""
    if target is not None:
        return _register(target, "Action", name, inputs, outputs, defaults, description)
    return lambda found: _register(found, "Action", name, inputs, outputs, defaults, description)


def condition(
    target: Any = None,
    *,
    name: str | None = None,
    inputs: dict[str, Any] | None = None,
    defaults: dict[str, str] | None = None,
    description: str = "",
) -> Any:
    """Register a function or class as a Condition node (it returns true/false, never RUNNING)."""
    if target is not None:
        return _register(target, "Condition", name, inputs, None, defaults, description)
    return lambda found: _register(found, "Condition", name, inputs, None, defaults, description)


def register_node_type(node_type: NodeType) -> NodeType:
    """Make ``node_type`` known to every registry built from now on, as a decorated function would be."""
    _REGISTERED[node_type.id] = node_type
    return node_type


def registered_node_types() -> list[NodeType]:
    return list(_REGISTERED.values())
