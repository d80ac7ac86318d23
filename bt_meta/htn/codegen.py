"""Generated evaluators for derived predicates, preconditions, whole compound tasks and primitives (the planner's
fast path).

Offers:

* :class:`Generated` -- per :class:`~bt_meta.htn.axioms.AxiomSet`: one plain Python function per derived
  predicate (truth of a ground atom), per query shape (the derived atoms matching a partly bound pattern), per
  precondition clause, per compound task (:meth:`~Generated.task_expander`: its alternatives) and per primitive
  (:meth:`~Generated.primitive_stepper`: its effects when it applies), with a memo dict per state
* :class:`Unsupported` -- a condition the generator does not handle (external atoms, a primitive binding
  variables of its own, a primitive with conditional effects): the caller keeps the reference matcher

A quantifier literal (``forall`` / ``exists``) becomes a call of its sub-condition's reference matcher with the
values of its free variables (``qh``): the loops around it are generated, the quantified part is interpreted.

Why: the reference engine (:mod:`bt_meta.htn.conditions`, :mod:`bt_meta.htn.axioms`) interprets match plans and
spends most of its time in the bookkeeping of that interpretation; straight-line loops over the same state
indexes answer the same questions several times faster. Small non-recursive derived predicates are written into
the code that tests or queries them (``INLINE_CLAUSES``, ``INLINE_LEVELS``), which saves a call, a memo entry and
a result tuple per question.

Safety: no text is parsed or executed. Each function is built as a Python :mod:`ast` tree in which every value
that comes from a task file (predicate names, constants) is an ``ast.Constant``; every identifier (``v0``,
``h3``, ``q7``, ``M2_0``, ...) is made up here, never taken from a task file. The tree is compiled with
``compile(tree, "<bt-meta rule ...>", "exec")``.

Coupling: the generated code reads :class:`~bt_meta.htn.state.State`'s private layout (``_preds``, ``_by_arg``,
``_hash``, ``_len``) and repeats the steps of ``State._apply`` (:meth:`Generated._effects`); a change to either
must be made in both (``tests/htn/test_compiled.py`` compares them on random states).

Semantics are the reference engine's, exactly: rules in file order, facts in state insertion order, the first
occurrence of a derived atom kept; a ground atom of a recursive derived predicate is proved top-down with an
in-progress marker and the same depth limit, and a proof that meets its own atom or goes deeper than
``MAX_DEPTH`` falls back, at the outermost proof, to the bottom-up extension (a truth value is the same either
way, so where the fallback happens only changes the cost); free queries on recursive predicates and queries on a
predicate whose extension a state already has are answered from that extension, as the reference does.
"""

from __future__ import annotations

import ast
import functools
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any

from bt_meta.htn.conditions import DNEG, DPOS, EQ, EXT, NEG, NEQ, NEXT, POS, QEX, QNEX, Term, Var, uses_external
from bt_meta.htn.fastpath import IN_PROGRESS as _REFERENCE_IN_PROGRESS
from bt_meta.htn.fastpath import Unsupported
from bt_meta.htn.state import Atom, atom_hash

INLINE_CLAUSES = 3  # a non-recursive derived predicate with more rule clauses than this is called, not inlined
INLINE_LEVELS = 3  # how deep inlined predicates may nest


def _locked(generate: Callable[..., Any]) -> Callable[..., Any]:
    """Generation shares a namespace and a name counter: one generation at a time (calls need no lock)."""

    @functools.wraps(generate)
    def wrapper(self: Generated, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return generate(self, *args, **kwargs)

    return wrapper


__all__ = ["Generated", "Unsupported"]  # Unsupported lives in bt_meta.htn.fastpath; importable from here too


def _name(ident: str) -> ast.Name:
    return ast.Name(id=ident, ctx=ast.Load())


def _store(ident: str) -> ast.Name:
    return ast.Name(id=ident, ctx=ast.Store())


def _const(value: Any) -> ast.Constant:
    return ast.Constant(value=value)


def _tuple(elts: Sequence[ast.expr]) -> ast.Tuple:
    return ast.Tuple(elts=list(elts), ctx=ast.Load())


def _call(func: ast.expr, *args: ast.expr) -> ast.Call:
    return ast.Call(func=func, args=list(args), keywords=[])


def _method(obj: str, meth: str, *args: ast.expr) -> ast.Call:
    return _call(ast.Attribute(value=_name(obj), attr=meth, ctx=ast.Load()), *args)


def _assign(target: str, value: ast.expr) -> ast.Assign:
    return ast.Assign(targets=[_store(target)], value=value)


def _if(test: ast.expr, body: list[ast.stmt], orelse: list[ast.stmt] | None = None) -> ast.If:
    return ast.If(test=test, body=body or [ast.Pass()], orelse=orelse or [])


def _cmp(left: ast.expr, op: ast.cmpop, right: ast.expr) -> ast.Compare:
    return ast.Compare(left=left, ops=[op], comparators=[right])


def _sub(value: ast.expr, index: int) -> ast.Subscript:
    return ast.Subscript(value=value, slice=_const(index), ctx=ast.Load())


def _guarded(checks: list[ast.expr], body: list[ast.stmt]) -> list[ast.stmt]:
    """``body`` under ``if check and ...:``, or as it is when there is nothing to check."""
    if not checks:
        return body
    return [_if(checks[0] if len(checks) == 1 else ast.BoolOp(op=ast.And(), values=checks), body)]


def _function(name: str, params: Sequence[str], body: list[ast.stmt]) -> ast.FunctionDef:
    arguments = ast.arguments(posonlyargs=[], args=[ast.arg(arg=p) for p in params], vararg=None, kwonlyargs=[],
                              kw_defaults=[], kwarg=None, defaults=[])
    extra: dict[str, Any] = {"type_params": []} if sys.version_info >= (3, 12) else {}
    return ast.FunctionDef(name=name, args=arguments, body=body, decorator_list=[], returns=None, **extra)


class _Fn:
    """Local names of one function being generated."""

    def __init__(self) -> None:
        self.count = 0
        self.facts: dict[str, str] = {}
        self.reference_memo = False  # whether the body reads the reference engine's memo (local ``om``)
        self.uses_index = False  # whether the body reads the state's argument indexes (local ``ib``)

    def fresh(self, prefix: str) -> str:
        self.count += 1
        return f"{prefix}{self.count}"

    def fact(self, pred: str) -> str:
        local = self.facts.get(pred)
        if local is None:
            local = self.facts[pred] = f"f{len(self.facts)}"
        return local

    def prologue(self) -> list[ast.stmt]:
        """``pr = st._preds`` and one local per fact predicate the body reads (its atoms, insertion order)."""
        out: list[ast.stmt] = []
        if self.reference_memo:
            out.append(_assign("om", _reference_memo()))
        if self.uses_index:
            out.append(_assign("ib", ast.Attribute(value=_name("st"), attr="_by_arg", ctx=ast.Load())))
        if not self.facts:
            return out
        out.append(_assign("pr", ast.Attribute(value=_name("st"), attr="_preds", ctx=ast.Load())))
        for pred, local in self.facts.items():
            out.append(_assign(local, _method("pr", "get", _const(pred), _name("EMPTY"))))
        return out


def _reference_memo() -> ast.expr:
    """``st._derived.get(OMK, EMPTY)``: the reference engine's memo of the state (AxiomSet.holds), if made yet."""
    return _call(ast.Attribute(value=ast.Attribute(value=_name("st"), attr="_derived", ctx=ast.Load()), attr="get",
                               ctx=ast.Load()), _name("OMK"), _name("EMPTY"))


def _quantifier_holds(sub: Any, state: Any, env: dict[str, str]) -> bool:
    """Whether a quantifier's sub-condition has a satisfier (the reference matcher, as the loader compiled it)."""
    for _ in sub.satisfiers(state, env):
        return True
    return False


class _Fallback(Exception):
    pass


_IN_PROGRESS = object()


class Generated:
    """The generated functions of one axiom set, compiled on first use into one namespace."""

    def __init__(self, axioms: Any, max_depth: int, reference_proofs: bool = False) -> None:
        self.axioms = axioms
        # reference_proofs: ground derived tests ask AxiomSet.holds (whose memo successor states inherit) instead
        # of the generated provers (whose memo starts empty in every state): cheaper on large states
        self.reference_proofs = reference_proofs
        self.memo_key = (axioms._key, "generated", reference_proofs)
        self.ns: dict[str, Any] = {
            "__builtins__": {"len": len, "set": set, "tuple": tuple, "dict": dict, "hash": atom_hash},
            "EMPTY": {}, "INP": _IN_PROGRESS, "Fallback": _Fallback, "MAXD": max_depth,
            "fb": self._fallback, "holds": axioms.holds,
            "OMK": axioms._memo_key, "OINP": _REFERENCE_IN_PROGRESS,
            "exth": self._extension_heads, "ext": axioms.extension, "qh": _quantifier_holds,
        }
        self.ids: dict[str, int] = {pred: i for i, pred in enumerate(axioms.rules)}
        for pred, i in self.ids.items():
            self.ns[f"ek{i}"] = (axioms._key, pred)  # the state cache key of the predicate's extension
        self.queries: dict[tuple[str, tuple[int, ...]], str] = {}
        self._provers_built = False
        self._matchers = 0
        self.quantified: list[Any] = []  # the sub-conditions of quantifier literals, named qs0, qs1, ...
        self._inline_level = 0
        self._lock = threading.RLock()
        for axiom in axioms.axioms:
            for clause in axiom.condition.clauses:
                if any(step[0] in (EXT, NEXT) for step in clause):
                    raise Unsupported(f"axiom {axiom.head_pred} uses an external predicate")

    # -- runtime helpers --------------------------------------------------------------------------------------
    def _fallback(self, state: Any, atom: Atom) -> bool:
        return atom in self.axioms.extension(state, atom[0])

    @staticmethod
    def _extension_heads(index: Any, pred: str, pattern: tuple[str | None, ...]) -> list[Atom]:
        """The atoms of a computed extension matching ``pattern``, in the order :func:`candidates` gives them."""
        length = len(pattern) + 1
        for position, value in enumerate(pattern, start=1):
            if value is not None:
                pool = index.with_arg(pred, position, value)
                fixed = [(i, v) for i, v in enumerate(pattern, start=1) if i > position and v is not None]
                break
        else:
            pool = index.atoms_of(pred)
            fixed = []
        out = []
        for atom in pool:
            if len(atom) != length:
                continue
            for i, v in fixed:
                if atom[i] != v:
                    break
            else:
                out.append(atom)
        return out

    def _compile(self, label: str, functions: list[ast.FunctionDef]) -> None:
        tree = ast.Module(body=list(functions), type_ignores=[])
        ast.fix_missing_locations(tree)
        code = compile(tree, f"<bt-meta rule {label}>", "exec")
        exec(code, self.ns)  # a code object built from an ast tree above, never task-file text

    # -- provers ----------------------------------------------------------------------------------------------
    def _build_provers(self) -> None:
        if self._provers_built:
            return
        self._provers_built = True
        functions: list[ast.FunctionDef] = []
        for pred, i in self.ids.items():
            rules = self.axioms.rules[pred]
            arity = len(rules[0].head_args)
            params = [f"a{j}" for j in range(arity)]
            fn = _Fn()
            recursive = pred in self.axioms.recursive
            proof: list[ast.stmt] = []
            for axiom in rules:
                proof.extend(self._rule_body(fn, axiom, params, "dd" if recursive else "d"))
            subscript_k = ast.Subscript(value=_name("m"), slice=_name("k"), ctx=ast.Store())
            settle = [ast.Assign(targets=[subscript_k], value=_const(False)), ast.Return(value=_const(False))]
            if not recursive:
                # no proof of it can meet itself: no in-progress mark, and its depth is its caller's
                functions.append(_function(f"h{i}", ["st", "m", "d", "k", *params], [*fn.prologue(), *proof, *settle]))
                continue
            body: list[ast.stmt] = [
                _if(_cmp(_method("m", "get", _name("k")), ast.Is(), _name("INP")),
                    [ast.Raise(exc=_name("Fallback"), cause=None)]),
                _if(_cmp(_name("d"), ast.GtE(), _name("MAXD")), [ast.Raise(exc=_name("Fallback"), cause=None)]),
                ast.Assign(targets=[subscript_k], value=_name("INP")),
                _assign("dd", ast.BinOp(left=_name("d"), op=ast.Add(), right=_const(1))),
                ast.Try(body=[*fn.prologue(), *proof, *settle],
                        handlers=[ast.ExceptHandler(type=_name("Fallback"), name=None, body=[
                            ast.Delete(targets=[ast.Subscript(value=_name("m"), slice=_name("k"), ctx=ast.Del())]),
                            ast.Raise(exc=None, cause=None)])],
                        orelse=[], finalbody=[]),
            ]
            functions.append(_function(f"h{i}", ["st", "m", "d", "k", *params], body))
        self._compile("provers", functions)

    def _rule_body(self, fn: _Fn, axiom: Any, params: list[str], depth: str) -> list[ast.stmt]:
        """Statements that store True and return when one rule proves the head ``k`` (inner proofs at ``depth``)."""
        checks, varmap = self._head(axiom.head_args, params)
        proved: list[ast.stmt] = [
            ast.Assign(targets=[ast.Subscript(value=_name("m"), slice=_name("k"), ctx=ast.Store())],
                       value=_const(True)),
            ast.Return(value=_const(True))]
        body: list[ast.stmt] = []
        for clause in axiom.condition.clauses:
            body.extend(self._clause(fn, list(clause), dict(varmap), depth, False, lambda _vm: list(proved)))
        return _guarded(checks, body)

    # -- queries ----------------------------------------------------------------------------------------------
    def query(self, pred: str, mask: tuple[int, ...]) -> str:
        """The name of the function giving the derived atoms of ``pred`` bound at positions ``mask``."""
        found = self.queries.get((pred, mask))
        if found is not None:
            return found
        i = self.ids[pred]
        name = f"q{i}_" + "_".join(str(p) for p in mask)
        self.queries[(pred, mask)] = name
        rules = self.axioms.rules[pred]
        arity = len(rules[0].head_args)
        params = {position: f"p{position}" for position in mask}
        pattern = _tuple([_name(params[p]) if p in params else _const(None) for p in range(1, arity + 1)])
        if pred in self.axioms.recursive:
            body: list[ast.stmt] = [ast.Return(value=_call(_name("exth"), _call(_name("ext"), _name("st"),
                                                                                 _const(pred)),
                                                           _const(pred), pattern))]
            self._compile(pred, [_function(name, ["st", "m", "d", *params.values()], body)])
            return name
        fn = _Fn()
        rules_body: list[ast.stmt] = []
        for axiom in rules:
            varmap: dict[str, str] = {}
            checks: list[ast.expr] = []
            for position, term in enumerate(axiom.head_args, start=1):
                if position not in params:
                    continue
                param = params[position]
                if term.__class__ is Var:
                    prior = varmap.get(term.name)
                    if prior is None:
                        varmap[term.name] = param
                    else:
                        checks.append(_cmp(_name(param), ast.Eq(), _name(prior)))
                else:
                    checks.append(_cmp(_name(param), ast.Eq(), _const(term)))

            def emit(vm: dict[str, str], axiom: Any = axiom) -> list[ast.stmt]:
                elts: list[ast.expr] = [_const(axiom.head_pred)]
                for term in axiom.head_args:
                    if term.__class__ is Var:
                        if term.name not in vm:
                            raise Unsupported(f"head variable ?{term.name} of {axiom.head_pred} is not bound")
                        elts.append(_name(vm[term.name]))
                    else:
                        elts.append(_const(term))
                atom = fn.fresh("x")
                return [_assign(atom, _tuple(elts)),
                        _if(_cmp(_name(atom), ast.NotIn(), _name("seen")), [
                            ast.Expr(value=_method("seen", "add", _name(atom))),
                            ast.Expr(value=_method("out", "append", _name(atom)))])]

            rule_body: list[ast.stmt] = []
            for clause in axiom.condition.clauses:
                rule_body.extend(self._clause(fn, list(clause), dict(varmap), "d", True, emit))
            rules_body.extend(_guarded(checks, rule_body))
        key = _tuple([_const(i), *[_name(p) for p in params.values()]])
        body = [
            _assign("k", key),
            _assign("v", _method("m", "get", _name("k"))),
            _if(_cmp(_name("v"), ast.IsNot(), _const(None)), [ast.Return(value=_name("v"))]),
            _assign("e", _call(ast.Attribute(value=ast.Attribute(value=_name("st"), attr="_derived", ctx=ast.Load()),
                                             attr="get", ctx=ast.Load()), _name(f"ek{i}"))),
            _if(_cmp(_name("e"), ast.IsNot(), _const(None)),
                [ast.Return(value=_call(_name("exth"), _name("e"), _const(pred), pattern))]),
            *fn.prologue(),
            _assign("out", ast.List(elts=[], ctx=ast.Load())),
            _assign("seen", _call(_name("set"))),
            *rules_body,
            _assign("v", _call(_name("tuple"), _name("out"))),
            ast.Assign(targets=[ast.Subscript(value=_name("m"), slice=_name("k"), ctx=ast.Store())],
                       value=_name("v")),
            ast.Return(value=_name("v")),
        ]
        self._compile(pred, [_function(name, ["st", "m", "d", *params.values()], body)])
        return name

    # -- preconditions ----------------------------------------------------------------------------------------
    @_locked
    def clause_matcher(self, clause: Sequence[tuple], bound: Sequence[str], label: str) -> Callable[..., Any]:
        """A generator function ``(state, env)`` yielding what :func:`match_clause` yields, in the same order."""
        if not self.reference_proofs:
            self._build_provers()
        fn = _Fn()
        varmap = {name: f"b{k}" for k, name in enumerate(bound)}
        fresh_vars = self._fresh_variables(clause, bound)

        def emit(vm: dict[str, str]) -> list[ast.stmt]:
            out: list[ast.stmt] = [_assign("res", _call(_name("dict"), _name("env")))]
            for var in fresh_vars:
                out.append(ast.Assign(targets=[ast.Subscript(value=_name("res"), slice=_const(var), ctx=ast.Store())],
                                      value=_name(vm[var])))
            out.append(ast.Expr(value=ast.Yield(value=_name("res"))))
            return out

        matched = self._clause(fn, list(clause), dict(varmap), "0", True, emit)
        used = [ast.Assign(targets=[_store(local)], value=ast.Subscript(value=_name("env"), slice=_const(name),
                                                                         ctx=ast.Load()))
                for name, local in varmap.items()]
        body: list[ast.stmt] = [*self._memo_prologue(), *fn.prologue(), *used, *matched]
        self._matchers += 1
        name = f"c{self._matchers}"
        self._compile(label, [_function(name, ["st", "env"], body)])
        return self.ns[name]  # type: ignore[no-any-return]

    # -- clause bodies ----------------------------------------------------------------------------------------
    def _inlinable(self, pred: str) -> list[Any] | None:
        """The rules of ``pred`` if it may be written in place here: small, non-recursive, not nested too deep."""
        if pred in self.axioms.recursive or self._inline_level >= INLINE_LEVELS:
            return None
        rules = self.axioms.rules[pred]
        if sum(len(axiom.condition.clauses) for axiom in rules) > INLINE_CLAUSES:
            return None
        return rules  # type: ignore[no-any-return]

    @staticmethod
    def _unify_value(fn: _Fn, term: Term, value: ast.expr, varmap: dict[str, str], checks: list[ast.expr],
                     stmts: list[ast.stmt]) -> None:
        """Unify a rule-head term with a caller's value: a test in ``checks``, or a binding in ``varmap`` (a
        constant value gets a local assigned in ``stmts`` first)."""
        if term.__class__ is not Var:
            checks.append(_cmp(value, ast.Eq(), _const(term)))
        elif term.name in varmap:  # type: ignore[union-attr]
            checks.append(_cmp(value, ast.Eq(), _name(varmap[term.name])))  # type: ignore[union-attr]
        elif isinstance(value, ast.Name):
            varmap[term.name] = value.id  # type: ignore[union-attr]
        else:
            local = fn.fresh("c")
            stmts.append(_assign(local, value))
            varmap[term.name] = local  # type: ignore[union-attr]

    def _inline_test(self, fn: _Fn, pred: str, values: list[ast.expr], depth: str,
                     outermost: bool) -> tuple[list[ast.stmt], str] | None:
        """Statements setting a fresh local to the truth of ground ``pred(values)``, its rules written in place.

        Only for small non-recursive predicates (at most ``INLINE_CLAUSES`` rule clauses, ``INLINE_LEVELS`` deep)
        whose clauses loop over at most one pattern, so a match can ``break`` out; None otherwise (the caller
        calls the prover). The truth is the prover's; only its memo entry is not written.
        """
        rules = self._inlinable(pred)
        if rules is None:
            return None
        flag = fn.fresh("t")
        stmts: list[ast.stmt] = [_assign(flag, _const(False))]
        self._inline_level += 1
        try:
            for axiom in rules:
                checks: list[ast.expr] = []
                varmap: dict[str, str] = {}
                for term, value in zip(axiom.head_args, values, strict=True):
                    self._unify_value(fn, term, value, varmap, checks, stmts)
                for clause in axiom.condition.clauses:
                    loops = self._loops(clause, varmap)
                    if loops is None or loops > 1:
                        return None
                    matched: list[ast.stmt] = [_assign(flag, _const(True))]
                    if loops:
                        matched.append(ast.Break())
                    body = self._clause(fn, list(clause), dict(varmap), depth, outermost,
                                        lambda _vm, matched=matched: list(matched))
                    body = _guarded(checks, body)
                    if len(stmts) > 1:
                        body = [_if(ast.UnaryOp(op=ast.Not(), operand=_name(flag)), body)]
                    stmts.extend(body)
        finally:
            self._inline_level -= 1
        return stmts, flag

    def _inline_query(self, fn: _Fn, pred: str, args: Sequence[Term], rest: list[tuple], varmap: dict[str, str],
                      depth: str, outermost: bool,
                      on_match: Callable[[dict[str, str]], list[ast.stmt]]) -> list[ast.stmt] | None:
        """The atoms of ``pred`` matching ``args`` found by its rules written in place, ``rest`` matched per atom.

        Yields what iterating the query function's result does: rules in order, each atom once (a set of the
        values at the free positions), for small non-recursive predicates only (None otherwise). The code of
        ``rest`` is repeated once per rule clause, which is why the predicates must be small.
        """
        rules = self._inlinable(pred)
        if rules is None:
            return None
        seen = fn.fresh("s")
        out: list[ast.stmt] = [_assign(seen, _call(_name("set")))]
        self._inline_level += 1
        try:
            for axiom in rules:
                checks: list[ast.expr] = []
                rule_vm: dict[str, str] = {}
                free: list[tuple[str, Term]] = []  # (the caller's unbound variable, the rule head term there)
                for term, arg in zip(axiom.head_args, args, strict=True):
                    if arg.__class__ is Var and arg.name not in varmap:  # type: ignore[union-attr]
                        free.append((arg.name, term))  # type: ignore[union-attr]
                        continue
                    self._unify_value(fn, term, self._value(arg, varmap), rule_vm, checks, out)

                def emit(vm: dict[str, str], free: list[tuple[str, Term]] = free) -> list[ast.stmt]:
                    outer = dict(varmap)
                    binds: list[ast.stmt] = []
                    same: list[ast.expr] = []
                    values: list[ast.expr] = []
                    for name, term in free:
                        if term.__class__ is Var:
                            if term.name not in vm:  # type: ignore[union-attr]
                                raise Unsupported(f"head variable ?{term.name} of {pred} is not bound")  # type: ignore[union-attr]
                            value: ast.expr = _name(vm[term.name])  # type: ignore[union-attr]
                        else:
                            value = _const(term)
                        values.append(value)
                        if name in outer:  # the caller repeats a variable: both positions must agree
                            same.append(_cmp(value, ast.Eq(), _name(outer[name])))
                        else:
                            local = fn.fresh("v")
                            binds.append(_assign(local, value))
                            outer[name] = local
                    key = fn.fresh("u")
                    new_atom = [ast.Expr(value=_method(seen, "add", _name(key))), *binds,
                                *self._clause(fn, rest, outer, depth, outermost, on_match)]
                    test: ast.expr = _cmp(_name(key), ast.NotIn(), _name(seen))
                    if same:
                        test = ast.BoolOp(op=ast.And(), values=[*same, test])
                    return [_assign(key, _tuple(values)), _if(test, new_atom)]

                for clause in axiom.condition.clauses:
                    body = self._clause(fn, list(clause), dict(rule_vm), depth, outermost, emit)
                    out.extend(_guarded(checks, body))
        finally:
            self._inline_level -= 1
        return out

    @staticmethod
    def _loops(clause: Sequence[tuple], varmap: dict[str, str]) -> int | None:
        """How many patterns of the clause bind new variables (loops); None if one is a derived query."""
        have = set(varmap)
        loops = 0
        for step in clause:
            if step[0] in (POS, DPOS):
                new = {a.name for a in step[2] if a.__class__ is Var and a.name not in have}
                if new:
                    if step[0] == DPOS:
                        return None
                    loops += 1
                    have |= new
        return loops

    def _value(self, term: Term, varmap: dict[str, str]) -> ast.expr:
        return _name(varmap[term.name]) if term.__class__ is Var else _const(term)  # type: ignore[union-attr]

    def _clause(self, fn: _Fn, steps: list[tuple], varmap: dict[str, str], depth: str, outermost: bool,
                on_match: Callable[[dict[str, str]], list[ast.stmt]]) -> list[ast.stmt]:
        """Nested loops and tests matching ``steps`` left to right; ``on_match`` gives the innermost statements.

        ``depth``: the local holding the proof depth of derived tests here (``"0"``: a constant 0); ``outermost``:
        whether a derived test here may be an outermost proof, so catches a fallback (when its depth is 0).
        """
        if not steps:
            return on_match(varmap)
        step, rest = steps[0], steps[1:]
        kind = step[0]
        if kind in (EXT, NEXT):
            raise Unsupported("external predicate")
        if kind in (EQ, NEQ):
            test = _cmp(self._value(step[1], varmap), ast.Eq() if kind == EQ else ast.NotEq(),
                        self._value(step[2], varmap))
            return [_if(test, self._clause(fn, rest, varmap, depth, outermost, on_match))]
        if kind in (QEX, QNEX):
            if uses_external(step[1].clauses):
                raise Unsupported("external predicate inside a quantifier")
            sub = f"qs{len(self.quantified)}"
            self.quantified.append(step[1])
            self.ns[sub] = step[1]
            env = ast.Dict(keys=[_const(v.name) for v in step[2]], values=[_name(varmap[v.name]) for v in step[2]])
            test = _call(_name("qh"), _name(sub), _name("st"), env)
            if kind == QNEX:
                test = ast.UnaryOp(op=ast.Not(), operand=test)
            return [_if(test, self._clause(fn, rest, varmap, depth, outermost, on_match))]
        pred, args = step[1], step[2]
        free = [a for a in args if a.__class__ is Var and a.name not in varmap]
        depth_expr: ast.expr = _const(0) if depth == "0" else _name(depth)
        if not free:
            atom = _tuple([_const(pred), *[self._value(a, varmap) for a in args]])
            if kind in (POS, NEG):
                test = _cmp(atom, ast.In() if kind == POS else ast.NotIn(), _name(fn.fact(pred)))
                return [_if(test, self._clause(fn, rest, varmap, depth, outermost, on_match))]
            inlined = self._inline_test(fn, pred, [self._value(a, varmap) for a in args], depth, outermost)
            if inlined is not None:
                stmts, flag = inlined
                test_expr = _name(flag) if kind == DPOS else ast.UnaryOp(op=ast.Not(), operand=_name(flag))
                return [*stmts, _if(test_expr, self._clause(fn, rest, varmap, depth, outermost, on_match))]
            if self.reference_proofs:
                # a memo entry of AxiomSet.holds is ``(truth,)``, valid for this state: read it without the call
                fn.reference_memo = True
                key = fn.fresh("k")
                truth = fn.fresh("t")
                ask: list[ast.stmt] = [
                    _assign(key, atom),
                    _assign(truth, _method("om", "get", _name(key))),
                    _if(ast.BoolOp(op=ast.Or(), values=[_cmp(_name(truth), ast.Is(), _const(None)),
                                                        _cmp(_name(truth), ast.Is(), _name("OINP"))]),
                        [_assign(truth, _call(_name("holds"), _name("st"), _name(key))),
                         _assign("om", _reference_memo())],
                        [_assign(truth, _sub(_name(truth), 0))]),
                ]
                test_expr = _name(truth)
                if kind == DNEG:
                    test_expr = ast.UnaryOp(op=ast.Not(), operand=test_expr)
                return [*ask, _if(test_expr, self._clause(fn, rest, varmap, depth, outermost, on_match))]
            key = fn.fresh("k")
            truth = fn.fresh("t")
            prover = _call(_name(f"h{self.ids[pred]}"), _name("st"), _name("m"), depth_expr, _name(key),
                           *[self._value(a, varmap) for a in args])
            compute: list[ast.stmt] = [_assign(truth, prover)]
            if outermost:
                handler: list[ast.stmt] = []
                if depth != "0":
                    handler.append(_if(_name(depth), [ast.Raise(exc=None, cause=None)]))
                handler.append(_assign(truth, _call(_name("fb"), _name("st"), _name(key))))
                compute = [ast.Try(body=compute, handlers=[ast.ExceptHandler(type=_name("Fallback"), name=None,
                                                                             body=handler)],
                                   orelse=[], finalbody=[])]
            pre: list[ast.stmt] = [
                _assign(key, atom),
                _assign(truth, _method("m", "get", _name(key))),
                _if(ast.BoolOp(op=ast.Or(), values=[_cmp(_name(truth), ast.Is(), _const(None)),
                                                    _cmp(_name(truth), ast.Is(), _name("INP"))]), compute),
            ]
            test_expr: ast.expr = _name(truth)
            if kind == DNEG:
                test_expr = ast.UnaryOp(op=ast.Not(), operand=test_expr)
            return [*pre, _if(test_expr, self._clause(fn, rest, varmap, depth, outermost, on_match))]
        if kind not in (POS, DPOS):  # a negation with unbound variables: the loader rejects it
            raise Unsupported("negated atom with unbound variables")
        if kind == DPOS:
            inlined = self._inline_query(fn, pred, args, rest, varmap, depth, outermost, on_match)
            if inlined is not None:
                return inlined
        loop = fn.fresh("i")
        new_map = dict(varmap)
        guards: list[ast.expr] = []
        binds: list[ast.stmt] = []
        if kind == POS:
            bound_positions = [p for p, a in enumerate(args, start=1)
                               if not (a.__class__ is Var and a.name not in varmap)]
            if bound_positions:
                first = bound_positions[0]
                # (st._by_arg.get((pred, first)) or st.index(pred, first)).get(value, ()): State.with_arg inlined
                made = ast.BoolOp(op=ast.Or(), values=[
                    _method("ib", "get", _const((pred, first))),
                    _method("st", "index", _const(pred), _const(first))])
                fn.uses_index = True
                pool: ast.expr = _call(ast.Attribute(value=made, attr="get", ctx=ast.Load()),
                                       self._value(args[first - 1], varmap), _tuple([]))
                fixed = bound_positions[1:]
            else:
                pool = _name(fn.fact(pred))
                fixed = []
            guards.append(_cmp(_call(_name("len"), _name(loop)), ast.NotEq(), _const(len(args) + 1)))
            for p in fixed:
                guards.append(_cmp(_sub(_name(loop), p), ast.NotEq(), self._value(args[p - 1], varmap)))
        else:
            bound_positions = [p for p, a in enumerate(args, start=1)
                               if not (a.__class__ is Var and a.name not in varmap)]
            mask = tuple(bound_positions)
            qname = self.query(pred, mask)
            pool = _call(_name(qname), _name("st"), _name("m"), depth_expr,
                         *[self._value(args[p - 1], varmap) for p in mask])
        first_position: dict[str, int] = {}
        for p, a in enumerate(args, start=1):
            if a.__class__ is Var and a.name not in varmap:
                if a.name in first_position:
                    guards.append(_cmp(_sub(_name(loop), p), ast.NotEq(), _sub(_name(loop), first_position[a.name])))
                else:
                    first_position[a.name] = p
        for var_name, p in first_position.items():
            local = fn.fresh("v")
            new_map[var_name] = local
            binds.append(_assign(local, _sub(_name(loop), p)))
        body: list[ast.stmt] = []
        if guards:
            test = guards[0] if len(guards) == 1 else ast.BoolOp(op=ast.Or(), values=guards)
            body.append(_if(test, [ast.Continue()]))
        body.extend(binds)
        body.extend(self._clause(fn, rest, new_map, depth, outermost, on_match))
        return [ast.For(target=_store(loop), iter=pool, body=body, orelse=[])]

    # -- whole tasks and primitives ---------------------------------------------------------------------------
    @staticmethod
    def _head(head: Sequence[Term], params: Sequence[str]) -> tuple[list[ast.expr], dict[str, str]]:
        """Tests the arguments in locals ``params`` must pass to unify with a head, and the head variables' locals."""
        checks: list[ast.expr] = []
        varmap: dict[str, str] = {}
        for term, param in zip(head, params, strict=True):
            if term.__class__ is Var:
                prior = varmap.get(term.name)  # type: ignore[union-attr]
                if prior is None:
                    varmap[term.name] = param  # type: ignore[union-attr]
                else:
                    checks.append(_cmp(_name(param), ast.Eq(), _name(prior)))
            else:
                checks.append(_cmp(_name(param), ast.Eq(), _const(term)))
        return checks, varmap

    @staticmethod
    def _fresh_variables(clause: Sequence[tuple], bound: Sequence[str]) -> list[str]:
        """Variables a clause binds beyond ``bound``, in the order the reference matcher adds them to a binding."""
        have = set(bound)
        fresh: list[str] = []
        for step in clause:
            if step[0] in (POS, DPOS):
                for arg in step[2]:
                    if arg.__class__ is Var and arg.name not in have:
                        have.add(arg.name)
                        fresh.append(arg.name)
        return fresh

    def _bindings(self, names: Sequence[str], vm: dict[str, str]) -> ast.Dict:
        return ast.Dict(keys=[_const(n) for n in names], values=[_name(vm[n]) for n in names])

    def _ground(self, pred: str, args: Sequence[Term], vm: dict[str, str]) -> ast.Tuple:
        values: list[ast.expr] = [_const(pred)]
        for term in args:
            if term.__class__ is Var:
                if term.name not in vm:  # type: ignore[union-attr]
                    raise Unsupported(f"?{term.name} is not bound")  # type: ignore[union-attr]
                values.append(_name(vm[term.name]))  # type: ignore[union-attr]
            else:
                values.append(_const(term))
        return _tuple(values)

    def _memo_prologue(self) -> list[ast.stmt]:
        """``m``: this state's memo of generated proofs (made on first use), as :meth:`clause_matcher` reads it."""
        self.ns["GK"] = self.memo_key
        return [
            _assign("dv", ast.Attribute(value=_name("st"), attr="_derived", ctx=ast.Load())),
            _assign("m", _method("dv", "get", _name("GK"))),
            _if(_cmp(_name("m"), ast.Is(), _const(None)), [
                ast.Assign(targets=[_store("m"), ast.Subscript(value=_name("dv"), slice=_name("GK"), ctx=ast.Store())],
                           value=ast.Dict(keys=[], values=[]))]),
        ]

    @_locked
    def task_expander(self, task: str, arity: int, methods: Sequence[Any]) -> Callable[..., Any]:
        """A generator function ``(state, *args)`` yielding ``(method, bindings, subtasks)`` for a compound task.

        It yields what the planner's reference path does (methods in order; per method the satisfiers of its
        precondition in the reference order, each clause's new ones once), with the subtasks already ground.
        Raises :class:`Unsupported` when a precondition uses something the generator does not handle.
        """
        if not self.reference_proofs:
            self._build_provers()
        fn = _Fn()
        self._matchers += 1
        name = f"x{self._matchers}"
        params = [f"a{j}" for j in range(arity)]
        body: list[ast.stmt] = []
        uses_memo = False
        for k, method in enumerate(methods):
            if len(method.task_args) != arity:
                continue  # never unifies (the loader rejects it; a learned method could still be malformed)
            method_ref = f"M{self._matchers}_{k}"
            self.ns[method_ref] = method
            checks, varmap = self._head(method.task_args, params)
            head_names = list(varmap)
            clauses = method.precondition.clauses
            seen = fn.fresh("s") if len(clauses) > 1 else None
            method_body: list[ast.stmt] = [_assign(seen, _call(_name("set")))] if seen else []
            for clause in clauses:
                if any(step[0] in (DPOS, DNEG) for step in clause):
                    uses_memo = True
                names = head_names + self._fresh_variables(clause, head_names)

                def emit(vm: dict[str, str], names: list[str] = names, method: Any = method,
                         method_ref: str = method_ref, seen: str | None = seen) -> list[ast.stmt]:
                    subtasks = _tuple([self._ground(t[0], t[1:], vm) for t in method.subtasks])
                    out_tuple = _tuple([_name(method_ref), self._bindings(names, vm), subtasks])
                    if seen is None:
                        return [ast.Expr(value=ast.Yield(value=out_tuple))]
                    # the reference keeps a binding once across clauses (compared as a set of items)
                    key = fn.fresh("u")
                    items = [_tuple([_const(n), _name(vm[n])]) for n in sorted(names)]
                    return [_assign(key, _tuple(items)),
                            _if(_cmp(_name(key), ast.NotIn(), _name(seen)), [
                                ast.Expr(value=_method(seen, "add", _name(key))),
                                ast.Expr(value=ast.Yield(value=out_tuple))])]

                method_body.extend(self._clause(fn, list(clause), dict(varmap), "0", True, emit))
            body.extend(_guarded(checks, method_body))
        body.append(ast.If(test=_const(False), body=[ast.Expr(value=ast.Yield(value=None))], orelse=[]))
        prologue = (self._memo_prologue() if uses_memo else []) + fn.prologue()
        self._compile(f"task {task}", [_function(name, ["st", *params], prologue + body)])
        return self.ns[name]  # type: ignore[no-any-return]

    @_locked
    def primitive_stepper(self, primitive: Any) -> Callable[..., Any]:
        """A function ``(state, *args)`` giving ``(bindings, successor state)`` when the primitive applies, else None.

        Only for preconditions that bind nothing beyond the parameters (so there is at most one satisfier);
        :class:`Unsupported` otherwise. The successor is :meth:`State._apply`'s, built by straight-line code
        (:meth:`_effects`).
        """
        if primitive.conditional:
            raise Unsupported(f"{primitive.name} has conditional effects")
        if not self.reference_proofs:
            self._build_provers()
        fn = _Fn()
        params = [f"a{j}" for j in range(len(primitive.parameters))]
        varmap = dict(zip(primitive.parameters, params, strict=True))
        names = list(varmap)
        body: list[ast.stmt] = []
        uses_memo = False
        for clause in primitive.precondition.clauses:
            if self._fresh_variables(clause, names):
                raise Unsupported(f"the precondition of {primitive.name} binds variables of its own")
            if any(step[0] in (DPOS, DNEG) for step in clause):
                uses_memo = True

            def emit(vm: dict[str, str]) -> list[ast.stmt]:
                return self._effects(fn, primitive, vm, self._bindings(names, vm))

            body.extend(self._clause(fn, list(clause), dict(varmap), "0", True, emit))
        body.append(ast.Return(value=_const(None)))
        prologue = (self._memo_prologue() if uses_memo else []) + fn.prologue()
        self._matchers += 1
        name = f"p{self._matchers}"
        self._compile(f"primitive {primitive.name}", [_function(name, ["st", *params], prologue + body)])
        return self.ns[name]  # type: ignore[no-any-return]

    def _effects(self, fn: _Fn, primitive: Any, vm: dict[str, str], bindings: ast.expr) -> list[ast.stmt]:
        """Statements returning ``(bindings, successor)``: what ``State._apply(add, delete)`` gives, step by step.

        The same steps in the same order: each delete that is present and not also added leaves a copy of its
        predicate's atoms (copies made in the order ``_apply`` makes them), then each add that is new (and not a
        repeat of an earlier add) goes in; the delta lists deletions, then additions. Which atoms can be equal is
        known here (same predicate and arity), so only those are compared. When two adds share a predicate,
        ``_apply`` sorts the new ones, and the generated code calls it instead.
        """
        deletes = [(t[0], len(t) - 1, fn.fresh("e"), self._ground(t[0], t[1:], vm)) for t in primitive.delete]
        adds = [(t[0], len(t) - 1, fn.fresh("e"), self._ground(t[0], t[1:], vm)) for t in primitive.add]
        out: list[ast.stmt] = [_assign(local, atom) for _, _, local, atom in deletes + adds]
        if len({pred for pred, _, _, _ in adds}) < len(adds):
            call = _method("st", "_apply", ast.List(elts=[_name(a[2]) for a in adds], ctx=ast.Load()),
                           ast.List(elts=[_name(d[2]) for d in deletes], ctx=ast.Load()))
            return [*out, ast.Return(value=_tuple([bindings, call]))]
        preds = list(dict.fromkeys(pred for pred, _, _, _ in deletes + adds))
        original = {pred: fn.fresh("o") for pred in preds}
        copy = {pred: fn.fresh("c") for pred in preds}
        out.append(_assign("sp", ast.Attribute(value=_name("st"), attr="_preds", ctx=ast.Load())))
        for pred in preds:
            out.append(_assign(original[pred], _method("sp", "get", _const(pred), _name("EMPTY"))))
            out.append(_assign(copy[pred], _const(None)))
        out += [_assign("hs", ast.Attribute(value=_name("st"), attr="_hash", ctx=ast.Load())),
                _assign("ln", ast.Attribute(value=_name("st"), attr="_len", ctx=ast.Load())),
                _assign("dl", ast.List(elts=[], ctx=ast.Load())),
                _assign("ch", ast.Dict(keys=[], values=[]))]

        def take_copy(pred: str) -> ast.stmt:
            """``cP = ch[P] = oP.copy()`` when not made yet (``_apply``'s copy on first change)."""
            target = ast.Subscript(value=_name("ch"), slice=_const(pred), ctx=ast.Store())
            made = ast.Assign(targets=[_store(copy[pred]), target], value=_method(original[pred], "copy"))
            return _if(_cmp(_name(copy[pred]), ast.Is(), _const(None)), [made])

        def count(atom: str, sign: ast.operator) -> list[ast.stmt]:
            return [ast.AugAssign(target=_store("hs"), op=sign, value=_call(_name("hash"), _name(atom))),
                    ast.AugAssign(target=_store("ln"), op=sign, value=_const(1)),
                    ast.Expr(value=_method("dl", "append", _name(atom)))]

        for pred, arity, local, _ in deletes:
            present = _cmp(_name(local), ast.In(), ast.IfExp(
                test=_cmp(_name(copy[pred]), ast.Is(), _const(None)), body=_name(original[pred]),
                orelse=_name(copy[pred])))
            tests = [present] + [_cmp(_name(local), ast.NotEq(), _name(a_local))
                                 for a_pred, a_arity, a_local, _ in adds if (a_pred, a_arity) == (pred, arity)]
            deleted = ast.Delete(targets=[ast.Subscript(value=_name(copy[pred]), slice=_name(local), ctx=ast.Del())])
            out.append(_if(ast.BoolOp(op=ast.And(), values=tests) if len(tests) > 1 else tests[0],
                           [take_copy(pred), deleted, *count(local, ast.Sub())]))
        for k, (pred, arity, local, _) in enumerate(adds):
            tests = [_cmp(_name(local), ast.NotIn(), _name(original[pred]))]
            tests += [_cmp(_name(local), ast.NotEq(), _name(earlier))
                      for e_pred, e_arity, earlier, _ in adds[:k] if (e_pred, e_arity) == (pred, arity)]
            inserted = ast.Assign(targets=[ast.Subscript(value=_name(copy[pred]), slice=_name(local), ctx=ast.Store())],
                                  value=_const(None))
            out.append(_if(ast.BoolOp(op=ast.And(), values=tests) if len(tests) > 1 else tests[0],
                           [take_copy(pred), inserted, *count(local, ast.Add())]))
        successor = ast.IfExp(test=_name("dl"), body=_method("st", "_successor", _name("ch"), _name("dl"), _name("hs"),
                                                               _name("ln")), orelse=_name("st"))
        out.append(ast.Return(value=_tuple([bindings, successor])))
        return out
