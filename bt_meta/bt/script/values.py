"""BehaviorTree.CPP's value rules for scripts: what is a number, how values convert, print and compare.

BT.CPP keeps script values in ``BT::Any``: 64-bit integers (integer literals, ``true``/``false``), doubles (every
arithmetic, comparison and logical result), strings, and whatever C++ type a node wrote. Here: ``int``, ``float``,
``str`` and ``bool`` (from nodes); any other Python object is opaque.

Offers:

* :func:`is_number`, :func:`to_double`, :func:`string_to_double`, :func:`to_string`, :func:`to_bool`,
  :func:`to_int64` -- the conversions BT.CPP applies (errors raise :class:`ScriptRuntimeError`)
* :func:`convert_into` -- BT.CPP's ``Any::copyInto``: a new value converted to the type an entry already has
* :func:`compare` -- one comparison with BT.CPP's epsilon for ``==``/``!=`` on numbers
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from bt_meta.bt.script.errors import ScriptRuntimeError

FLOAT_EPSILON = 1.1920928955078125e-07  # std::numeric_limits<float>::epsilon(), BT.CPP's tolerance for ==
INT64_MIN = -(2**63)
INT64_MAX = 2**63 - 1


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float))


def to_double(value: Any) -> float:
    return float(value)


# std::stod reads the longest prefix that is a number ("1ab" -> 1.0) and fails only when there is none.
_DOUBLE_PREFIX = re.compile(
    r"\s*([+-]?(?:0[xX][0-9a-fA-F]+|(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan))", re.IGNORECASE
)


def parse_double(text: str) -> float:
    match = _DOUBLE_PREFIX.match(text)
    if match is None:
        raise ScriptRuntimeError("Any failed string to number conversion")
    number = match.group(1)
    if "x" in number.lower() and "n" not in number.lower():
        return float(int(number, 16))
    return float(number)


def string_to_double(text: str, enums: Mapping[str, int]) -> float:
    """BT.CPP's ``StringToDouble``: "true"/"false", an enum name, or a number written as a string."""
    if text == "true":
        return 1.0
    if text == "false":
        return 0.0
    if text in enums:
        return float(enums[text])
    return parse_double(text)


def to_string(value: Any) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "-nan" if math.copysign(1.0, value) < 0 else "nan"
        return f"{value:f}"
    raise ScriptRuntimeError(f"cannot convert a {type(value).__name__} to a string")


def to_bool(value: Any) -> bool:
    """``Any::cast<bool>``: integers must be 0 or 1, doubles must not be negative (true when non-zero), strings
    never convert."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        if value in (0, 1):
            return bool(value)
        raise ScriptRuntimeError("Implicit casting to bool is not allowed")
    if isinstance(value, float):
        if value < 0:
            raise ScriptRuntimeError("Value is negative and can't be converted to bool")
        return value != 0.0
    if value is None:
        raise ScriptRuntimeError("the value is not initialized")
    raise ScriptRuntimeError(f"no known safe conversion between [{type(value).__name__}] and [bool]")


def to_int64(value: Any) -> int:
    """``Any::cast<int64_t>``: a double converts only when it is integral and in range."""
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float) and value.is_integer() and INT64_MIN <= value <= INT64_MAX:
        return int(value)
    raise ScriptRuntimeError("Invalid floating point to integer conversion")


def convert_into(value: Any, current: Any) -> Any:
    """The value an entry holding ``current`` stores when assigned ``value`` (it keeps its type)."""
    if isinstance(current, bool):
        if isinstance(value, bool):
            return value
        if isinstance(value, int) and value in (0, 1):
            return bool(value)
        if isinstance(value, float):
            return value != 0.0
    elif isinstance(current, int):
        if is_number(value):
            return to_int64(value)
    elif isinstance(current, float):
        if is_number(value):
            return float(value)
    elif isinstance(current, str):
        if isinstance(value, str):
            return value
    elif type(value) is type(current):
        return value
    raise ScriptRuntimeError(
        f"a {type(value).__name__} value cannot be stored in an entry of type {type(current).__name__}"
    )


def divide(left: float, right: float) -> float:
    """IEEE division (C++ semantics): dividing by zero gives an infinity or NaN, not an exception."""
    if right == 0.0:
        if math.isnan(left):
            return left
        if left == 0.0:
            return math.copysign(math.nan, -1.0)  # x86's default NaN has the sign bit set: BT.CPP prints "-nan"
        return math.copysign(math.inf, left) * math.copysign(1.0, right)
    return left / right


def compare(op: str, left: Any, right: Any) -> bool:
    """One comparison, written as BT.CPP's ``SwitchImpl`` (so NaN behaves the same)."""
    numbers = isinstance(left, float)
    if op == "==":
        return abs(left - right) <= FLOAT_EPSILON if numbers else left == right
    if op == "!=":
        return not (abs(left - right) <= FLOAT_EPSILON if numbers else left == right)
    if op == "<":
        return not left >= right
    if op == ">":
        return not left <= right
    if op == "<=":
        return not left > right
    return not left < right  # ">="
