"""Interface types by name and the fields of their messages: what a port of a ROS leaf maps to.

A type is named as ROS 2 names it (``std_msgs/msg/Bool``, ``lifecycle_msgs/srv/ChangeState``,
``control_msgs/action/GripperCommand``) and imported from the installed interface packages (``control_msgs`` is
generated from the kept definitions first, :mod:`bt_meta.ros2.interfaces`). A field is a dotted path into a message
(``command.position``); only fields holding a value a port can carry may be mapped: a bool, an integer, a float, a
string, or an array of those (written ``1;2;3`` in XML, as BT.CPP writes vectors). A field holding a whole message
is refused, naming its fields.

Offers:

* :data:`KINDS` -- leaf kind -> the interface kind it needs (``action``, ``srv``, ``msg``); :data:`ROS_NAME`
* :func:`import_interface` -- ``pkg/kind/Name`` -> the Python class (raises ``LookupError`` saying why)
* :class:`Field` -- a resolved field path: its port type name, :meth:`Field.assign` into a message,
  :meth:`Field.read` out of one
* :func:`resolve_field` -- a dotted path in a message class -> :class:`Field` (raises ``LookupError``)
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from typing import Any

__all__ = ["KINDS", "ROS_NAME", "Field", "import_interface", "resolve_field"]

KINDS = {"action": "action", "service": "srv", "topic_sub": "msg", "topic_pub": "msg"}
ROS_NAME = re.compile(r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$")
"""A topic, service or action name (absolute or relative, no substitutions)."""
_TYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(msg|srv|action)/([A-Z][A-Za-z0-9]*)$")
_SIGNED = {"int8", "int16", "int32", "int64", "char"}
_UNSIGNED = {"uint8", "uint16", "uint32", "uint64", "byte", "octet"}
_FLOATS = {"float", "double", "float32", "float64"}
_ARRAY = re.compile(r"^(?:sequence<([^,>]+)(?:,\s*\d+)?>|([^\[]+)\[(?:<=)?\d*\])$")


def import_interface(name: str) -> Any:
    """The class of interface ``pkg/kind/Name``; ``LookupError`` when the name is malformed or not installed."""
    match = _TYPE.match(name)
    if match is None:
        raise LookupError(f"{name!r} is not an interface type (expected package/msg|srv|action/Name, e.g. "
                          "std_msgs/msg/Bool)")
    package, kind, type_name = match.groups()
    if package == "control_msgs":
        from bt_meta.ros2.interfaces import load_control_msgs

        load_control_msgs()
    try:
        module = importlib.import_module(f"{package}.{kind}")
    except ImportError:
        raise LookupError(f"unknown interface type {name!r}: no installed package {package!r} with {kind} "
                          "interfaces") from None
    found = getattr(module, type_name, None)
    if found is None:
        known = sorted(n for n in dir(module) if n[:1].isupper() and not n.startswith("Metaclass_"))
        raise LookupError(f"unknown interface type {name!r}; {package}/{kind} has: {', '.join(known) or 'none'}")
    return found


def _scalar_port_type(ros_type: str) -> str | None:
    base = ros_type.split("<=")[0]
    if base == "boolean":
        return "bool"
    if base in _SIGNED:
        return "int"
    if base in _UNSIGNED:
        return "unsigned"
    if base in _FLOATS:
        return "double"
    if base in ("string", "wstring"):
        return "std::string"
    return None


@dataclass(frozen=True)
class Field:
    """One mapped field: ``path`` into the message, the ROS type, and the BT.CPP port type it is carried as."""

    path: tuple[str, ...]
    ros_type: str
    port_type: str
    element: str | None = None
    """For an array field, the port type of one element (``double``, ``int`` ...); else ``None``."""

    @property
    def name(self) -> str:
        return ".".join(self.path)

    def convert(self, value: Any) -> Any:
        """A port value (converted literal, blackboard value, ``a;b;c`` text) as the field's Python value."""
        if self.element is not None:
            items = value.split(";") if isinstance(value, str) else list(value)
            return [_scalar(self.element, item) for item in items if not (isinstance(item, str) and not item.strip())]
        return _scalar(self.port_type, value)

    def assign(self, message: Any, value: Any) -> None:
        """Set the field of ``message`` (raises ``ValueError`` naming the field when the value does not fit)."""
        target = message
        for part in self.path[:-1]:
            target = getattr(target, part)
        try:
            setattr(target, self.path[-1], self.convert(value))
        except (AssertionError, TypeError, ValueError) as error:
            raise ValueError(f"field {self.name} ({self.ros_type}): cannot take {value!r} ({error or 'out of range'})"
                             ) from None

    def read(self, message: Any) -> Any:
        value = message
        for part in self.path:
            value = getattr(value, part)
        if self.element is not None:
            return [item.item() if hasattr(item, "item") else item for item in list(value)]
        return value.item() if hasattr(value, "item") else value


def _scalar(port_type: str, value: Any) -> Any:
    if port_type == "bool":
        if isinstance(value, str):
            lowered = value.strip().lower()
            if lowered not in ("true", "false", "1", "0"):
                raise ValueError(f"{value!r} is not a bool")
            return lowered in ("true", "1")
        return bool(value)
    if port_type in ("int", "unsigned"):
        if isinstance(value, float) and not value.is_integer():
            raise ValueError(f"{value!r} is not an integer")
        return int(value.strip(), 10) if isinstance(value, str) else int(value)
    if port_type == "double":
        return float(value)
    return str(value)


def _nested_class(slot: Any) -> Any:
    """The message class a NamespacedType slot names (``lifecycle_msgs/Transition`` -> its class)."""
    module = importlib.import_module(".".join(slot.namespaces))
    return getattr(module, slot.name)


def resolve_field(message_class: Any, dotted: str) -> Field:
    """``dotted`` in ``message_class``; ``LookupError`` names the message's fields when a part is unknown."""
    parts = tuple(dotted.split("."))
    current = message_class
    for index, part in enumerate(parts):
        fields = current.get_fields_and_field_types()
        if part not in fields:
            where = ".".join(parts[:index]) or _class_name(message_class)
            raise LookupError(f"{_class_name(current)} has no field {part!r} (in {dotted!r}); fields of {where}: "
                              f"{', '.join(fields) or 'none'}")
        ros_type = fields[part]
        last = index == len(parts) - 1
        scalar = _scalar_port_type(ros_type)
        array = _ARRAY.match(ros_type)
        if scalar is not None or array is not None:
            if not last:
                raise LookupError(f"field {'.'.join(parts[:index + 1])} is a {ros_type}, it has no field "
                                  f"{parts[index + 1]!r}")
            if scalar is not None:
                return Field(parts, ros_type, scalar)
            element = _scalar_port_type((array.group(1) or array.group(2)).strip())  # type: ignore[union-attr]
            if element is None:
                raise LookupError(f"field {dotted} is a {ros_type}: only arrays of numbers, bools or strings can "
                                  "be a port")
            return Field(parts, ros_type, f"std::vector<{'std::string' if element == 'std::string' else element}>",
                         element)
        slot = current.SLOT_TYPES[list(fields).index(part)]
        nested = _nested_class(slot)
        if last:
            raise LookupError(f"field {dotted} is a whole message ({ros_type}); map one of its fields: "
                              f"{', '.join(f'{dotted}.{f}' for f in nested.get_fields_and_field_types())}")
        current = nested
    raise LookupError(f"empty field path {dotted!r}")  # pragma: no cover - split never yields no parts


def _class_name(message_class: Any) -> str:
    module = message_class.__module__.split(".")
    return f"{module[0]}/{message_class.__name__}" if module else message_class.__name__
