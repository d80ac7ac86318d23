"""The safe condition language of task files: tokenizer, parser, compiler and matcher (never ``eval``).

Offers:

* :class:`Var` -- a variable term (``?x`` in the text; ``Var("x")`` here); constants are plain ``str``
* :func:`parse_condition`, :func:`parse_atom`, :func:`parse_parameter` -- text to syntax tree, raising
  :class:`ConditionSyntaxError` with the offset (0-based) of the offending character
* :func:`dnf_size`, :func:`check_dnf_size` -- the size of a condition's distributed form, computed not built
* :func:`compile_condition` -- syntax tree to a :class:`Condition`: checks predicates, arities and that every
  variable of ``not`` / ``==`` / ``!=`` / external atoms is bound first, and turns the condition into a
  disjunction of clauses (DNF) whose literals are matched left to right (SHOP2 style)
* :class:`Condition` -- ``holds`` and ``satisfiers`` over a :class:`~bt_meta.htn.state.State`
* :func:`match_clause` -- the iterative matcher, also used by the axiom evaluator
* :class:`ExternalPredicateError` -- a condition needs an external predicate but no callable was given
* :func:`free_variables` -- the variables of a syntax tree that no quantifier inside it binds
* :func:`uses_external` -- whether compiled clauses ask an external predicate, inside quantifiers too

Grammar (lowest precedence first)::

    cond    := expr ['implies' cond]                          (A implies B: not A or B)
    expr    := and ('or' and)*
    and     := unary ('and' unary)*
    unary   := 'not' unary | primary
    primary := '(' cond ')' | 'true' | 'false' | term ('==' | '!=') term | NAME '(' [term (',' term)*] ')'
             | ('forall' | 'exists') typed (',' typed)* ':' cond   (the body reaches as far right as it can)
    typed   := ?variable '-' TYPE                             (TYPE: a type or any unary predicate)
    term    := ?variable | NAME | NUMBER | 'quoted' | "quoted"

``forall``, ``exists`` and ``implies`` are recognised only where nothing else can stand (``forall`` before a
variable, ``implies`` after a complete condition), so predicates and constants with those names keep working.
A quantifier is a test: its free variables must be bound where it is reached (like ``not``), and it binds
nothing outside itself.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from bt_meta.errors import PlanningError
from bt_meta.htn.fastpath import Unsupported
from bt_meta.htn.state import Atom, State

# From this many facts on, generated preconditions prove ground derived atoms with AxiomSet.holds, whose memo a
# successor state inherits, rather than with generated provers, whose memo starts empty in every state (cheaper per
# proof, but re-proves everything a state asks). Measured on the generated blocks problems: 330 facts, generated
# provers 1.35x faster; 664 facts, inherited memo 1.1x faster.
REFERENCE_PROOFS_MIN = 500

KEYWORDS = frozenset({"and", "or", "not", "true", "false"})

# Bounds checked before the work they protect: parentheses and 'not's nested deeper than this are refused by the
# parser (which recurses once per level); a condition whose disjunctive normal form would have more alternatives
# or literals than these is refused from sizes computed on the syntax tree, before any clause is built.
MAX_CONDITION_NESTING = 100
MAX_ALTERNATIVES = 4096
MAX_DNF_LITERALS = 100_000

ExternalFn = Callable[[str, tuple, State], bool]


class Var:
    """A variable term. Equality and hash follow the name so templates can be compared."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Var) and other.name == self.name

    def __hash__(self) -> int:
        return hash(("?", self.name))

    def __repr__(self) -> str:
        return f"?{self.name}"


Term = Var | str


def term_text(term: Term) -> str:
    return f"?{term.name}" if isinstance(term, Var) else term


def template_text(pred: str, args: Sequence[Term]) -> str:
    return f"{pred}({', '.join(term_text(a) for a in args)})"


class ConditionSyntaxError(Exception):
    """A mistake inside one condition or atom string; ``offset`` is 0-based within that string."""

    def __init__(self, message: str, offset: int) -> None:
        super().__init__(message)
        self.message = message
        self.offset = offset


class ExternalPredicateError(PlanningError):
    """A condition asked an external predicate but the planner was given no ``external`` callable."""


# -- syntax tree ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AtomExpr:
    pred: str
    args: tuple[Term, ...]
    offset: int
    arg_offsets: tuple[int, ...] = ()


@dataclass(frozen=True)
class CompareExpr:
    op: str  # "==" or "!="
    left: Term
    right: Term
    offset: int


@dataclass(frozen=True)
class NotExpr:
    child: Expr
    offset: int


@dataclass(frozen=True)
class AndExpr:
    children: tuple[Expr, ...]


@dataclass(frozen=True)
class OrExpr:
    children: tuple[Expr, ...]


@dataclass(frozen=True)
class BoolExpr:
    value: bool


@dataclass(frozen=True)
class QuantExpr:
    """``forall`` / ``exists`` over ``variables`` (name, type predicate, offset of the variable)."""

    op: str  # "forall" or "exists"
    variables: tuple[tuple[str, str, int], ...]
    body: Expr
    offset: int


Expr = AtomExpr | CompareExpr | NotExpr | AndExpr | OrExpr | BoolExpr | QuantExpr
QUANTIFIERS = ("forall", "exists")


# -- tokenizer --------------------------------------------------------------------------------------------------
_TOKEN_RE = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<var>\?[A-Za-z_][A-Za-z0-9_\-]*)
  | (?P<str>"[^"\\\n]*(?:\\.[^"\\\n]*)*"|'[^'\n]*')
  | (?P<op>==|!=|\(|\)|,|:)
  | (?P<name>[A-Za-z0-9_.+\-](?:[A-Za-z0-9_.+\-/:]*[A-Za-z0-9_.+\-/])?)
    """,
    re.VERBOSE,
)


@dataclass(frozen=True)
class Token:
    kind: str  # var, str, op, name, kw, eof
    text: str
    offset: int

    def describe(self) -> str:
        return "end of text" if self.kind == "eof" else repr(self.text)


def tokenize(text: str) -> list[Token]:
    tokens: list[Token] = []
    pos = 0
    while pos < len(text):
        match = _TOKEN_RE.match(text, pos)
        if match is None:
            char = text[pos]
            if char == "?":
                raise ConditionSyntaxError("a variable is '?' followed by a letter or '_'", pos)
            if char in "\"'":
                raise ConditionSyntaxError("unterminated quoted string", pos)
            raise ConditionSyntaxError(f"unexpected character {char!r}", pos)
        kind = match.lastgroup or ""
        if kind != "ws":
            value = match.group()
            if kind == "name" and value in KEYWORDS:
                kind = "kw"
            tokens.append(Token(kind, value, pos))
        pos = match.end()
    tokens.append(Token("eof", "", len(text)))
    return tokens


# -- parser -----------------------------------------------------------------------------------------------------
class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = tokenize(text)
        self.pos = 0
        self.depth = 0

    def nest(self, offset: int) -> None:
        self.depth += 1
        if self.depth > MAX_CONDITION_NESTING:
            raise ConditionSyntaxError(f"condition nested deeper than {MAX_CONDITION_NESTING} levels of '(' and "
                                       "'not'", offset)

    @property
    def tok(self) -> Token:
        return self.tokens[self.pos]

    def peek(self, ahead: int = 1) -> Token:
        return self.tokens[min(self.pos + ahead, len(self.tokens) - 1)]

    def take(self) -> Token:
        token = self.tokens[self.pos]
        self.pos += 1
        return token

    def expect_op(self, op: str, what: str) -> Token:
        if self.tok.kind == "op" and self.tok.text == op:
            return self.take()
        raise ConditionSyntaxError(f"expected {what}, found {self.tok.describe()}", self.tok.offset)

    def expect_end(self, what: str) -> None:
        if self.tok.kind != "eof":
            raise ConditionSyntaxError(f"expected end of {what}, found {self.tok.describe()}", self.tok.offset)

    def cond(self) -> Expr:
        left = self.expr()
        if self.tok.kind == "name" and self.tok.text == "implies":
            offset = self.take().offset
            self.nest(offset)
            right = self.cond()
            self.depth -= 1
            return OrExpr((NotExpr(left, offset), right))
        return left

    def expr(self) -> Expr:
        children = [self.conj()]
        while self.tok.kind == "kw" and self.tok.text == "or":
            self.take()
            children.append(self.conj())
        return children[0] if len(children) == 1 else OrExpr(tuple(children))

    def conj(self) -> Expr:
        children = [self.unary()]
        while self.tok.kind == "kw" and self.tok.text == "and":
            self.take()
            children.append(self.unary())
        return children[0] if len(children) == 1 else AndExpr(tuple(children))

    def unary(self) -> Expr:
        if self.tok.kind == "kw" and self.tok.text == "not":
            offset = self.take().offset
            self.nest(offset)
            child = self.unary()
            self.depth -= 1
            return NotExpr(child, offset)
        return self.primary()

    def primary(self) -> Expr:
        tok = self.tok
        if tok.kind == "op" and tok.text == "(":
            self.take()
            self.nest(tok.offset)
            inner = self.cond()
            self.expect_op(")", "')' to close the '(' opened before")
            self.depth -= 1
            return inner
        if tok.kind == "kw" and tok.text in ("true", "false"):
            self.take()
            return BoolExpr(tok.text == "true")
        if tok.kind == "name" and self.peek().kind == "op" and self.peek().text == "(":
            return self.atom()
        if tok.kind == "name" and tok.text in QUANTIFIERS and self.peek().kind == "var":
            return self.quantifier()
        if tok.kind in ("var", "name", "str"):
            nxt = self.peek()
            if nxt.kind == "op" and nxt.text in ("==", "!="):
                left = self.term()
                op = self.take().text
                right = self.term()
                return CompareExpr(op, left, right, tok.offset)
            if tok.kind == "name":
                raise ConditionSyntaxError(
                    f"expected '(' after predicate name {tok.text!r} (write {tok.text}() for a 0-ary atom)",
                    nxt.offset,
                )
            raise ConditionSyntaxError(f"expected '==' or '!=' after {tok.text}, found {nxt.describe()}", nxt.offset)
        raise ConditionSyntaxError(
            f"expected an atom like pred(?x), 'not', '(', 'true' or a comparison, found {tok.describe()}", tok.offset
        )

    def quantifier(self) -> QuantExpr:
        op_tok = self.take()
        variables: list[tuple[str, str, int]] = []
        while True:
            var = self.tok
            if var.kind != "var":
                raise ConditionSyntaxError(f"expected a variable after {op_tok.text!r} or ',', found "
                                           f"{var.describe()}", var.offset)
            self.take()
            type_tok = self.tok
            if type_tok.kind == "name" and type_tok.text == "-":
                self.take()
                type_tok = self.tok
                type_name = type_tok.text if type_tok.kind == "name" else ""
            elif type_tok.kind == "name" and type_tok.text.startswith("-") and len(type_tok.text) > 1:
                type_name = type_tok.text[1:]  # '?x -block'
            else:
                raise ConditionSyntaxError(f"expected '- type' after {var.text} (write {op_tok.text} {var.text} - "
                                           "type: ...)", type_tok.offset)
            if not type_name or not (type_name[0].isalpha() or type_name[0] == "_"):
                raise ConditionSyntaxError(f"expected a type name after '-', found {type_tok.describe()}",
                                           type_tok.offset)
            self.take()
            if ":" in type_name and not (self.tok.kind == "op" and self.tok.text in (",", ":")):
                raise ConditionSyntaxError(f"put a space after the ':' that ends the variables of {op_tok.text!r} "
                                           f"({type_name!r} reads as one name)", type_tok.offset)
            if any(name == var.text[1:] for name, _, _ in variables):
                raise ConditionSyntaxError(f"variable {var.text} is quantified twice", var.offset)
            variables.append((var.text[1:], type_name, var.offset))
            if self.tok.kind == "op" and self.tok.text == ",":
                self.take()
                continue
            break
        self.expect_op(":", f"',' or ':' after the variables of {op_tok.text!r}")
        self.nest(op_tok.offset)
        if self.tok.kind == "eof" or (self.tok.kind == "op" and self.tok.text == ")"):
            raise ConditionSyntaxError(f"expected the condition of {op_tok.text!r} after ':', found "
                                       f"{self.tok.describe()}", self.tok.offset)
        body = self.cond()
        self.depth -= 1
        return QuantExpr(op_tok.text, tuple(variables), body, op_tok.offset)

    def term(self) -> Term:
        tok = self.tok
        if tok.kind == "var":
            self.take()
            return Var(tok.text[1:])
        if tok.kind == "name":
            self.take()
            return tok.text
        if tok.kind == "str":
            self.take()
            body = tok.text[1:-1]
            if tok.text[0] == '"':
                body = re.sub(r"\\(.)", r"\1", body)
            return body
        raise ConditionSyntaxError(f"expected a variable or a constant, found {tok.describe()}", tok.offset)

    def atom(self) -> AtomExpr:
        name_tok = self.take()
        self.expect_op("(", "'('")
        args: list[Term] = []
        offsets: list[int] = []
        if self.tok.kind == "op" and self.tok.text == ")":
            self.take()
            return AtomExpr(name_tok.text, (), name_tok.offset, ())
        while True:
            offsets.append(self.tok.offset)
            args.append(self.term())
            if self.tok.kind == "op" and self.tok.text == ",":
                self.take()
                continue
            if self.tok.kind == "op" and self.tok.text == ")":
                self.take()
                return AtomExpr(name_tok.text, tuple(args), name_tok.offset, tuple(offsets))
            raise ConditionSyntaxError(f"expected ',' or ')' in the arguments of {name_tok.text}, found "
                                       f"{self.tok.describe()}", self.tok.offset)


def parse_condition(text: str) -> Expr:
    parser = _Parser(text)
    if parser.tok.kind == "eof":
        raise ConditionSyntaxError("empty condition (write 'true' for no condition)", 0)
    expr = parser.cond()
    parser.expect_end("condition")
    return expr


def parse_atom(text: str) -> AtomExpr:
    """One atom ``name(arg, ...)``: an effect, a subtask, a task head, an initial fact or a goal fact."""
    parser = _Parser(text)
    tok = parser.tok
    if tok.kind != "name":
        raise ConditionSyntaxError(f"expected an atom like name(arg, ...), found {tok.describe()}", tok.offset)
    if not (parser.peek().kind == "op" and parser.peek().text == "("):
        raise ConditionSyntaxError(
            f"expected '(' after {tok.text!r} (write {tok.text}() when there are no arguments)", parser.peek().offset
        )
    atom = parser.atom()
    parser.expect_end("atom")
    return atom


_PARAM_RE = re.compile(r"^\s*\?([A-Za-z_][A-Za-z0-9_\-]*)\s*(?:-\s*([A-Za-z_][A-Za-z0-9_\-]*))?\s*$")


def parse_parameter(text: str) -> tuple[str, str | None]:
    """``?b - block`` (typed) or ``?b`` (untyped) to ``("b", "block")`` / ``("b", None)``."""
    match = _PARAM_RE.match(text)
    if match is None:
        stripped = text.lstrip()
        offset = len(text) - len(stripped)
        if not stripped.startswith("?"):
            raise ConditionSyntaxError("expected a parameter like '?b' or '?b - block'", offset)
        raise ConditionSyntaxError("expected a parameter like '?b' or '?b - block'", offset)
    return match.group(1), match.group(2)


# -- compiled form ----------------------------------------------------------------------------------------------
# Literal kinds of a compiled clause.
POS, NEG, DPOS, DNEG, EXT, NEXT, EQ, NEQ = range(8)
# A quantifier: ``(QEX | QNEX, sub-condition, free variables, node)``; QEX holds when the sub-condition has a
# satisfier under the free variables' values, QNEX when it has none (forall F is QNEX of 'types and not F').
QEX, QNEX = 8, 9


@dataclass
class DomainContext:
    """What the compiler and matcher need to know about predicates; ``axioms`` is set once they are built."""

    arities: dict[str, int]
    derived: set[str] = field(default_factory=set)
    external: set[str] = field(default_factory=set)
    axioms: Any = None  # bt_meta.htn.axioms.AxiomSet


Step = tuple  # (kind, pred_or_left, args_or_right, node)


def dnf_size(expr: Expr, negate: bool = False) -> tuple[int, int]:
    """``(alternatives, literals)`` of the disjunctive normal form of ``expr``, computed without building it.

    Counts are capped just past the bounds (:data:`MAX_ALTERNATIVES`, :data:`MAX_DNF_LITERALS`) so a condition
    that would distribute to astronomically many clauses costs no more than one walk of its syntax tree.
    """
    cap_clauses, cap_literals = MAX_ALTERNATIVES + 1, MAX_DNF_LITERALS + 1
    if isinstance(expr, (AtomExpr, CompareExpr, QuantExpr)):
        return 1, 1
    if isinstance(expr, BoolExpr):
        return (1, 0) if expr.value != negate else (0, 0)
    if isinstance(expr, NotExpr):
        return dnf_size(expr.child, not negate)
    conjunctive = isinstance(expr, AndExpr) != negate
    parts = [dnf_size(child, negate) for child in expr.children]  # type: ignore[union-attr]
    if not conjunctive:
        return min(sum(c for c, _ in parts), cap_clauses), min(sum(n for _, n in parts), cap_literals)
    clauses, literals = 1, 0
    for part_clauses, part_literals in parts:
        # Every clause of the product joins one clause of each side: literals add up across the cross product.
        literals = min(literals * part_clauses + part_literals * clauses, cap_literals)
        clauses = min(clauses * part_clauses, cap_clauses)
    return clauses, (literals if clauses else 0)


def check_dnf_size(expr: Expr) -> None:
    """Refuse a condition whose distributed form would pass the bounds, before it is distributed."""
    clauses, literals = dnf_size(expr)
    if clauses > MAX_ALTERNATIVES:
        raise ConditionSyntaxError(f"condition too large once distributed (more than {MAX_ALTERNATIVES} "
                                   "alternatives)", 0)
    if literals > MAX_DNF_LITERALS:
        raise ConditionSyntaxError(f"condition too large once distributed (more than {MAX_DNF_LITERALS} atoms "
                                   "and comparisons in its alternatives)", 0)


def _to_dnf(expr: Expr, negate: bool) -> list[list[tuple[str, Expr, bool]]]:
    """Clauses of (literal-kind, node, negated) in left-to-right order."""
    if isinstance(expr, AtomExpr):
        return [[("atom", expr, negate)]]
    if isinstance(expr, CompareExpr):
        return [[("cmp", expr, negate)]]
    if isinstance(expr, QuantExpr):
        return [[("quant", expr, negate)]]
    if isinstance(expr, BoolExpr):
        return [[]] if expr.value != negate else []
    if isinstance(expr, NotExpr):
        return _to_dnf(expr.child, not negate)
    conjunctive = isinstance(expr, AndExpr) != negate
    parts = [_to_dnf(child, negate) for child in expr.children]
    if conjunctive:
        clauses: list[list[tuple[str, Expr, bool]]] = [[]]
        for part in parts:
            if len(clauses) * len(part) > MAX_ALTERNATIVES:  # checked before the product is built
                raise ConditionSyntaxError(f"condition too large once distributed (more than {MAX_ALTERNATIVES} "
                                           "alternatives)", 0)
            clauses = [left + right for left in clauses for right in part]
        return clauses
    result: list[list[tuple[str, Expr, bool]]] = []
    for part in parts:
        result.extend(part)
    return result


def _vars_of(terms: Iterable[Term]) -> list[Var]:
    return [t for t in terms if isinstance(t, Var)]


def free_variables(expr: Expr) -> list[Var]:
    """The variables of ``expr`` not quantified inside it, in order of first appearance."""
    found: dict[str, Var] = {}

    def walk(node: Expr, inner: frozenset[str]) -> None:
        if isinstance(node, AtomExpr):
            terms: Iterable[Term] = node.args
        elif isinstance(node, CompareExpr):
            terms = (node.left, node.right)
        elif isinstance(node, NotExpr):
            walk(node.child, inner)
            return
        elif isinstance(node, (AndExpr, OrExpr)):
            for child in node.children:
                walk(child, inner)
            return
        elif isinstance(node, QuantExpr):
            walk(node.body, inner | {name for name, _, _ in node.variables})
            return
        else:
            return
        for var in _vars_of(terms):
            if var.name not in inner:
                found.setdefault(var.name, var)

    walk(expr, frozenset())
    return list(found.values())


def uses_external(clauses: Iterable[Iterable[Step]]) -> bool:
    """Whether a literal of ``clauses``, or of a quantifier inside them, asks an external predicate."""
    for clause in clauses:
        for step in clause:
            if step[0] in (EXT, NEXT) or (step[0] in (QEX, QNEX) and uses_external(step[1].clauses)):
                return True
    return False


class Condition:
    """A compiled condition: a disjunction of clauses, each a list of literals matched left to right.

    ``variables_bound`` is the set of variable names every clause binds (given the initially bound ones):
    effects and subtasks may only use those.
    """

    def __init__(self, source: str, expr: Expr, clauses: list[list[Step]], context: DomainContext,
                 variables_bound: frozenset[str]) -> None:
        self.source = source
        self.expr = expr
        self.clauses = clauses
        self.context = context
        self.variables_bound = variables_bound
        self.trivial = len(clauses) == 1 and not clauses[0]
        self.seeded = _seeded_spec(clauses)
        # generated matchers per tuple of bound variable names; only for conditions that test derived predicates
        self.generatable = any(step[0] in (DPOS, DNEG) for clause in clauses for step in clause) and not \
            uses_external(clauses)
        self._matchers: dict[tuple[Any, ...], Any] = {}

    def __repr__(self) -> str:
        return f"Condition({self.source!r})"

    def satisfiers(self, state: State, bindings: dict[str, str] | None = None,
                   external: ExternalFn | None = None) -> Iterator[dict[str, str]]:
        """Every extension of ``bindings`` that makes the condition true, in SHOP2 order (lazy)."""
        env = dict(bindings) if bindings else {}
        clauses = self.clauses
        if len(clauses) == 1:
            return iter(match_clause(clauses[0], state, env, external, self.context.axioms))
        return self._union(state, env, external)

    def satisfiers_of(self, state: State, env: dict[str, str], external: ExternalFn | None) -> Iterable[dict]:
        """Like :meth:`satisfiers` but ``env`` is the caller's fresh dict, not copied (planner fast path)."""
        clauses = self.clauses
        if self.generatable and state.__class__ is State and self.context.axioms.codegen:
            axioms = self.context.axioms
            reference = axioms.reference_proofs
            if reference is None:
                reference = state._len >= REFERENCE_PROOFS_MIN
            shape = (reference, *env)
            matchers = self._matchers.get(shape)
            if matchers is None:
                matchers = self._matchers[shape] = self._generate(tuple(env), reference)
            if matchers:
                if len(matchers) == 1:
                    return matchers[0](state, env)  # type: ignore[no-any-return]
                return self._union_of(matchers, state, env)
        if len(clauses) == 1:
            seeded = self.seeded
            if seeded is not None and state.__class__ is State:
                axioms = self.context.axioms
                if axioms.incremental:
                    return axioms.seeded(state, seeded, env)  # type: ignore[no-any-return]
            return match_clause(clauses[0], state, env, external, axioms if seeded else self.context.axioms)
        return self._union(state, env, external)

    def _generate(self, bound: tuple[str, ...], reference_proofs: bool) -> list[Any]:
        """The generated matcher of each clause (:mod:`bt_meta.htn.codegen`), or [] to keep the reference one."""
        generated = self.context.axioms.generated(reference_proofs)
        if generated is None:
            return []
        try:
            return [generated.clause_matcher(clause, bound, self.source) for clause in self.clauses]
        except Unsupported:
            return []

    @staticmethod
    def _union_of(matchers: list[Any], state: State, env: dict[str, str]) -> Iterator[dict[str, str]]:
        seen: set[tuple] = set()
        for matcher in matchers:
            for result in matcher(state, env):
                key = tuple(sorted(result.items()))
                if key not in seen:
                    seen.add(key)
                    yield result

    def _union(self, state: State, env: dict[str, str], external: ExternalFn | None) -> Iterator[dict[str, str]]:
        seen: set[tuple] = set()
        for clause in self.clauses:
            for result in match_clause(clause, state, env, external, self.context.axioms):
                key = tuple(sorted(result.items()))
                if key not in seen:
                    seen.add(key)
                    yield result

    def holds(self, state: State, bindings: dict[str, str] | None = None, external: ExternalFn | None = None) -> bool:
        for _ in self.satisfiers(state, bindings, external):
            return True
        return False


def _seeded_spec(clauses: list[list[Step]]) -> tuple | None:
    """``(token, first literal, rest, clause variables)`` when the planner may match the clause per seed.

    That is a single clause that starts with a fact pattern and tests derived predicates after it (so its
    per-seed results are worth keeping in the axiom memo, see :meth:`AxiomSet.seeded`), and calls no external
    predicate (those are asked lazily, at plan time, and never cached).
    """
    if len(clauses) != 1:
        return None
    clause = clauses[0]
    if not clause or clause[0][0] != POS or not any(step[0] in (DPOS, DNEG) for step in clause[1:]):
        return None
    names: set[str] = set()
    for step in clause:
        kind = step[0]
        if kind in (EXT, NEXT, QEX, QNEX):  # a quantifier reads facts the per-seed memo would not watch
            return None
        terms = (step[1], step[2]) if kind in (EQ, NEQ) else step[2]
        names.update(term.name for term in terms if isinstance(term, Var))
    return (object(), clause[0], Clause(clause[1:]), tuple(sorted(names)), clause)


def compile_condition(source: str, expr: Expr, context: DomainContext, bound: Iterable[str],
                      _quantified: dict[tuple[int, bool], Step] | None = None) -> Condition:
    """Check and compile; raises :class:`ConditionSyntaxError` at the offending offset.

    ``_quantified`` (internal): each quantifier's compiled literal by node and polarity, shared with the
    quantifiers inside, so a quantifier that distribution copies into many clauses is compiled once.
    """
    quantified: dict[tuple[int, bool], Step] = {} if _quantified is None else _quantified
    initially = frozenset(bound)
    clauses: list[list[Step]] = []
    bound_everywhere: set[str] | None = None
    check_dnf_size(expr)
    for raw in _to_dnf(expr, False):
        have = set(initially)
        steps: list[Step] = []
        for kind, node, negated in raw:
            if kind == "atom":
                assert isinstance(node, AtomExpr)
                check_atom_predicate(node, context)
                variables = _vars_of(node.args)
                if node.pred in context.external:
                    _require_bound(variables, have, node, "an external atom")
                    steps.append((NEXT if negated else EXT, node.pred, node.args, node))
                    continue
                derived = node.pred in context.derived
                if negated:
                    _require_bound(variables, have, node, "'not'")
                    steps.append((DNEG if derived else NEG, node.pred, node.args, node))
                else:
                    have.update(v.name for v in variables)
                    steps.append((DPOS if derived else POS, node.pred, node.args, node))
            elif kind == "quant":
                assert isinstance(node, QuantExpr)
                _require_bound(free_variables(node), have, node, f"'{node.op}'")
                key = (id(node), negated)
                step = quantified.get(key)
                if step is None:
                    step = quantified[key] = _compile_quantifier(source, node, negated, context, quantified)
                steps.append(step)
            else:
                assert isinstance(node, CompareExpr)
                _require_bound(_vars_of((node.left, node.right)), have, node, f"'{node.op}'")
                is_eq = (node.op == "==") != negated
                steps.append((EQ if is_eq else NEQ, node.left, node.right, node))
        clauses.append(Clause(steps))
        bound_everywhere = have if bound_everywhere is None else bound_everywhere & have
    return Condition(source, expr, clauses, context, frozenset(bound_everywhere or initially))


def _compile_quantifier(source: str, node: QuantExpr, negated: bool, context: DomainContext,
                        quantified: dict[tuple[int, bool], Step]) -> Step:
    """``exists V: F`` -> QEX of ``types(V) and F``; ``forall V: F`` -> QNEX of ``types(V) and not F``."""
    free = free_variables(node)
    type_atoms: list[Expr] = []
    for name, type_name, offset in node.variables:
        if context.arities.get(type_name) != 1 or type_name in context.external:
            unary = sorted(p for p, n in context.arities.items() if n == 1 and p not in context.external)
            raise ConditionSyntaxError(f"the type {type_name!r} of ?{name} is not a type or a unary predicate "
                                       f"(known: {', '.join(unary) or 'none'})", offset)
        type_atoms.append(AtomExpr(type_name, (Var(name),), offset, (offset,)))
    body = node.body if node.op == "exists" else NotExpr(node.body, node.offset)
    sub = compile_condition(source, AndExpr((*type_atoms, body)), context, [v.name for v in free], quantified)
    kind = QEX if (node.op == "exists") != negated else QNEX
    return (kind, sub, tuple(free), node)


def _require_bound(variables: list[Var], have: set[str], node: AtomExpr | CompareExpr | QuantExpr,
                   what: str) -> None:
    for var in variables:
        if var.name not in have:
            offset = node.offset
            if isinstance(node, AtomExpr):
                for arg, arg_offset in zip(node.args, node.arg_offsets, strict=False):
                    if arg == var:
                        offset = arg_offset
                        break
            raise ConditionSyntaxError(
                f"variable ?{var.name} in {what} is not bound: bind it first with a positive atom to its left "
                "or a parameter", offset)


def check_atom_predicate(node: AtomExpr, context: DomainContext) -> None:
    arity = context.arities.get(node.pred)
    if arity is None:
        known = ", ".join(sorted(context.arities)) or "none declared"
        raise ConditionSyntaxError(f"unknown predicate {node.pred!r} (known: {known})", node.offset)
    if arity != len(node.args):
        raise ConditionSyntaxError(
            f"predicate {node.pred} takes {arity} argument{'s' if arity != 1 else ''}, got {len(node.args)}",
            node.offset)


# -- matcher ----------------------------------------------------------------------------------------------------
def ground(pred: str, args: Sequence[Term], env: dict[str, str]) -> Atom:
    """The ground atom of a template under ``env`` (every variable must be bound)."""
    return (pred, *[env[a.name] if a.__class__ is Var else a for a in args])  # type: ignore[union-attr]


def _value(term: Term, env: dict[str, str]) -> str:
    return env[term.name] if term.__class__ is Var else term  # type: ignore[union-attr,return-value]


def candidates(source: Any, pred: str, args: Sequence[Term], env: dict[str, str]) -> Iterable[dict[str, str]]:
    """Extensions of ``env`` matching ``pred(args)`` against ``source`` (a State or a derived index)."""
    vals: list[Any] = [pred]
    free: list[tuple[int, str]] | None = None
    for arg in args:
        if arg.__class__ is Var:
            value = env.get(arg.name)  # type: ignore[union-attr]
            if value is None:
                if free is None:
                    free = []
                free.append((len(vals), arg.name))  # type: ignore[union-attr]
                vals.append(None)
                continue
            vals.append(value)
        else:
            vals.append(arg)
    if free is None:
        return (env,) if tuple(vals) in source else ()
    length = len(vals)
    for position in range(1, length):
        value = vals[position]
        if value is not None:
            pool: Iterable[Atom] = source.with_arg(pred, position, value)
            fixed = [(i, v) for i, v in enumerate(vals) if i > position and v is not None]
            break
    else:
        pool = source.atoms_of(pred)
        fixed = []
    return _extend(pool, len(vals), fixed, free, env)


def _extend(pool: Iterable[Atom], length: int, fixed: list[tuple[int, str]], free: list[tuple[int, str]],
            env: dict[str, str]) -> Iterator[dict[str, str]]:
    single = free[0] if len(free) == 1 else None
    for atom in pool:
        if len(atom) != length:
            continue
        for i, v in fixed:
            if atom[i] != v:
                break
        else:
            new = dict(env)
            if single is not None:
                new[single[1]] = atom[single[0]]
                yield new
                continue
            for i, name in free:
                prior = new.get(name)
                if prior is None:
                    new[name] = atom[i]
                elif prior != atom[i]:
                    break
            else:
                yield new


def _step_results(step: Step, state: State, env: dict[str, str], external: ExternalFn | None,
                  axioms: Any, derived_source: Callable[[str], Any] | None) -> Iterable[dict[str, str]]:
    kind = step[0]
    if kind == POS:
        return candidates(state, step[1], step[2], env)
    if kind == NEG:
        return () if ground(step[1], step[2], env) in state else (env,)
    if kind == EQ:
        return (env,) if _value(step[1], env) == _value(step[2], env) else ()
    if kind == NEQ:
        return (env,) if _value(step[1], env) != _value(step[2], env) else ()
    if kind in (QEX, QNEX):
        inner = {var.name: env[var.name] for var in step[2]}  # the quantifier sees its free variables only
        found = False
        for clause in step[1].clauses:
            if next(iter(match_clause(clause, state, inner, external, axioms, derived_source)), None) is not None:
                found = True
                break
        return (env,) if found == (kind == QEX) else ()
    if kind in (DPOS, DNEG):
        if derived_source is not None:  # inside a bottom-up fixpoint
            source = derived_source(step[1])
            if kind == DPOS:
                return candidates(source, step[1], step[2], env)
            return () if ground(step[1], step[2], env) in source else (env,)
        if kind == DNEG:
            return () if axioms.holds(state, ground(step[1], step[2], env)) else (env,)
        for arg in step[2]:
            if arg.__class__ is Var and arg.name not in env:  # type: ignore[union-attr]
                return axioms.query(state, step[1], step[2], env)
        return (env,) if axioms.holds(state, ground(step[1], step[2], env)) else ()
    # external
    if external is None:
        raise ExternalPredicateError(
            f"condition uses external predicate {step[1]!r} but the planner was given no external callable")
    args = tuple(_value(a, env) for a in step[2])
    truth = bool(external(step[1], args, state))
    if kind == NEXT:
        truth = not truth
    return (env,) if truth else ()


def match_clause(steps: Sequence[Step], state: State, env: dict[str, str], external: ExternalFn | None,
                 axioms: Any, derived_source: Callable[[str], Any] | None = None) -> Iterable[dict[str, str]]:
    """Left-to-right matching of one clause: an iterable of each complete binding (lazy when it matters)."""
    count = len(steps)
    if count == 0:
        return (env,)
    if count == 1:
        return _step_results(steps[0], state, env, external, axioms, derived_source)
    bound = frozenset(env)
    plans = getattr(steps, "plans", None)
    if plans is None:
        ops = _plan(steps, bound)
    else:
        ops = plans.get(bound)
        if ops is None:
            ops = plans[bound] = _plan(steps, bound)
    if ops[0] is _TESTS:  # nothing to bind: a conjunction of tests, decided without a generator
        for op in ops[1]:
            if op[0] == "T":
                atom = op[4](env)
                kind = op[1]
                if kind == POS:
                    ok = atom in state
                elif kind == NEG:
                    ok = atom not in state
                elif derived_source is not None:
                    ok = (atom in derived_source(op[2])) != (kind == DNEG)
                else:
                    ok = axioms.holds(state, atom) != (kind == DNEG)
            else:
                ok = bool(_step_results(op[1], state, env, external, axioms, derived_source))
            if not ok:
                return ()
        return (env,)
    if ops[0] is _SCAN:
        return _scan(ops[1], ops[2], state, env, axioms, derived_source)
    return _match_many(ops, state, env, external, axioms, derived_source)


_DONE: Iterator[Any] = iter(())  # a test literal that passed: nothing more to try at its level


class Clause(list):  # type: ignore[type-arg]
    """The literals of one conjunction, with their match plans cached per set of initially bound variables."""

    __slots__ = ("plans",)

    def __init__(self, steps: Iterable[Step] = ()) -> None:
        super().__init__(steps)
        self.plans: dict[frozenset[str], tuple] = {}


def _plan(steps: Sequence[Step], bound: frozenset[str]) -> tuple:
    """Per literal, what is bound when it is reached (left to right), so matching does no analysis."""
    have = set(bound)
    ops = []
    for step in steps:
        kind = step[0]
        if kind in (NEG, DNEG):  # variables are bound (checked at load time): a ground test
            getters_neg = tuple((True, a.name) if isinstance(a, Var) else (False, a) for a in step[2])
            ops.append(("T", kind, step[1], getters_neg, _atom_builder(step[1], getters_neg)))
            continue
        if kind not in (POS, DPOS):
            ops.append(("X", step))
            continue
        pred = step[1]
        getters: list[tuple[bool, str]] = []
        free: list[tuple[int, str, int]] = []
        first_position: dict[str, int] = {}
        for position, arg in enumerate(step[2], start=1):
            if isinstance(arg, Var):
                if arg.name in have:
                    getters.append((True, arg.name))
                    continue
                getters.append((True, arg.name))
                free.append((position, arg.name, first_position.get(arg.name, 0)))
                first_position.setdefault(arg.name, position)
            else:
                getters.append((False, arg))
        if not free:
            ops.append(("T", kind, pred, tuple(getters), _atom_builder(pred, tuple(getters))))
            continue
        free_positions = {position for position, _, _ in free}
        bound_positions = [p for p in range(1, len(getters) + 1) if p not in free_positions]
        pool = bound_positions[0] if bound_positions else 0
        fixed = tuple((p, *getters[p - 1]) for p in bound_positions[1:])
        pool_getter = getters[pool - 1] if pool else (False, "")
        ops.append(("F", kind, pred, step[2], pool, pool_getter, fixed, tuple(free), len(getters) + 1))
        have.update(name for _, name, _ in free)
    if all(op[0] != "F" for op in ops):
        return (_TESTS, tuple(ops))
    if ops[0][0] == "F" and ops[0][1] == POS and all(op[0] == "T" for op in ops[1:]):
        return (_SCAN, ops[0], tuple(ops[1:]))
    # the tests right after a binding literal run on each of its candidates, without a level of their own
    fused: list[tuple] = []
    for op in ops:
        if op[0] == "T" and fused and fused[-1][0] == "F":
            fused[-1] = (*fused[-1][:9], (*fused[-1][9], op))
        else:
            fused.append((*op, ()) if op[0] == "F" else op)
    return tuple(fused)


def _atom_builder(pred: str, getters: tuple[tuple[bool, str], ...]) -> Callable[[dict[str, str]], Atom]:
    """A function from a binding to the ground atom of a test literal, specialised for the usual arities."""
    if not any(is_var for is_var, _ in getters):
        atom = (pred, *[v for _, v in getters])
        return lambda env: atom
    if len(getters) == 1:
        name = getters[0][1]
        return lambda env: (pred, env[name])
    if len(getters) == 2:
        (first_var, first), (second_var, second) = getters
        if first_var and second_var:
            return lambda env: (pred, env[first], env[second])
        if first_var:
            return lambda env: (pred, env[first], second)
        return lambda env: (pred, first, env[second])
    if len(getters) == 3 and all(is_var for is_var, _ in getters):
        names = tuple(v for _, v in getters)
        first, second, third = names
        return lambda env: (pred, env[first], env[second], env[third])
    return lambda env: (pred, *[env[v] if is_var else v for is_var, v in getters])


def template_builder(pred: str, args: Sequence[Term]) -> Callable[[dict[str, str]], Atom]:
    """``ground(pred, args, env)`` as a function of ``env`` alone, for templates grounded again and again."""
    return _atom_builder(pred, tuple((True, a.name) if isinstance(a, Var) else (False, a) for a in args))


_TESTS = "tests-only"  # marks the plan of a clause that binds nothing (see match_clause)


def _tests_pass(tests: tuple, state: State, env: dict[str, str], axioms: Any,
                derived_source: Callable[[str], Any] | None) -> bool:
    """Whether every ground test literal (``T`` op) holds under ``env``, in order."""
    for op in tests:
        atom = op[4](env)
        kind = op[1]
        if kind in (POS, NEG):
            ok = atom in state
        elif derived_source is not None:
            ok = atom in derived_source(op[2])
        else:
            ok = axioms.holds(state, atom)
        if ok == (kind in (NEG, DNEG)):
            return False
    return True
_SCAN = "scan-then-tests"  # marks the plan of a clause that binds only with its first literal, a fact (see _scan)


def _scan(op: tuple, tests: tuple, state: State, env: dict[str, str], axioms: Any,
          derived_source: Callable[[str], Any] | None) -> Iterator[dict[str, str]]:
    """The matcher for a clause whose first literal, a fact pattern, binds every variable the rest tests.

    The usual shape of axiom bodies and method preconditions (``on(?b, ?c) and goal_on(?b, ?c) and done(?c)``):
    one loop over the candidate facts and the tests in order, the same results in the same order as
    :func:`_match_many`, without its per-level bookkeeping.
    """
    pred = op[2]
    position = op[4]
    if position:
        is_var, v = op[5]
        pool: Iterable[Atom] = state.with_arg(pred, position, env[v] if is_var else v)
    else:
        pool = state.atoms_of(pred)
    length = op[8]
    fixed = [(p, env[v] if is_var else v) for p, is_var, v in op[6]] if op[6] else ()
    free = op[7]
    for found in pool:
        if len(found) != length:
            continue
        for i, v in fixed:
            if found[i] != v:
                break
        else:
            new = dict(env)
            for place, name, same in free:
                if same and found[place] != found[same]:
                    break
                new[name] = found[place]
            else:
                for test in tests:
                    kind = test[1]
                    atom = test[4](new)
                    if kind == POS:
                        if atom not in state:
                            break
                    elif kind == NEG:
                        if atom in state:
                            break
                    elif derived_source is not None:
                        if (atom in derived_source(test[2])) == (kind == DNEG):
                            break
                    elif axioms.holds(state, atom) == (kind == DNEG):
                        break
                else:
                    yield new


def _match_many(ops: tuple, state: State, env: dict[str, str], external: ExternalFn | None,
                axioms: Any, derived_source: Callable[[str], Any] | None) -> Iterator[dict[str, str]]:
    """Iterative backtracking over the literals of a clause (no recursion), following its match plan ``ops``.

    One binding dict is updated in place: a level binds its free variables from each candidate fact and
    unbinds them when it is exhausted; only complete matches are copied. Tests (``not``, ``==``, ``!=``,
    ground atoms, external atoms) are evaluated once when their level opens. What is bound at each level is
    worked out once per clause and set of initially bound variables (:func:`_plan`).
    """
    env = dict(env)
    count = len(ops)
    last = count - 1
    iters: list[Any] = [None] * count
    level = 0
    while level >= 0:
        op = ops[level]
        it = iters[level]
        if it is None:  # open the level
            tag = op[0]
            if tag == "T":
                atom = op[4](env)
                kind = op[1]
                if kind in (POS, NEG):
                    ok = atom in state
                elif derived_source is not None:
                    ok = atom in derived_source(op[2])
                else:
                    ok = axioms.holds(state, atom)
                if kind in (NEG, DNEG):
                    ok = not ok
            elif tag == "X":
                ok = bool(_step_results(op[1], state, env, external, axioms, derived_source))
            else:
                pred = op[2]
                if op[1] == DPOS and derived_source is None:
                    iters[level] = iter(axioms.query(state, pred, op[3], env))
                else:
                    source = state if op[1] == POS else derived_source(pred)  # type: ignore[misc]
                    position = op[4]
                    if position:
                        is_var, v = op[5]
                        iters[level] = iter(source.with_arg(pred, position, env[v] if is_var else v))
                    else:
                        iters[level] = iter(source.atoms_of(pred))
                continue  # consume the first candidate below
            if not ok:
                level -= 1
                continue
            if level == last:
                yield dict(env)
                level -= 1
            else:
                iters[level] = _DONE
                level += 1
            continue
        if it is _DONE:  # back at a passed test: nothing else to try here
            iters[level] = None
            level -= 1
            continue
        free = op[7]
        tests = op[9]
        if op[1] == DPOS and derived_source is None:  # a stream of bindings from the axiom evaluator
            while True:
                for _, name, _ in free:  # the stream extends the live env: drop the previous candidate's values
                    env.pop(name, None)
                found = next(it, None)
                if found is None:
                    break
                for _, name, _ in free:
                    env[name] = found[name]
                if not tests or _tests_pass(tests, state, env, axioms, derived_source):
                    break
        else:
            length = op[8]
            fixed = [(p, env[v] if is_var else v) for p, is_var, v in op[6]] if op[6] else ()
            while True:
                found = next(it, None)
                if found is None:
                    break
                if len(found) != length:
                    continue
                for i, v in fixed:
                    if found[i] != v:
                        break
                else:
                    for position, name, same in free:
                        if same and found[position] != found[same]:
                            break
                        env[name] = found[position]
                    else:
                        if not tests or _tests_pass(tests, state, env, axioms, derived_source):
                            break
        if found is None:  # level exhausted: unbind its variables and go back
            for _, name, _ in free:
                env.pop(name, None)
            iters[level] = None
            level -= 1
            continue
        if level == last:
            yield dict(env)
        else:
            level += 1
