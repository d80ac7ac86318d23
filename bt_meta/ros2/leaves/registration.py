"""Registering ROS leaves: an ID bound to an interface type, ports bound to its fields, and when it succeeds.

BehaviorTree.ROS2's leaves are C++ subclasses (``RosActionNode<T>`` ...) registered under an ID with a
``RosNodeParams`` (default server or topic name, ``server_timeout`` 1000 ms, ``wait_for_server_timeout`` 500 ms);
each fills the goal from its ports and turns the result into SUCCESS or FAILURE in code. Here the same is declared,
in YAML (``ros2_leaves:``, :func:`load_leaves_file`) or in Python (:func:`ros_leaf`)::

    ros2_leaves:
      - ID: CloseGripper
        kind: action                          # action | service | topic_sub | topic_pub
        type: control_msgs/action/GripperCommand
        action_name: /gripper_controller/gripper_cmd   # the port's default (RosNodeParams' default_port_value)
        server_timeout: 1000                  # ms: BT.ROS2's defaults, also ports of the node
        wait_for_server_timeout: 500
        inputs:                               # input port -> goal / request / message field
          position: command.position
          max_effort: {field: command.max_effort, default: 10.0}
        outputs:                              # output port <- result / response / message field
          reached: reached_goal
        success_if: reached                   # a BT.CPP script over the output ports

Every type and field is checked when the file is read: an unknown type, field, port or script name is a
:class:`~bt_meta.errors.ConfigError` at ``path:line:column`` (the CLI exits 2).

Offers:

* :class:`InputField`, :class:`LeafSpec` -- one registration, resolved against its interface
* :func:`load_leaves_file` -- a YAML file -> node types; :func:`leaves_from_text` the same for text
* :func:`ros_leaf` -- the Python form; registers the node type like ``@action`` does (plugins/ files)
* :func:`node_type` -- a :class:`LeafSpec` as the registry's :class:`~bt_meta.bt.registry.NodeType`
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bt_meta.bt.registry import NodeType, PortSpec
from bt_meta.bt.script import CompiledScript, ScriptSyntaxError, compile_script
from bt_meta.bt.script.ast import Name
from bt_meta.bt.script.parser import walk
from bt_meta.errors import ConfigError
from bt_meta.ros2.leaves.fields import KINDS, ROS_NAME, Field, import_interface, resolve_field
from bt_meta.world._yaml_nodes import YamlNodeReader

__all__ = ["CATEGORY", "NAME_PORT", "InputField", "LeafSpec", "leaves_from_text", "load_leaves_file", "node_type",
           "ros_leaf"]

NAME_PORT = {"action": "action_name", "service": "service_name", "topic_sub": "topic_name",
             "topic_pub": "topic_name"}
"""The port naming the server or topic, as BehaviorTree.ROS2 names it."""
CATEGORY = {"action": "Action", "service": "Action", "topic_sub": "Condition", "topic_pub": "Condition"}
"""BehaviorTree.ROS2's base classes: RosActionNode and RosServiceNode are actions, the topic nodes conditions."""
SERVER_TIMEOUT_MS = 1000
WAIT_FOR_SERVER_TIMEOUT_MS = 500
_TIMED = ("action", "service")
_ID = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_KEYS = {"ID", "kind", "type", "action_name", "service_name", "topic_name", "server_timeout",
         "wait_for_server_timeout", "inputs", "outputs", "success_if", "latch", "description"}


@dataclass(frozen=True)
class InputField:
    field: Field
    default: str | None = None


@dataclass(frozen=True)
class LeafSpec:
    """One ROS leaf: ``inputs`` fill the goal / request / message, ``outputs`` are read from the result /
    response / message, ``success_if`` (over the output ports) decides SUCCESS when given."""

    id: str
    kind: str
    type_name: str
    interface: Any
    default_name: str | None
    inputs: dict[str, InputField] = field(default_factory=dict)
    outputs: dict[str, Field] = field(default_factory=dict)
    success_if: CompiledScript | None = None
    server_timeout: int = SERVER_TIMEOUT_MS
    wait_for_server_timeout: int = WAIT_FOR_SERVER_TIMEOUT_MS
    latch: bool = False
    description: str = ""

    @property
    def name_port(self) -> str:
        return NAME_PORT[self.kind]

    @property
    def category(self) -> str:
        return CATEGORY[self.kind]


def _messages(kind: str, interface: Any) -> tuple[Any, Any]:
    """The message classes the input ports fill and the output ports read (``None`` where the kind has none)."""
    if kind == "action":
        return interface.Goal, interface.Result
    if kind == "service":
        return interface.Request, interface.Response
    if kind == "topic_pub":
        return interface, None
    return None, interface


class _Problem(Exception):
    """A registration mistake; ``where`` names the YAML node it is about (or nothing, in Python)."""

    def __init__(self, message: str, where: Any = None) -> None:
        super().__init__(message)
        self.message = message
        self.where = where


def _build(values: dict[str, Any], at: dict[str, Any]) -> LeafSpec:
    """A LeafSpec from plain values; ``at[key]`` (and ``at[(key, name)]``) is where each came from."""
    leaf_id = values.get("ID")
    if not isinstance(leaf_id, str) or not _ID.match(leaf_id):
        raise _Problem(f"ID: {leaf_id!r} is not a node ID (letters, digits, _)", at.get("ID"))
    from bt_meta.bt.nodes import builtin_node_types

    if leaf_id in {builtin.id for builtin in builtin_node_types()}:
        raise _Problem(f"ID {leaf_id!r} is a BehaviorTree.CPP built-in node; choose another", at.get("ID"))
    kind = values.get("kind")
    if kind not in KINDS:
        raise _Problem(f"{leaf_id}: kind {kind!r} is not one of {', '.join(KINDS)}", at.get("kind"))
    type_name = values.get("type")
    if not isinstance(type_name, str):
        raise _Problem(f"{leaf_id}: type must name an interface, e.g. std_msgs/msg/Bool", at.get("type"))
    if f"/{KINDS[kind]}/" not in type_name:
        raise _Problem(f"{leaf_id}: a {kind} leaf needs a {KINDS[kind]} type (package/{KINDS[kind]}/Name), got "
                       f"{type_name!r}", at.get("type"))
    try:
        interface = import_interface(type_name)
    except LookupError as error:
        raise _Problem(f"{leaf_id}: {error}", at.get("type")) from None
    name_port = NAME_PORT[kind]
    for other in set(NAME_PORT.values()) - {name_port}:
        if other in values:
            raise _Problem(f"{leaf_id}: a {kind} leaf is named by {name_port}, not {other}", at.get(other))
    default_name = values.get(name_port)
    if default_name is not None and (not isinstance(default_name, str) or not ROS_NAME.match(default_name)):
        raise _Problem(f"{leaf_id}: {name_port} {default_name!r} is not a valid ROS 2 name", at.get(name_port))
    timeouts = {}
    for key, default in (("server_timeout", SERVER_TIMEOUT_MS), ("wait_for_server_timeout",
                                                                 WAIT_FOR_SERVER_TIMEOUT_MS)):
        value = values.get(key, default)
        if key in values and kind not in _TIMED:
            raise _Problem(f"{leaf_id}: {key} applies to action and service leaves", at.get(key))
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise _Problem(f"{leaf_id}: {key} must be a whole number of milliseconds (>= 0)", at.get(key))
        timeouts[key] = value
    latch = values.get("latch", False)
    if "latch" in values and kind != "topic_sub":
        raise _Problem(f"{leaf_id}: latch applies to topic_sub leaves", at.get("latch"))
    if not isinstance(latch, bool):
        raise _Problem(f"{leaf_id}: latch must be true or false", at.get("latch"))
    fills, reads = _messages(kind, interface)
    reserved = {"ID", "name", name_port, *(("server_timeout", "wait_for_server_timeout") if kind in _TIMED else ())}
    inputs: dict[str, InputField] = {}
    given_inputs = values.get("inputs") or {}
    if given_inputs and fills is None:
        raise _Problem(f"{leaf_id}: a {kind} leaf has no input fields (it only reads messages)", at.get("inputs"))
    for port, target in given_inputs.items():
        where = at.get(("inputs", port), at.get("inputs"))
        _check_port(leaf_id, port, reserved, where)
        dotted, default = (target.get("field"), target.get("default")) if isinstance(target, dict) else (target, None)
        resolved = _field(leaf_id, fills, dotted, at.get(("inputs", port, "field"), where))
        if default is not None:
            default = _literal(default)
            try:
                resolved.convert(default)
            except (TypeError, ValueError):
                raise _Problem(f"{leaf_id}: default of input {port!r}: {default!r} is no {resolved.port_type} "
                               f"({resolved.name} is a {resolved.ros_type})",
                               at.get(("inputs", port, "default"), where)) from None
        inputs[port] = InputField(resolved, default)
    outputs: dict[str, Field] = {}
    given_outputs = values.get("outputs") or {}
    if given_outputs and reads is None:
        raise _Problem(f"{leaf_id}: a {kind} leaf has no output fields (it only sends)", at.get("outputs"))
    for port, dotted in given_outputs.items():
        where = at.get(("outputs", port), at.get("outputs"))
        _check_port(leaf_id, port, reserved | set(inputs), where)
        outputs[port] = _field(leaf_id, reads, dotted, at.get(("outputs", port, "field"), where))
    success_if = None
    text = values.get("success_if")
    if text is not None:
        if kind == "topic_pub":
            raise _Problem(f"{leaf_id}: success_if applies to leaves that receive something (a publisher succeeds "
                           "once it published)", at.get("success_if"))
        success_if = _script(leaf_id, str(text), set(outputs), at.get("success_if"))
    return LeafSpec(leaf_id, kind, type_name, interface, default_name, inputs, outputs, success_if,
                    timeouts["server_timeout"], timeouts["wait_for_server_timeout"], latch,
                    str(values.get("description") or ""))


def _literal(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ";".join(_literal(item) for item in value)
    return str(value)


def _check_port(leaf_id: str, port: Any, reserved: set[str], where: Any) -> None:
    if not isinstance(port, str) or not _ID.match(port):
        raise _Problem(f"{leaf_id}: port {port!r} is not a port name (letters, digits, _)", where)
    if port in reserved:
        raise _Problem(f"{leaf_id}: port {port!r} is taken (the node's own ports: {', '.join(sorted(reserved))})",
                       where)


def _field(leaf_id: str, message_class: Any, dotted: Any, where: Any) -> Field:
    if not isinstance(dotted, str) or not dotted:
        raise _Problem(f"{leaf_id}: a port maps a field path such as command.position, got {dotted!r}", where)
    try:
        return resolve_field(message_class, dotted)
    except LookupError as error:
        raise _Problem(f"{leaf_id}: {error}", where) from None


def _script(leaf_id: str, text: str, outputs: set[str], where: Any) -> CompiledScript:
    try:
        script = compile_script(text)
    except ScriptSyntaxError as error:
        raise _Problem(f"{leaf_id}: success_if: {error.message}", where) from None
    for expr in script.exprs:
        for part in walk(expr):
            if isinstance(part, Name) and part.name not in outputs:
                raise _Problem(f"{leaf_id}: success_if reads {part.name!r}, which is no output port (outputs: "
                               f"{', '.join(sorted(outputs)) or 'none'})", where)
    return script


def node_type(spec: LeafSpec) -> NodeType:
    """The registry's node type: the name port, the timeouts (action, service), then the mapped ports."""
    from bt_meta.bt.nodes.base import PortValue
    from bt_meta.ros2.leaves.behaviours import LEAF_CLASSES

    ports = [PortSpec(spec.name_port, "input", "std::string", spec.default_name,
                      f"{'topic' if spec.kind.startswith('topic') else spec.kind} name ({spec.type_name})")]
    if spec.kind in _TIMED:
        ports.append(PortSpec("server_timeout", "input", "unsigned", str(spec.server_timeout),
                              "ms to wait for the goal/request to be answered"))
        ports.append(PortSpec("wait_for_server_timeout", "input", "unsigned", str(spec.wait_for_server_timeout),
                              "ms the first tick waits for the server to be discovered"))
    for port, item in spec.inputs.items():
        ports.append(PortSpec(port, "input", item.field.port_type, item.default, item.field.name))
    for port, read in spec.outputs.items():
        ports.append(PortSpec(port, "output", read.port_type, None, read.name))
    by_name = {port.name: port for port in ports}
    leaf_class = LEAF_CLASSES[spec.kind]

    def factory(*, name: str, ports: dict[str, str], children: list[Any]) -> Any:
        values = {port: PortValue(by_name[port], ports.get(port)) for port in by_name}
        return leaf_class(name, spec, values)

    description = spec.description or f"ROS 2 {spec.kind.replace('_', ' ')} leaf ({spec.type_name})"
    return NodeType(spec.id, spec.category, ports, factory, description)  # type: ignore[arg-type]


class _File(YamlNodeReader):
    def leaves(self, text: str) -> list[NodeType]:
        from bt_meta.safe_yaml import compose_yaml

        root = compose_yaml(text, str(self.path), ConfigError)
        if root is None:
            raise ConfigError("empty ROS leaves file: expected ros2_leaves: [...]", self.path)
        top = self.mapping(root, "the ROS leaves file", {"ros2_leaves"})
        if "ros2_leaves" not in top:
            raise self.error("missing key 'ros2_leaves' (a list of leaves)", root)
        types: list[NodeType] = []
        seen: dict[str, yaml.Node] = {}
        for item in self.sequence(top["ros2_leaves"][1], "ros2_leaves"):
            entries = self.mapping(item, "a ROS leaf", _KEYS)
            values: dict[str, Any] = {}
            at: dict[Any, yaml.Node] = {}
            for key, (_key, value_node) in entries.items():
                at[key] = value_node
                if key in ("inputs", "outputs"):
                    values[key] = self.ports(key, value_node, at)
                else:
                    values[key] = self.scalar(value_node, key)
            if "ID" not in entries or "kind" not in entries or "type" not in entries:
                missing = next(k for k in ("ID", "kind", "type") if k not in entries)
                raise self.error(f"a ROS leaf: missing key {missing!r}", item)
            if values["ID"] in seen:
                raise self.error(f"ID {values['ID']!r} is registered twice", entries["ID"][1])
            seen[values["ID"]] = entries["ID"][1]
            try:
                types.append(node_type(_build(values, at)))
            except _Problem as problem:
                raise self.error(problem.message, problem.where if problem.where is not None else item) from None
        return types

    def ports(self, key: str, node: yaml.Node, at: dict[Any, yaml.Node]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for port, (key_node, value) in self.mapping(node, key).items():
            at[(key, port)] = key_node
            if key == "inputs" and isinstance(value, yaml.MappingNode):
                entries = self.mapping(value, f"inputs.{port}", {"field", "default"})
                if "field" not in entries:
                    raise self.error(f"inputs.{port}: missing key 'field'", value)
                at[(key, port, "field")] = entries["field"][1]
                mapped = {"field": self.scalar(entries["field"][1], f"inputs.{port}.field")}
                if "default" in entries:
                    at[(key, port, "default")] = entries["default"][1]
                    default = entries["default"][1]
                    mapped["default"] = ([self.scalar(v, f"inputs.{port}.default") for v in default.value]
                                         if isinstance(default, yaml.SequenceNode)
                                         else self.scalar(default, f"inputs.{port}.default"))
                out[port] = mapped
            else:
                at[(key, port, "field")] = value
                out[port] = self.scalar(value, f"{key}.{port}")
        return out


def leaves_from_text(text: str, path: str | Path) -> list[NodeType]:
    return _File(Path(path)).leaves(text)


def load_leaves_file(path: str | Path) -> list[NodeType]:
    """The node types a ``ros2_leaves:`` YAML file registers (every type and field checked)."""
    from bt_meta.user_files import read_user_text

    path = Path(path)
    return leaves_from_text(read_user_text(path, what="ROS leaves file", error=ConfigError), path)


def ros_leaf(
    id: str,  # the BT.CPP word
    kind: str,
    type: str,  # the ROS word
    *,
    name: str | None = None,
    inputs: dict[str, str | dict[str, Any]] | None = None,
    outputs: dict[str, str] | None = None,
    success_if: str | None = None,
    server_timeout: int = SERVER_TIMEOUT_MS,
    wait_for_server_timeout: int = WAIT_FOR_SERVER_TIMEOUT_MS,
    latch: bool | None = None,
    description: str = "",
) -> NodeType:
    """Register a ROS leaf from Python (a file in ``plugins/``), as the YAML form does; ``name`` is the default of
    its ``action_name`` / ``service_name`` / ``topic_name`` port. Raises ConfigError on a bad type or field."""
    from bt_meta.bt.python_nodes import register_node_type

    values: dict[str, Any] = {"ID": id, "kind": kind, "type": type, "inputs": inputs or {},
                              "outputs": outputs or {}, "description": description}
    if kind in NAME_PORT and name is not None:
        values[NAME_PORT[kind]] = name
    if kind in _TIMED:
        values.update(server_timeout=server_timeout, wait_for_server_timeout=wait_for_server_timeout)
    if latch is not None:
        values["latch"] = latch
    if success_if is not None:
        values["success_if"] = success_if
    try:
        made = node_type(_build(values, {}))
    except _Problem as problem:
        raise ConfigError(problem.message) from None
    register_node_type(made)
    return made
