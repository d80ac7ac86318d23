"""A recursive-descent parser for BehaviorTree.CPP 4's script language, with BT.CPP's precedence rules.

Offers:

* :func:`parse` -- script text -> list of expressions (statements separated by ``;``)
* :func:`walk`, :func:`tree_depth` -- every node / the depth of an expression tree

Precedence, lowest first (as BT.CPP's grammar): assignment (``:= = += -= *= /=``, not chainable), the ternary
``c ? a : b`` (not chainable), ``&& ||`` (one level, left to right), comparisons (a chain ``a < b == c``), then one
of three operator groups that cannot be mixed without parentheses: arithmetic (``+ -`` then ``* /`` then prefix
``-``; BT.CPP 4.8 groups these to the right), bitwise/logical (``| ^`` then ``&`` then prefix ``~ !``) and string
concatenation (``..``). One expression commits to one group, across its comparisons and ``&&``/``||`` too
(``1 + 1 == 2 && 1 & 1`` is refused, as in BT.CPP); parentheses and the ternary's middle part start afresh.
"""

from __future__ import annotations

from bt_meta.bt.script.ast import Assignment, Binary, Comparison, Conditional, Expr, Literal, Name, Unary
from bt_meta.bt.script.errors import ScriptSyntaxError
from bt_meta.bt.script.lexer import Token, tokenize

ASSIGNMENTS = (":=", "=", "+=", "-=", "*=", "/=")
COMPARISONS = ("==", "!=", "<", ">", "<=", ">=")
MATH = ("+", "-", "*", "/")
BITS = ("|", "^", "&")
GROUP_OPS = (*MATH, "..", *BITS, "~", "!")
# Deep nesting is refused before Python's own recursion limit is near.
MAX_DEPTH = 64
# The evaluator recurses over the tree: a longer chain (``1+1+...``) than this is refused at parse time.
MAX_TREE_DEPTH = 128


class _Parser:
    def __init__(self, text: str) -> None:
        self.tokens = tokenize(text)
        self.index = 0
        self.depth = 0
        # The operator group ("math", "bit" or "concat") the current expression committed to: BT.CPP refuses a
        # second group anywhere in the same expression (across comparisons and &&/||), until parentheses.
        self.group_kind: str | None = None

    def peek(self) -> Token:
        return self.tokens[self.index]

    def at(self, *ops: str) -> bool:
        token = self.tokens[self.index]
        return token.kind == "op" and token.text in ops

    def advance(self) -> Token:
        token = self.tokens[self.index]
        self.index += 1
        return token

    def fail(self, message: str, token: Token | None = None) -> ScriptSyntaxError:
        return ScriptSyntaxError(message, (token or self.peek()).start)

    def statements(self) -> list[Expr]:
        if self.peek().kind == "end":
            raise self.fail("empty script")
        exprs = [self.expression()]
        while self.at(";"):
            self.advance()
            if self.peek().kind == "end":
                raise self.fail("unexpected trailing ';'")
            exprs.append(self.expression())
        if self.peek().kind != "end":
            raise self.fail(f"expected ';' before {self.peek().text!r}")
        return exprs

    def expression(self) -> Expr:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.fail(f"expression nested deeper than {MAX_DEPTH} levels")
        outer_group, self.group_kind = self.group_kind, None
        try:
            left = self.conditional()
            if self.at(*ASSIGNMENTS):
                op = self.advance().text
                right = self.conditional()
                if self.at(*ASSIGNMENTS):
                    raise self.fail("assignment cannot be chained")
                return Assignment(op, left, right)
            return left
        finally:
            self.depth -= 1
            self.group_kind = outer_group

    def conditional(self) -> Expr:
        condition = self.logical()
        if not self.at("?"):
            return condition
        self.advance()
        then = self.expression()
        if not self.at(":"):
            raise self.fail("expected ':' in the conditional operator")
        self.advance()
        otherwise = self.logical()
        if self.at("?"):
            raise self.fail("the conditional operator cannot be chained; use parentheses")
        return Conditional(condition, then, otherwise)

    def logical(self) -> Expr:
        left = self.comparison()
        while self.at("&&", "||"):
            op = self.advance().text
            left = Binary(op, left, self.comparison())
        return left

    def comparison(self) -> Expr:
        operands = [self.group()]
        ops: list[str] = []
        while self.at(*COMPARISONS):
            ops.append(self.advance().text)
            operands.append(self.group())
        if not ops:
            return operands[0]
        return Comparison(tuple(ops), tuple(operands))

    def commit(self, kind: str) -> None:
        if self.group_kind is not None and self.group_kind != kind:
            raise self.fail("operator cannot be mixed with previous operators (add parentheses)")
        self.group_kind = kind

    def group(self) -> Expr:
        if self.at("-"):
            self.commit("math")
            result = self.sum()
        elif self.at("~", "!"):
            self.commit("bit")
            result = self.bit_or()
        else:
            first = self.atom()
            if self.at(*MATH):
                self.commit("math")
                result = self.sum(first)
            elif self.at(".."):
                self.commit("concat")
                result = self.concat(first)
            elif self.at(*BITS):
                self.commit("bit")
                result = self.bit_or(first)
            else:
                return first
        if self.at(*GROUP_OPS):
            raise self.fail("operator cannot be mixed with previous operators (add parentheses)")
        return result

    # BT.CPP 4.8 groups + - and * / to the RIGHT: 2 - 1 - 3 is 2 - (1 - 3) = 4 there, and so it is here (the
    # differential tests check it). &&, ||, the bitwise operators and .. group to the left.
    def sum(self, first: Expr | None = None) -> Expr:
        left = self.product(first)
        if self.at("+", "-"):
            op = self.advance().text
            return self.nested(lambda: Binary(op, left, self.sum()))
        return left

    def product(self, first: Expr | None = None) -> Expr:
        left = first if first is not None else self.negation()
        if self.at("*", "/"):
            op = self.advance().text
            return self.nested(lambda: Binary(op, left, self.product()))
        return left

    def negation(self) -> Expr:
        if self.at("-"):
            self.advance()
            if self.at("~", "!"):
                raise self.fail("operator cannot be mixed with previous operators (add parentheses)")
            return self.nested(lambda: Unary("-", self.negation()))
        return self.atom()

    def concat(self, first: Expr) -> Expr:
        left = first
        while self.at(".."):
            self.advance()
            left = Binary("..", left, self.atom())
        return left

    def bit_or(self, first: Expr | None = None) -> Expr:
        left = self.bit_and(first)
        while self.at("|", "^"):
            op = self.advance().text
            left = Binary(op, left, self.bit_and())
        return left

    def bit_and(self, first: Expr | None = None) -> Expr:
        left = first if first is not None else self.bit_prefix()
        while self.at("&"):
            self.advance()
            left = Binary("&", left, self.bit_prefix())
        return left

    def bit_prefix(self) -> Expr:
        if self.at("~", "!"):
            op = self.advance().text
            return self.nested(lambda: Unary(op, self.bit_prefix()))
        return self.atom()

    def nested(self, build):  # type: ignore[no-untyped-def]
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.fail(f"expression nested deeper than {MAX_DEPTH} levels")
        try:
            return build()
        finally:
            self.depth -= 1

    def atom(self) -> Expr:
        token = self.peek()
        if token.kind == "op" and token.text == "(":
            self.advance()
            inner = self.expression()
            if not self.at(")"):
                raise self.fail("expected ')'")
            self.advance()
            return inner
        if token.kind in ("int", "real", "string", "bool"):
            self.advance()
            return Literal(token.value)  # type: ignore[arg-type]
        if token.kind == "name":
            self.advance()
            return Name(token.text)
        if token.kind == "op" and token.text == "+":
            number = self.tokens[self.index + 1]
            if number.kind in ("int", "real") and not number.spaced:
                self.index += 2
                return Literal(number.value)  # type: ignore[arg-type]
        if token.kind == "op" and token.text in GROUP_OPS:
            raise self.fail("operator cannot be mixed with previous operators (add parentheses)")
        raise self.fail("expected operand" + (f", got {token.text!r}" if token.text else " at the end of the script"))


def _children(expr: Expr) -> tuple[Expr, ...]:
    if isinstance(expr, Unary):
        return (expr.operand,)
    if isinstance(expr, Binary):
        return (expr.left, expr.right)
    if isinstance(expr, Comparison):
        return expr.operands
    if isinstance(expr, Conditional):
        return (expr.condition, expr.then, expr.otherwise)
    if isinstance(expr, Assignment):
        return (expr.target, expr.value)
    return ()


def walk(expr: Expr) -> list[Expr]:
    """Every node of an expression tree (iteratively)."""
    found: list[Expr] = []
    stack = [expr]
    while stack:
        node = stack.pop()
        found.append(node)
        stack.extend(_children(node))
    return found


def tree_depth(expr: Expr) -> int:
    """Depth of an expression tree, computed without recursion."""
    deepest = 0
    stack = [(expr, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in _children(node))
    return deepest


def parse(text: str) -> list[Expr]:
    """Parse a script; raises :class:`ScriptSyntaxError` with the offending character offset."""
    exprs = _Parser(text).statements()
    for expr in exprs:
        if tree_depth(expr) > MAX_TREE_DEPTH:
            raise ScriptSyntaxError(f"expression more than {MAX_TREE_DEPTH} operators deep", 0)
    return exprs
