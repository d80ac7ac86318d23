"""The node types a task file's domain adds to a registry: one Action per primitive, and the guard condition.

A compiled tree and a tree loaded from XML are built by the same factories, so ticking a compiled plan and
ticking its XML give the same behaviours.

Offers:

* :func:`domain_registry` -- BehaviorTree.CPP built-ins + ``CheckCondition`` + the domain's primitives + the
  ``@action``/``@condition`` nodes of :mod:`bt_meta.bt.python_nodes` + whatever
  plugins register through ``bt_meta_register_nodes``
* :func:`primitive_node_type` -- the Action node type of one primitive (ID = its name, one port per parameter)
* :func:`check_condition_node_type` -- the ``CheckCondition`` guard (ports ``condition``, ``bindings``, ``method``,
  ``output_prefix``, ``record``)
* :func:`node_id_of` -- the decomposition-node id at the start of a behaviour name (``"n3 place(b0)"`` -> ``"n3"``)
"""

from __future__ import annotations

import re
from typing import Any

from bt_meta.bt.actions import PrimitiveAction
from bt_meta.bt.guards import CheckCondition, compile_guard, parse_bindings
from bt_meta.bt.registry import NodeRegistry, NodeType, PortSpec, RegistryError, default_registry
from bt_meta.errors import PluginError

CHECK_CONDITION = "CheckCondition"
RESERVED_PORTS = frozenset({"ID", "name"})
_NODE_ID_RE = re.compile(r"^(n\d+)(?:\s|$)")


def node_id_of(name: str) -> str | None:
    match = _NODE_ID_RE.match(name)
    return match.group(1) if match else None


def primitive_node_type(primitive: Any) -> NodeType:
    """An Action node type for ``primitive``; its ports are the parameters, in order."""
    for parameter in primitive.parameters:
        if parameter in RESERVED_PORTS or parameter.startswith("_"):
            raise RegistryError(f"primitive {primitive.name}: parameter ?{parameter} cannot be a BehaviorTree.CPP "
                                "port name (reserved); rename it")
    parameters = list(primitive.parameters)

    def factory(name: str, ports: dict[str, str], children: list[Any]) -> PrimitiveAction:
        return PrimitiveAction(name, primitive.name, [ports[p] for p in parameters], primitive=primitive,
                               node_id=node_id_of(name))

    types = list(getattr(primitive, "types", []) or [None] * len(parameters))
    ports = [PortSpec(p, "input", "std::string", None, f"?{p}" + (f" - {t}" if t else ""))
             for p, t in zip(parameters, types, strict=False)]
    return NodeType(primitive.name, "Action", ports, factory,
                    description=f"primitive {primitive.name}: {primitive.precondition.source}")


def check_condition_node_type(domain: Any) -> NodeType:
    """The guard node: a condition in the task-file language, checked against the belief state."""

    def factory(name: str, ports: dict[str, str], children: list[Any]) -> CheckCondition:
        if domain is None:
            raise RegistryError("CheckCondition needs the task file whose predicates it uses (--task-file)")
        bindings = parse_bindings(ports.get("bindings", ""))
        prefix = ports.get("output_prefix", "") or None
        condition = compile_guard(ports["condition"], domain, bindings.keys())
        record = ports.get("record", "true").strip().lower() not in ("false", "0", "no")
        return CheckCondition(name, condition, bindings, output_prefix=prefix, record=record,
                              method=ports.get("method") or None, node_id=node_id_of(name))

    return NodeType(
        CHECK_CONDITION,
        "Condition",
        [
            PortSpec("condition", "input", "std::string", None, "condition in the task-file language"),
            PortSpec("bindings", "input", "std::string", "", "var=value;var={key} given before matching"),
            PortSpec("method", "input", "std::string", "", "the method whose precondition this is"),
            PortSpec("output_prefix", "input", "std::string", "", "write bound variables to {prefix<var>}"),
            PortSpec("record", "input", "bool", "true", "record a precondition failure when it does not hold"),
        ],
        factory,
        description="a method precondition checked against the belief state (/bt_meta/state)",
    )


def domain_registry(domain: Any = None, plugins: Any = None, base: NodeRegistry | None = None) -> NodeRegistry:
    """A registry for trees of ``domain``: built-ins, ``CheckCondition``, primitives, then plugin node types."""
    registry = base.copy() if base is not None else default_registry()
    if CHECK_CONDITION not in registry:
        registry.register(check_condition_node_type(domain))
    if domain is not None:
        for primitive in domain.primitives.values():
            if primitive.name in registry:
                raise RegistryError(f"primitive {primitive.name!r} has the ID of a built-in node; rename it")
            registry.register(primitive_node_type(primitive))
    if plugins is not None and plugins.implements("bt_meta_register_nodes"):
        result = plugins.call("bt_meta_register_nodes", registry=registry, domain=domain)
        if result.errors:
            raise PluginError(result.errors[0].message)
    from bt_meta.bt.python_nodes import registered_node_types

    for node_type in registered_node_types():  # @action / @condition in any loaded module
        if node_type.id not in registry:
            registry.register(node_type)
    return registry
