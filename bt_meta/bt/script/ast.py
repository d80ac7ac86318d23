"""The syntax tree of a parsed script (what :mod:`~bt_meta.bt.script.parser` builds and
:mod:`~bt_meta.bt.script.evaluator` runs).

Offers: :class:`Literal`, :class:`Name`, :class:`Unary`, :class:`Binary`, :class:`Comparison`, :class:`Conditional`,
:class:`Assignment`, and :data:`Expr`, their union.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union


@dataclass(frozen=True)
class Literal:
    value: int | float | str


@dataclass(frozen=True)
class Name:
    name: str


@dataclass(frozen=True)
class Unary:
    op: str  # "-", "~", "!"
    operand: Expr


@dataclass(frozen=True)
class Binary:
    op: str  # "+", "-", "*", "/", "..", "&", "|", "^", "&&", "||"
    left: Expr
    right: Expr


@dataclass(frozen=True)
class Comparison:
    """A chain ``a < b <= c``: true when every adjacent pair compares true (evaluated left to right, lazily)."""

    ops: tuple[str, ...]
    operands: tuple[Expr, ...]


@dataclass(frozen=True)
class Conditional:
    condition: Expr
    then: Expr
    otherwise: Expr


@dataclass(frozen=True)
class Assignment:
    op: str  # ":=", "=", "+=", "-=", "*=", "/="
    target: Expr
    value: Expr


Expr = Union[Literal, Name, Unary, Binary, Comparison, Conditional, Assignment]  # noqa: UP007
