"""Running a parsed script against a blackboard, with BehaviorTree.CPP's evaluation rules.

Offers:

* :class:`Environment` -- what a script reads and writes: blackboard entries by name, enums by name
* :class:`DictEnvironment` -- an environment over a plain dict (tests, tools)
* :func:`evaluate` -- one expression -> its value
* :func:`run` -- every statement in order -> the last one's value

Rules kept from BT.CPP (``operators.hpp``): both operands of a binary operator are evaluated (``&&``/``||`` do not
short-circuit); comparison chains stop at the first false pair; arithmetic results are doubles; an enum name wins
over a blackboard entry of the same name; ``=`` refuses an entry that does not exist, ``:=`` creates it; an entry
keeps the type of its first value (a string assigned to a numeric entry is parsed as a number).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from bt_meta.bt.script import values
from bt_meta.bt.script.ast import Assignment, Binary, Comparison, Conditional, Expr, Literal, Name, Unary
from bt_meta.bt.script.errors import ScriptRuntimeError


class Environment(Protocol):
    enums: Mapping[str, int]

    def exists(self, name: str) -> bool: ...

    def get(self, name: str) -> Any: ...

    def set(self, name: str, value: Any) -> None: ...


class DictEnvironment:
    """Entries in a dict; ``@name`` is the same entry as ``name`` (there is only one blackboard)."""

    def __init__(self, entries: dict[str, Any] | None = None, enums: Mapping[str, int] | None = None) -> None:
        self.entries = entries if entries is not None else {}
        self.enums = dict(enums or {})

    def exists(self, name: str) -> bool:
        return name.lstrip("@") in self.entries

    def get(self, name: str) -> Any:
        try:
            return self.entries[name.lstrip("@")]
        except KeyError:
            raise ScriptRuntimeError(f"Variable not found: {name}") from None

    def set(self, name: str, value: Any) -> None:
        self.entries[name.lstrip("@")] = value


def _not_initialised(side: str, op: str) -> ScriptRuntimeError:
    return ScriptRuntimeError(f"The {side} operand of the operator [{op}] is not initialized")


def _unary(op: str, value: Any) -> Any:
    if values.is_number(value):
        number = float(value)
        if op == "-":
            return -number
        if op == "~":
            if not values.INT64_MIN <= number <= values.INT64_MAX or number != number:
                raise ScriptRuntimeError("Number out of range for bitwise operation")
            return float(~int(number))
        return float(not number)
    if isinstance(value, str):
        raise ScriptRuntimeError("Invalid operator for std::string")
    raise ScriptRuntimeError("ExprUnaryArithmetic: undefined")


def _binary(op: str, left: Any, right: Any) -> Any:
    if left is None:
        raise _not_initialised("left", op)
    if right is None:
        raise _not_initialised("right", op)
    if values.is_number(left) and values.is_number(right):
        lv, rv = float(left), float(right)
        if op == "+":
            return lv + rv
        if op == "-":
            return lv - rv
        if op == "*":
            return lv * rv
        if op == "/":
            return values.divide(lv, rv)
        if op in ("&", "|", "^"):
            try:
                li, ri = values.to_int64(left), values.to_int64(right)
            except ScriptRuntimeError:
                raise ScriptRuntimeError(
                    "Binary operators are not allowed if one of the operands is not an integer"
                ) from None
            return float(li & ri if op == "&" else li | ri if op == "|" else li ^ ri)
        if op in ("&&", "||"):
            try:
                lb, rb = values.to_bool(left), values.to_bool(right)
            except ScriptRuntimeError:
                raise ScriptRuntimeError(
                    "Logic operators are not allowed if one of the operands is not castable to bool"
                ) from None
            return float(lb and rb if op == "&&" else lb or rb)
        return None  # ".." of two numbers: BT.CPP yields an empty value
    if isinstance(left, str) and isinstance(right, str) and op == "+":
        return left + right
    if op == ".." and (isinstance(left, str) or isinstance(right, str)) and (
        (isinstance(left, str) or values.is_number(left)) and (isinstance(right, str) or values.is_number(right))
    ):
        return values.to_string(left) + values.to_string(right)
    raise ScriptRuntimeError("Operation not permitted")


def _comparison(expr: Comparison, env: Environment) -> float:
    left = evaluate(expr.operands[0], env)
    for op, operand in zip(expr.ops, expr.operands[1:], strict=True):
        right = evaluate(operand, env)
        if left is None:
            raise _not_initialised("left", op)
        if right is None:
            raise _not_initialised("right", op)
        if values.is_number(left) and values.is_number(right):
            lv, rv = float(left), float(right)
        elif isinstance(left, str) and isinstance(right, str):
            lv, rv = left, right  # type: ignore[assignment]
        elif isinstance(left, str) and values.is_number(right):
            lv, rv = values.string_to_double(left, env.enums), float(right)
        elif values.is_number(left) and isinstance(right, str):
            lv, rv = float(left), values.string_to_double(right, env.enums)
        else:
            raise ScriptRuntimeError(
                f"Can't mix different types in Comparison. Left operand [{type(left).__name__}] right operand "
                f"[{type(right).__name__}]"
            )
        if not values.compare(op, lv, rv):
            return 0.0
        left = right
    return 1.0


def _truthy(value: Any) -> bool:
    """The ternary's test: a number is true when non-zero; a string must hold a number."""
    if isinstance(value, str):
        return values.parse_double(value) != 0.0
    if values.is_number(value):
        return float(value) != 0.0
    raise ScriptRuntimeError("the condition of the ternary operator is not a number")


def _assign(expr: Assignment, env: Environment) -> Any:
    if not isinstance(expr.target, Name):
        raise ScriptRuntimeError("Assignment left operand not a blackboard entry")
    key = expr.target.name
    existed = env.exists(key)
    if not existed and expr.op != ":=":
        raise ScriptRuntimeError(
            f"The blackboard entry [{key}] doesn't exist, yet. If you want to create a new one, use the operator "
            "[:=] instead of [=]"
        )
    value = evaluate(expr.value, env)
    if value is None:
        raise _not_initialised("right", expr.op)
    current = env.get(key) if existed else None
    if expr.op in (":=", "="):
        if current is None:
            stored = value
        elif isinstance(value, str) and not isinstance(current, str):
            if not values.is_number(current):
                raise ScriptRuntimeError(f"Error assigning a value to entry [{key}]: the right operand is a string")
            stored = values.string_to_double(value, env.enums)
        else:
            try:
                stored = values.convert_into(value, current)
            except ScriptRuntimeError as error:
                raise ScriptRuntimeError(f"Error assigning a value to entry [{key}]. {error}") from None
        env.set(key, stored)
        return stored
    if current is None:
        raise _not_initialised("left", expr.op)
    if values.is_number(value):
        if not values.is_number(current):
            raise ScriptRuntimeError("This Assignment operator can't be used with a non-numeric type")
        lv, rv = float(current), float(value)
        temp: Any = lv + rv if expr.op == "+=" else lv - rv if expr.op == "-=" else lv * rv
        if expr.op == "/=":
            temp = values.divide(lv, rv)
    elif isinstance(value, str):
        if expr.op != "+=":
            raise ScriptRuntimeError("Operator not supported for strings")
        temp = values.to_string(current) + value
    else:
        raise ScriptRuntimeError("Operation not permitted")
    stored = values.convert_into(temp, current)
    env.set(key, stored)
    return stored


def evaluate(expr: Expr, env: Environment) -> Any:
    if isinstance(expr, Literal):
        return expr.value
    if isinstance(expr, Name):
        if expr.name in env.enums:
            return float(env.enums[expr.name])
        if not env.exists(expr.name):
            raise ScriptRuntimeError(f"Variable not found: {expr.name}")
        return env.get(expr.name)
    if isinstance(expr, Unary):
        return _unary(expr.op, evaluate(expr.operand, env))
    if isinstance(expr, Binary):
        left = evaluate(expr.left, env)
        right = evaluate(expr.right, env)
        return _binary(expr.op, left, right)
    if isinstance(expr, Comparison):
        return _comparison(expr, env)
    if isinstance(expr, Conditional):
        branch = expr.then if _truthy(evaluate(expr.condition, env)) else expr.otherwise
        return evaluate(branch, env)
    return _assign(expr, env)


def run(exprs: list[Expr], env: Environment) -> Any:
    result: Any = None
    for expr in exprs:
        result = evaluate(expr, env)
    return result
