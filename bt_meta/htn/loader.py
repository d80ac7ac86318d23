"""Loading and validating YAML task files, with ``path:line:column`` on every error.

Offers:

* :func:`load_task_file` -- a file (and the domain file a problem-only file names) to a :class:`TaskFile`
* :func:`load_task_text` -- the same from a string (tests, generated problems)

The YAML is composed into nodes (``yaml.compose``) so every value keeps its position; validation walks the
nodes. One convenience goes beyond plain YAML: a flow list whose items are atoms, such as
``[place(?b, 2, 1), done()]``, is read as a list of atoms. Plain YAML would split ``place(?b`` at the comma or
refuse the ``?``; the loader reads such a list as one quoted scalar of the same length (positions unchanged)
and splits it at the top-level commas itself.

Bounds, checked before the work they protect: the file is read through :mod:`bt_meta.user_files` (regular files
only, at most 8 MiB), composed through :mod:`bt_meta.safe_yaml` (nesting depth, alias count and alias expansion
bounded, tag errors located), conditions are bounded by :mod:`bt_meta.htn.conditions` (nesting, size once
distributed), and ``domain_file:`` chains are at most :data:`MAX_DOMAIN_FILE_CHAIN` long, never circular, and
stay under the task file's folder or a root listed in ``$BT_META_DOMAIN_ROOTS``.
"""

from __future__ import annotations

import bisect
import os
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import TaskFileError
from bt_meta.htn.axioms import Axiom, AxiomSet, StratificationError
from bt_meta.htn.conditions import (
    EXT,
    KEYWORDS,
    NEXT,
    QEX,
    QNEX,
    AndExpr,
    AtomExpr,
    Condition,
    ConditionSyntaxError,
    DomainContext,
    Var,
    check_atom_predicate,
    compile_condition,
    parse_atom,
    parse_condition,
    parse_parameter,
)
from bt_meta.htn.model import ConditionalEffect, Domain, Method, Primitive, Problem, TaskDecl, TaskFile
from bt_meta.htn.state import Atom, State
from bt_meta.safe_yaml import compose_yaml, construct_yaml
from bt_meta.user_files import check_path_text, read_user_text

# A task file may name its domain's file only inside its own folder (and below) or inside a folder listed here
# (os.pathsep-separated), so a task file cannot make bt-meta read and report on any file of the machine.
DOMAIN_ROOTS_ENV = "BT_META_DOMAIN_ROOTS"
# How many domain files one task file may chain through (a problem file naming a file that names another ...).
MAX_DOMAIN_FILE_CHAIN = 8

_PREDICATE_NAME = re.compile(r"[A-Za-z0-9_.+\-](?:[A-Za-z0-9_.+\-/:]*[A-Za-z0-9_.+\-/])?")

# -- flow lists of atoms ----------------------------------------------------------------------------------------


def _rewrite_flow_lists(text: str) -> tuple[str, set[int]]:
    """Turn ``[a(?x), b()]`` into ``'a(?x), b()'`` (same length); returns the new text and the start indices."""
    out = list(text)
    starts: set[int] = set()
    i = 0
    n = len(text)
    line_start = True
    value_start = True
    block_indent: int | None = None  # inside a block scalar deeper than this indentation
    while i < n:
        if line_start:
            j = i
            while j < n and text[j] == " ":
                j += 1
            indent = j - i
            if block_indent is not None:
                if j < n and text[j] != "\n" and indent <= block_indent:
                    block_indent = None
                else:
                    nl = text.find("\n", i)
                    i = n if nl < 0 else nl + 1
                    continue
            line_start = False
            value_start = True
            i = j
            current_indent = indent
            continue
        ch = text[i]
        if ch == "\n":
            line_start = True
            i += 1
            continue
        if ch == "#" and (i == 0 or text[i - 1] in " \t\n"):
            nl = text.find("\n", i)
            i = n if nl < 0 else nl
            continue
        if ch in " \t":
            i += 1
            continue
        if value_start and ch in "'\"":
            i = _skip_quoted(text, i)
            value_start = False
            continue
        if value_start and ch in "|>":
            rest = text[i + 1: (text.find("\n", i) if text.find("\n", i) >= 0 else n)]
            if rest.split("#")[0].strip().strip("+-0123456789") == "":
                block_indent = current_indent
                nl = text.find("\n", i)
                i = n if nl < 0 else nl
                continue
        if value_start and ch == "[":
            end = _matching_bracket(text, i)
            if end is not None:
                content = text[i + 1: end]
                if ("(" in content or "?" in content) and "[" not in content and "{" not in content:
                    quote = "'" if "'" not in content else ('"' if '"' not in content and "\\" not in content else "")
                    if quote:
                        out[i] = quote
                        out[end] = quote
                        starts.add(i)
                        i = end + 1
                        value_start = False
                        continue
            i += 1
            value_start = True
            continue
        if ch in "{,":
            value_start = True
            i += 1
            continue
        if ch == ":" and (i + 1 >= n or text[i + 1] in " \t\n"):
            value_start = True
            i += 1
            continue
        if ch == "-" and value_start and (i + 1 >= n or text[i + 1] in " \t\n"):
            i += 1
            continue
        value_start = False
        i += 1
    return "".join(out), starts


def _skip_quoted(text: str, i: int) -> int:
    quote = text[i]
    j = i + 1
    while j < len(text):
        if quote == "'" and text[j] == "'":
            if j + 1 < len(text) and text[j + 1] == "'":
                j += 2
                continue
            return j + 1
        if quote == '"' and text[j] == "\\":
            j += 2
            continue
        if quote == '"' and text[j] == '"':
            return j + 1
        j += 1
    return j


def _matching_bracket(text: str, i: int) -> int | None:
    """The ``]`` closing the flow list opened at ``i`` when it holds no nested ``[`` or ``{``, else ``None``.

    Stopping at the first nested bracket keeps the whole rewrite linear: otherwise every ``[`` of 40 KB of nested
    brackets would scan to the end of the text.
    """
    depth = 0
    j = i
    while j < len(text):
        ch = text[j]
        if ch in "[{" and j > i:
            return None
        if ch in "'\"" and (text[j - 1] in "([, \t\n"):
            j = _skip_quoted(text, j)
            continue
        if ch == "#" and text[j - 1] in " \t\n":
            nl = text.find("\n", j)
            if nl < 0:
                return None
            j = nl
            continue
        if ch in "[(":
            depth += 1
        elif ch in "])":
            depth -= 1
            if depth == 0:
                return j if ch == "]" else None
        j += 1
    return None


# -- positions --------------------------------------------------------------------------------------------------
@dataclass
class Src:
    """A string from the file and how to map an offset inside it back to a 1-based line and column."""

    text: str
    locate: Callable[[int], tuple[int, int]]


class _Loader:
    def __init__(self, text: str, path: str, base_dir: Path | None, allowed_roots: Sequence[Path] = (),
                 chain: tuple[str, ...] = ()) -> None:
        self.path = path
        self.base_dir = base_dir
        self.allowed_roots = list(allowed_roots)
        self.chain = chain  # the resolved files being loaded, outermost first (domain_file cycles)
        self.text, self.flow_starts = _rewrite_flow_lists(text)
        self.line_starts = [0]
        for index, ch in enumerate(self.text):
            if ch == "\n":
                self.line_starts.append(index + 1)

    # errors and positions
    def at_index(self, index: int) -> tuple[int, int]:
        line = bisect.bisect_right(self.line_starts, index) - 1
        return line + 1, index - self.line_starts[line] + 1

    def check_predicate_name(self, pred: str, where: Any) -> None:
        """A declared predicate must be usable in a condition: one name token, not a keyword."""
        if not _PREDICATE_NAME.fullmatch(pred) or pred in KEYWORDS:
            raise self.error(f"predicate name {pred!r} is not a name (letters, digits and _ . + - / :, not "
                             "starting with / or :, and not and/or/not/true/false)", where)

    def error(self, message: str, where: Any) -> TaskFileError:
        line = column = None
        if isinstance(where, yaml.Node):
            line, column = where.start_mark.line + 1, where.start_mark.column + 1
        elif isinstance(where, tuple):
            line, column = where
        return TaskFileError(message, self.path, line, column)

    def src_of(self, node: yaml.ScalarNode) -> Src:
        value = node.value
        start = node.start_mark.index
        end = node.end_mark.index
        raw = self.text[start:end]
        style = node.style
        if style in ("'", '"'):
            begin = start + 1
            if "\n" not in raw and (style == "'" or "\\" not in raw) and "''" not in raw:
                return Src(value, lambda off: self.at_index(begin + off))
        elif style in ("|", ">"):
            # Each content line of a block scalar adds its text plus one separator ("\n" or a folding " ").
            raw_lines = raw.split("\n")[1:]
            indent = next((len(x) - len(x.lstrip(" ")) for x in raw_lines if x.strip()), 0)
            first_line = node.start_mark.line + 2
            starts: list[tuple[int, int]] = []  # (offset in value, 1-based line)
            cursor = 0
            for row, raw_line in enumerate(raw_lines):
                starts.append((cursor, first_line + row))
                cursor += len(raw_line[indent:]) + 1

            def locate(off: int) -> tuple[int, int]:
                if not starts:  # an empty block scalar: point at its indicator
                    return node.start_mark.line + 1, node.start_mark.column + 1
                k = max(bisect.bisect_right([o for o, _ in starts], off) - 1, 0)
                return starts[k][1], indent + off - starts[k][0] + 1

            return Src(value, locate)
        elif raw == value:
            return Src(value, lambda off: self.at_index(start + off))
        found = raw.find(value)
        if found >= 0:
            return Src(value, lambda off: self.at_index(start + found + off))
        fallback = (node.start_mark.line + 1, node.start_mark.column + 1)
        return Src(value, lambda off: fallback)

    # node helpers
    def mapping(self, node: yaml.Node, what: str) -> list[tuple[str, yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self.error(f"{what} must be a mapping (key: value), found {_node_kind(node)}", node)
        seen: dict[str, yaml.Node] = {}
        items: list[tuple[str, yaml.Node, yaml.Node]] = []
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise self.error(f"keys of {what} must be plain names, found {_node_kind(key_node)}", key_node)
            key = key_node.value
            if key in seen:
                first = seen[key].start_mark.line + 1
                raise self.error(f"duplicate key {key!r} in {what} (first defined at line {first})", key_node)
            seen[key] = key_node
            items.append((key, key_node, value_node))
        return items

    def keys(self, node: yaml.Node, what: str, allowed: set[str], required: set[str] = frozenset()
             ) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        items = self.mapping(node, what)
        result: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key, key_node, value_node in items:
            if key not in allowed:
                raise self.error(f"unknown key {key!r} in {what} (expected one of: {', '.join(sorted(allowed))})",
                                 key_node)
            result[key] = (key_node, value_node)
        for key in sorted(required):
            if key not in result:
                raise self.error(f"{what} is missing the required key {key!r}", node)
        return result

    def scalar(self, node: yaml.Node, what: str) -> str:
        if not isinstance(node, yaml.ScalarNode) or node.start_mark.index in self.flow_starts:
            raise self.error(f"{what} must be a single value, found {_node_kind(node, self.flow_starts)}", node)
        return node.value

    def is_null(self, node: yaml.Node) -> bool:
        return isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null"

    def items(self, node: yaml.Node, what: str) -> list[Src]:
        """A list of strings: a YAML sequence of scalars, or a flow list of atoms."""
        if self.is_null(node):
            return []
        if isinstance(node, yaml.ScalarNode) and node.start_mark.index in self.flow_starts:
            return self._split_flow(node)
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(f"{what} must be a list, found {_node_kind(node)}", node)
        result = []
        for item in node.value:
            if not isinstance(item, yaml.ScalarNode) or item.start_mark.index in self.flow_starts:
                raise self.error(f"each item of {what} must be a string, found {_node_kind(item, self.flow_starts)}",
                                 item)
            result.append(self.src_of(item))
        return result

    def _split_flow(self, node: yaml.ScalarNode) -> list[Src]:
        start = node.start_mark.index + 1
        end = node.end_mark.index - 1
        items: list[Src] = []
        depth = 0
        item_start = start
        j = start

        def flush(stop: int) -> None:
            raw = self.text[item_start:stop]
            # drop comments that a multi-line flow list may hold
            lines = [(line.split(" #")[0] if " #" in line else line) for line in raw.split("\n")]
            cleaned = "\n".join(lines)
            stripped = cleaned.strip()
            if not stripped:
                if stop < end or items:
                    raise self.error("empty item in a list (two commas in a row?)", self.at_index(stop))
                return
            lead = len(cleaned) - len(cleaned.lstrip())
            begin = item_start + lead
            if len(stripped) >= 2 and stripped[0] in "'\"" and stripped[-1] == stripped[0] \
                    and _skip_quoted(stripped, 0) == len(stripped):
                # a quoted item inside an atom list, e.g. ["?x", "?y"]
                inner = stripped[1:-1]
                inner = inner.replace("''", "'") if stripped[0] == "'" else inner.replace('\\"', '"')
                items.append(Src(inner, lambda off, b=begin: self.at_index(b + 1 + off)))
                return
            one_line = " ".join(stripped.split())
            if "\n" in stripped:
                items.append(Src(one_line, lambda off, b=begin: self.at_index(b)))
            else:
                items.append(Src(stripped, lambda off, b=begin: self.at_index(b + off)))

        while j < end:
            ch = self.text[j]
            if ch in "'\"":
                j = _skip_quoted(self.text, j)
                continue
            if ch == "(":
                depth += 1
            elif ch == ")":
                depth -= 1
            elif ch == "," and depth == 0:
                flush(j)
                item_start = j + 1
            j += 1
        flush(end)
        return items

    def condition_src(self, node: yaml.Node, what: str) -> Src | None:
        """A condition: a string, or a list of strings meaning their conjunction."""
        if self.is_null(node):
            return None
        if isinstance(node, yaml.ScalarNode) and node.start_mark.index not in self.flow_starts:
            return self.src_of(node)
        parts = self.items(node, what)
        if not parts:
            return None
        if len(parts) == 1:
            return parts[0]
        # Join with ' and ', keeping a map from offsets in the joined text back to each part.
        offsets: list[int] = []
        joined = ""
        for index, part in enumerate(parts):
            if index:
                joined += " and "
            offsets.append(len(joined))
            joined += f"({part.text})"

        def locate(off: int) -> tuple[int, int]:
            k = max(bisect.bisect_right(offsets, off) - 1, 0)
            inner = max(off - offsets[k] - 1, 0)
            return parts[k].locate(min(inner, len(parts[k].text)))

        return Src(joined, locate)

    # parsing helpers with positions
    def parse_atom(self, src: Src) -> AtomExpr:
        try:
            return parse_atom(src.text)
        except ConditionSyntaxError as exc:
            raise self.error(exc.message, src.locate(exc.offset)) from None

    def compile(self, src: Src | None, context: DomainContext, bound: set[str]) -> Condition:
        text = src.text if src is not None else "true"
        try:
            expr = parse_condition(text)
            return compile_condition(text, expr, context, bound)
        except ConditionSyntaxError as exc:
            where = src.locate(exc.offset) if src is not None else None
            raise self.error(exc.message, where) from None

    def parameters(self, node: yaml.Node, what: str, types: dict[str, str | None]
                   ) -> tuple[list[str], list[str | None]]:
        names: list[str] = []
        param_types: list[str | None] = []
        for src in self.items(node, what):
            try:
                name, type_name = parse_parameter(src.text)
            except ConditionSyntaxError as exc:
                raise self.error(f"bad parameter {src.text!r} in {what}: {exc.message}",
                                 src.locate(exc.offset)) from None
            if name in names:
                raise self.error(f"duplicate parameter ?{name} in {what}", src.locate(0))
            if type_name is not None and type_name not in types:
                known = ", ".join(sorted(types)) or "no types declared"
                raise self.error(f"unknown type {type_name!r} in {what} (known: {known})",
                                 src.locate(src.text.index(type_name, src.text.index("-"))))
            names.append(name)
            param_types.append(type_name)
        return names, param_types

    # -- the file ---------------------------------------------------------------------------------------------
    def load(self) -> TaskFile:
        root = compose_yaml(self.text, self.path, TaskFileError)
        if root is None:
            raise self.error("empty task file: expected a mapping with 'domain:' and/or 'problems:'", (1, 1))
        if not isinstance(root, yaml.MappingNode):
            # Not echoing the value: a file that is not a task file at all should not be quoted back.
            raise self.error(f"a task file must be a mapping with 'domain:' and/or 'problems:', found "
                             f"{'a list' if isinstance(root, yaml.SequenceNode) else 'a single value'}", root)
        top = self.keys(root, "the task file", {"domain", "problems", "domain_file"})
        if "domain" in top and "domain_file" in top:
            raise self.error("a task file has either 'domain:' or 'domain_file:', not both", top["domain_file"][0])
        domain_path: str | None = None
        if "domain" in top:
            domain = self.domain(top["domain"][1])
        elif "domain_file" in top:
            domain_path, domain = self.domain_file(top["domain_file"][1])
        else:
            raise self.error("the task file has no 'domain:' (or 'domain_file:' naming the domain's file)", root)
        problems: dict[str, Problem] = {}
        if "problems" in top and not self.is_null(top["problems"][1]):
            for name, key_node, value in self.mapping(top["problems"][1], "problems"):
                problems[name] = self.problem(name, key_node, value, domain)
        return TaskFile(self.path, domain, problems, domain_path)

    def domain_file(self, node: yaml.Node) -> tuple[str, Domain]:
        name = self.scalar(node, "domain_file")
        try:
            check_path_text(name, "domain file", TaskFileError)
        except TaskFileError as exc:
            raise self.error(exc.message, node) from None
        base = (self.base_dir if self.base_dir is not None else Path.cwd()).resolve()
        try:
            target = (base / name).resolve()
        except (OSError, RuntimeError):
            raise self.error(f"domain file {name!r}: symlink loop", node) from None
        allowed = [base, *self.allowed_roots]
        if not any(target == root or root in target.parents for root in allowed):
            raise self.error(f"domain file {name!r} is outside the task file's folder {base}; a domain file must be "
                             f"in that folder or below it, or under a folder listed in ${DOMAIN_ROOTS_ENV}", node)
        if str(target) in self.chain:
            raise self.error(f"domain file {name!r} names a file that is already being loaded (a cycle: "
                             f"{' -> '.join(Path(p).name for p in (*self.chain, str(target)))})", node)
        if len(self.chain) >= MAX_DOMAIN_FILE_CHAIN:
            raise self.error(f"domain file {name!r}: more than {MAX_DOMAIN_FILE_CHAIN} domain files chained", node)
        if not target.exists():
            raise self.error(f"domain file {name!r} not found (looked for {target})", node)
        loaded = _load_file(target, self.allowed_roots, self.chain)
        return str(target), loaded.domain

    # -- domain ---------------------------------------------------------------------------------------------
    def domain(self, node: yaml.Node) -> Domain:
        keys = self.keys(node, "domain", {"name", "types", "predicates", "external", "axioms", "primitives",
                                          "tasks", "methods"})
        name = self.scalar(keys["name"][1], "domain name") if "name" in keys else Path(self.path).stem
        types = self.types(keys["types"][1]) if "types" in keys else {}

        arities: dict[str, int] = {}
        predicates: dict[str, list[str]] = {}
        positions: dict[str, yaml.Node] = {}
        for type_name in types:
            arities[type_name] = 1
        if "predicates" in keys and not self.is_null(keys["predicates"][1]):
            for pred, key_node, value in self.mapping(keys["predicates"][1], "predicates"):
                self.check_predicate_name(pred, key_node)
                arg_types = [src.text for src in self.items(value, f"the argument types of predicate {pred}")]
                if pred in types and arg_types != [pred] and len(arg_types) != 1:
                    raise self.error(f"predicate {pred} has the name of a type (a type is a 1-argument "
                                     "predicate)", key_node)
                self.check_types(arg_types, value, types, f"predicate {pred}")
                predicates[pred] = arg_types
                arities[pred] = len(arg_types)
                positions[pred] = key_node
        external: dict[str, list[str]] = {}
        if "external" in keys and not self.is_null(keys["external"][1]):
            for pred, key_node, value in self.mapping(keys["external"][1], "external"):
                self.check_predicate_name(pred, key_node)
                if pred in arities:
                    raise self.error(f"external predicate {pred} is already declared as a predicate or type",
                                     key_node)
                arg_types = [src.text for src in self.items(value, f"the argument types of external {pred}")]
                self.check_types(arg_types, value, types, f"external predicate {pred}")
                external[pred] = arg_types
                arities[pred] = len(arg_types)
        context = DomainContext(arities=arities, external=set(external))

        # axioms: heads first (they declare derived predicates), then bodies
        axiom_nodes: list[tuple[yaml.Node, AtomExpr, Src, yaml.Node | None]] = []
        if "axioms" in keys and not self.is_null(keys["axioms"][1]):
            axioms_node = keys["axioms"][1]
            if not isinstance(axioms_node, yaml.SequenceNode):
                raise self.error(f"axioms must be a list of {{head: ..., when: ...}}, found {_node_kind(axioms_node)}",
                                 axioms_node)
            derived_arity: dict[str, int] = {}
            for item in axioms_node.value:
                ax = self.keys(item, "an axiom", {"head", "when"}, {"head"})
                head_src = self.src_of_scalar(ax["head"][1], "axiom head")
                head = self.parse_atom(head_src)
                if head.pred in predicates or head.pred in types:
                    raise self.error(f"axiom head {head.pred} is a declared predicate; derived predicates must not be "
                                     "declared or changed by effects", head_src.locate(head.offset))
                if head.pred in external:
                    raise self.error(f"axiom head {head.pred} is an external predicate", head_src.locate(head.offset))
                if derived_arity.setdefault(head.pred, len(head.args)) != len(head.args):
                    raise self.error(f"axiom head {head.pred} has {len(head.args)} arguments but an earlier axiom "
                                     f"gives it {derived_arity[head.pred]}", head_src.locate(head.offset))
                axiom_nodes.append((item, head, head_src, ax["when"][1] if "when" in ax else None))
            for pred, arity in derived_arity.items():
                arities[pred] = arity
            context.derived = set(derived_arity)
        axioms: list[Axiom] = []
        for item, head, head_src, when_node in axiom_nodes:
            src = self.condition_src(when_node, "axiom condition") if when_node is not None else None
            condition = self.compile(src, context, set())
            for step_clause in condition.clauses:
                for step in step_clause:
                    if step[0] in (EXT, NEXT):
                        raise self.error(f"axiom {head.pred} uses external predicate {step[1]}; axioms may use "
                                         "state and derived predicates only",
                                         src.locate(step[3].offset) if src else None)
                    if step[0] in (QEX, QNEX):
                        # the axiom memo (inherited by successor states) does not watch the facts a quantifier
                        # reads, and stratification does not see through it
                        raise self.error(f"axiom {head.pred} uses '{step[3].op}'; axiom conditions may not use "
                                         "quantifiers (write the quantified part as an axiom of its own: "
                                         "forall F is 'not' of an axiom for 'type and not F')",
                                         src.locate(step[3].offset) if src else None)
            for arg, offset in zip(head.args, head.arg_offsets, strict=False):
                if isinstance(arg, Var) and arg.name not in condition.variables_bound:
                    raise self.error(f"variable ?{arg.name} in the axiom head is not bound by its condition",
                                     head_src.locate(offset))
            axioms.append(Axiom(head.pred, head.args, condition, src.text if src else "true",
                                item.start_mark.line + 1, item.start_mark.column + 1))
        try:
            axiom_set = AxiomSet(axioms)
        except StratificationError as exc:
            raise self.error(exc.message, (exc.axiom.line, exc.axiom.column)) from None
        context.axioms = axiom_set

        # declarations of primitives and tasks (names and parameters) before bodies: methods refer to both
        prim_nodes: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        if "primitives" in keys and not self.is_null(keys["primitives"][1]):
            for pname, key_node, value in self.mapping(keys["primitives"][1], "primitives"):
                prim_nodes[pname] = (key_node, value)
        tasks: dict[str, TaskDecl] = {}
        if "tasks" in keys and not self.is_null(keys["tasks"][1]):
            for tname, key_node, value in self.mapping(keys["tasks"][1], "tasks"):
                if tname in prim_nodes:
                    raise self.error(f"duplicate name {tname!r}: it is both a primitive (line "
                                     f"{prim_nodes[tname][0].start_mark.line + 1}) and a task", key_node)
                params, ptypes = self.parameters(value, f"the parameters of task {tname}", types)
                tasks[tname] = TaskDecl(tname, params, ptypes, key_node.start_mark.line + 1,
                                        key_node.start_mark.column + 1)
        primitives: dict[str, Primitive] = {}
        for pname, (key_node, value) in prim_nodes.items():
            primitives[pname] = self.primitive(pname, key_node, value, context, types, predicates)

        methods: list[Method] = []
        if "methods" in keys and not self.is_null(keys["methods"][1]):
            methods_node = keys["methods"][1]
            if not isinstance(methods_node, yaml.SequenceNode):
                raise self.error(f"methods must be a list (tried in order), found {_node_kind(methods_node)}",
                                 methods_node)
            names: dict[str, int] = {}
            for item in methods_node.value:
                method = self.method(item, context, primitives, tasks)
                if method.name in names:
                    raise self.error(f"duplicate method name {method.name!r} (first defined at line "
                                     f"{names[method.name]})", item)
                names[method.name] = item.start_mark.line + 1
                methods.append(method)
        return Domain(name, types, predicates, external, axioms, primitives, tasks, methods, context, axiom_set,
                      self.path)

    def src_of_scalar(self, node: yaml.Node, what: str) -> Src:
        self.scalar(node, what)
        return self.src_of(node)  # type: ignore[arg-type]

    def types(self, node: yaml.Node) -> dict[str, str | None]:
        types: dict[str, str | None] = {}
        if self.is_null(node):
            return types
        if isinstance(node, yaml.MappingNode):
            pairs = self.mapping(node, "types")
            for name, _key_node, value in pairs:
                parent = None if self.is_null(value) else self.scalar(value, f"the parent type of {name}")
                types[name] = parent
            for name, key_node, value in pairs:
                parent = types[name]
                if parent is not None and parent not in types and parent != "object":
                    raise self.error(f"unknown parent type {parent!r} of type {name}", value)
                seen = {name}
                while parent is not None and parent in types:
                    if parent in seen:
                        raise self.error(f"type {name} is its own ancestor (cycle in types)", key_node)
                    seen.add(parent)
                    parent = types[parent]
            for name in list(types):
                if types[name] == "object" and "object" not in types:
                    types[name] = None
            return types
        seen_nodes: dict[str, Src] = {}
        for src in self.items(node, "types"):
            if src.text in seen_nodes:
                raise self.error(f"duplicate type {src.text!r}", src.locate(0))
            seen_nodes[src.text] = src
            types[src.text] = None
        return types

    def check_types(self, arg_types: list[str], node: yaml.Node, types: dict[str, str | None], what: str) -> None:
        if not types:
            return
        for type_name in arg_types:
            if type_name not in types and type_name != "object":
                raise self.error(f"unknown type {type_name!r} in {what} (known: {', '.join(sorted(types))})", node)

    def primitive(self, name: str, key_node: yaml.Node, node: yaml.Node, context: DomainContext,
                  types: dict[str, str | None], predicates: dict[str, list[str]]) -> Primitive:
        what = f"primitive {name}"
        if self.is_null(node):
            node = yaml.MappingNode("tag:yaml.org,2002:map", [], node.start_mark, node.end_mark)
        keys = self.keys(node, what, {"parameters", "precondition", "add", "delete", "effects", "cost",
                                      "expectations"})
        params, ptypes = (self.parameters(keys["parameters"][1], f"the parameters of {what}", types)
                          if "parameters" in keys else ([], []))
        pre_src = self.condition_src(keys["precondition"][1], f"the precondition of {what}") \
            if "precondition" in keys else None
        precondition = self.compile(pre_src, context, set(params))
        effects = self.effect_lists(keys, context, precondition.variables_bound, what,
                                    "its parameters or its precondition")
        conditional = []
        if "effects" in keys and not self.is_null(keys["effects"][1]):
            conditional = self.conditional_effects(keys["effects"][1], context, precondition.variables_bound, what)
        cost = 1.0
        if "cost" in keys:
            text = self.scalar(keys["cost"][1], f"the cost of {what}")
            try:
                cost = float(text)
            except ValueError:
                raise self.error(f"the cost of {what} must be a number, found {text!r}", keys["cost"][1]) from None
        expectations: dict[str, Any] = {}
        if "expectations" in keys and not self.is_null(keys["expectations"][1]):
            exp_node = keys["expectations"][1]
            self.mapping(exp_node, f"the expectations of {what}")
            expectations = construct_yaml(exp_node, self.path, TaskFileError)
        return Primitive(name, params, ptypes, precondition, effects["add"], effects["delete"], cost, expectations,
                         key_node.start_mark.line + 1, key_node.start_mark.column + 1, conditional)

    def effect_lists(self, keys: dict[str, tuple[yaml.Node, yaml.Node]], context: DomainContext,
                     bound: frozenset[str] | set[str], what: str, by: str) -> dict[str, list[tuple]]:
        """The ``add:`` and ``delete:`` atoms of a primitive or of one of its conditional effects."""
        effects: dict[str, list[tuple]] = {"add": [], "delete": []}
        for effect_key in ("add", "delete"):
            if effect_key not in keys:
                continue
            for src in self.items(keys[effect_key][1], f"the {effect_key} effects of {what}"):
                atom = self.parse_atom(src)
                if atom.pred in context.derived:
                    raise self.error(f"effect {atom.pred} is a derived predicate (an axiom head); effects may only "
                                     "change declared predicates", src.locate(atom.offset))
                if atom.pred in context.external:
                    raise self.error(f"effect {atom.pred} is an external predicate; its truth comes from a plugin",
                                     src.locate(atom.offset))
                self.check_atom(atom, context, src)
                self.check_bound(atom, bound, src, f"effect of {what}", by)
                effects[effect_key].append((atom.pred, *atom.args))
        return effects

    def conditional_effects(self, node: yaml.Node, context: DomainContext, bound: frozenset[str],
                            what: str) -> list[ConditionalEffect]:
        """``effects:``, a list of ``{forall: [?v - type, ...], when: condition, add: [...], delete: [...]}``."""
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(f"the effects of {what} must be a list of {{forall: ..., when: ..., add: ..., "
                             f"delete: ...}}, found {_node_kind(node, self.flow_starts)}", node)
        found: list[ConditionalEffect] = []
        for index, item in enumerate(node.value, start=1):
            where = f"conditional effect {index} of {what}"
            keys = self.keys(item, where, {"forall", "when", "add", "delete"})
            if "add" not in keys and "delete" not in keys:
                raise self.error(f"{where} has neither 'add:' nor 'delete:'", item)
            variables: list[str] = []
            types: list[str] = []
            type_atoms: list[AtomExpr] = []
            if "forall" in keys:
                for src in self.items(keys["forall"][1], f"the forall variables of {where}"):
                    try:
                        name, type_name = parse_parameter(src.text)
                    except ConditionSyntaxError as exc:
                        raise self.error(f"bad variable {src.text!r} in the forall of {where}: {exc.message}",
                                         src.locate(exc.offset)) from None
                    if type_name is None:
                        raise self.error(f"forall variable ?{name} of {where} needs a type: ?{name} - type",
                                         src.locate(0))
                    if name in variables or name in bound:
                        raise self.error(f"forall variable ?{name} of {where} is already "
                                         f"{'quantified' if name in variables else 'bound by the primitive'}; "
                                         "give it another name", src.locate(0))
                    if context.arities.get(type_name) != 1 or type_name in context.external:
                        unary = sorted(p for p, n in context.arities.items() if n == 1 and p not in context.external)
                        raise self.error(f"the type {type_name!r} of ?{name} is not a type or a unary predicate "
                                         f"(known: {', '.join(unary) or 'none'})",
                                         src.locate(src.text.index(type_name, src.text.index("-"))))
                    variables.append(name)
                    types.append(type_name)
                    type_atoms.append(AtomExpr(type_name, (Var(name),), 0, (0,)))
            inner = set(bound) | set(variables)
            when_src = self.condition_src(keys["when"][1], f"the when condition of {where}") \
                if "when" in keys else None
            when = self.compile(when_src, context, inner)
            try:
                condition = compile_condition(when.source, AndExpr((*type_atoms, when.expr)), context, bound)
            except ConditionSyntaxError as exc:  # the size bounds, with the forall's type atoms added
                raise self.error(exc.message, when_src.locate(exc.offset) if when_src else item) from None
            lists = self.effect_lists(keys, context, inner, where,
                                      "its forall, its primitive's parameters or its precondition")
            found.append(ConditionalEffect(variables, types, when, condition, lists["add"], lists["delete"],
                                           item.start_mark.line + 1, item.start_mark.column + 1))
        return found

    def check_atom(self, atom: AtomExpr, context: DomainContext, src: Src) -> None:
        try:
            check_atom_predicate(atom, context)
        except ConditionSyntaxError as exc:
            raise self.error(exc.message, src.locate(exc.offset)) from None

    def check_bound(self, atom: AtomExpr, bound: frozenset[str] | set[str], src: Src, what: str, by: str) -> None:
        for arg, offset in zip(atom.args, atom.arg_offsets, strict=False):
            if isinstance(arg, Var) and arg.name not in bound:
                raise self.error(f"variable ?{arg.name} in {what} is not bound by {by}", src.locate(offset))

    def check_call(self, atom: AtomExpr, src: Src, primitives: dict[str, Primitive], tasks: dict[str, TaskDecl],
                   what: str) -> None:
        if atom.pred in primitives:
            arity = len(primitives[atom.pred].parameters)
        elif atom.pred in tasks:
            arity = len(tasks[atom.pred].parameters)
        else:
            known = ", ".join(sorted([*primitives, *tasks])) or "none declared"
            raise self.error(f"unknown task or primitive {atom.pred!r} in {what} (known: {known})",
                             src.locate(atom.offset))
        if arity != len(atom.args):
            raise self.error(f"{atom.pred} takes {arity} argument{'s' if arity != 1 else ''}, got {len(atom.args)}",
                             src.locate(atom.offset))

    def method(self, node: yaml.Node, context: DomainContext, primitives: dict[str, Primitive],
               tasks: dict[str, TaskDecl]) -> Method:
        keys = self.keys(node, "a method", {"name", "task", "precondition", "subtasks", "unordered"},
                         {"name", "task"})
        name = self.scalar(keys["name"][1], "the method name")
        what = f"method {name}"
        head_src = self.src_of_scalar(keys["task"][1], f"the task of {what}")
        head = self.parse_atom(head_src)
        if head.pred in primitives:
            raise self.error(f"{what} decomposes {head.pred}, which is a primitive; methods decompose compound tasks "
                             "(declare it under tasks:)", head_src.locate(head.offset))
        if head.pred not in tasks:
            known = ", ".join(sorted(tasks)) or "none declared"
            raise self.error(f"unknown task {head.pred!r} in {what} (declared tasks: {known})",
                             head_src.locate(head.offset))
        self.check_call(head, head_src, primitives, tasks, what)
        head_vars = {a.name for a in head.args if isinstance(a, Var)}
        pre_src = self.condition_src(keys["precondition"][1], f"the precondition of {what}") \
            if "precondition" in keys else None
        precondition = self.compile(pre_src, context, head_vars)
        if "subtasks" in keys and "unordered" in keys:
            raise self.error(f"{what} has both 'subtasks' (ordered) and 'unordered'; give one", keys["unordered"][0])
        ordered = "unordered" not in keys
        sub_key = "subtasks" if ordered else "unordered"
        subtasks: list[tuple] = []
        if sub_key in keys:
            for src in self.items(keys[sub_key][1], f"the subtasks of {what}"):
                atom = self.parse_atom(src)
                self.check_call(atom, src, primitives, tasks, f"the subtasks of {what}")
                self.check_bound(atom, precondition.variables_bound, src, f"subtask {atom.pred} of {what}",
                                 "the task head or the precondition")
                subtasks.append((atom.pred, *atom.args))
        return Method(name, head.pred, head.args, precondition, subtasks, ordered, node.start_mark.line + 1,
                      node.start_mark.column + 1)

    # -- problems ---------------------------------------------------------------------------------------------
    def problem(self, name: str, key_node: yaml.Node, node: yaml.Node, domain: Domain) -> Problem:
        what = f"problem {name}"
        keys = self.keys(node, what, {"objects", "init", "tasks", "goal"}, {"tasks"})
        context = domain.context
        objects: dict[str, list[str]] = {}
        facts: list[Atom] = []
        if "objects" in keys and not self.is_null(keys["objects"][1]):
            for type_name, type_key, value in self.mapping(keys["objects"][1], f"the objects of {what}"):
                if type_name not in domain.types:
                    known = ", ".join(sorted(domain.types)) or "no types declared"
                    raise self.error(f"unknown type {type_name!r} in the objects of {what} (known: {known})",
                                     type_key)
                names = [src.text for src in self.items(value, f"the {type_name} objects of {what}")]
                objects[type_name] = names
                for obj in names:
                    type_cursor: str | None = type_name
                    while type_cursor is not None:
                        facts.append((type_cursor, obj))
                        type_cursor = domain.types.get(type_cursor)
        init: list[Atom] = []
        if "init" in keys:
            for src in self.items(keys["init"][1], f"the initial facts of {what}"):
                atom = self.parse_atom(src)
                if atom.pred in context.derived:
                    raise self.error(f"initial fact {atom.pred} is a derived predicate (computed by axioms)",
                                     src.locate(atom.offset))
                if atom.pred in context.external:
                    raise self.error(f"initial fact {atom.pred} is an external predicate (a plugin decides it)",
                                     src.locate(atom.offset))
                self.check_atom(atom, context, src)
                self.check_ground(atom, src, f"initial fact of {what}")
                init.append((atom.pred, *atom.args))  # type: ignore[arg-type]
        tasks: list[Atom] = []
        for src in self.items(keys["tasks"][1], f"the tasks of {what}"):
            atom = self.parse_atom(src)
            self.check_call(atom, src, domain.primitives, domain.tasks, f"the tasks of {what}")
            self.check_ground(atom, src, f"task of {what}")
            tasks.append((atom.pred, *atom.args))  # type: ignore[arg-type]
        goal: list[Atom] = []
        if "goal" in keys:
            for src in self.items(keys["goal"][1], f"the goal of {what}"):
                atom = self.parse_atom(src)
                if atom.pred in context.external:
                    raise self.error(f"goal fact {atom.pred} is an external predicate", src.locate(atom.offset))
                self.check_atom(atom, context, src)
                self.check_ground(atom, src, f"goal fact of {what}")
                goal.append((atom.pred, *atom.args))  # type: ignore[arg-type]
        state = State([*facts, *init])
        return Problem(name, objects, init, tasks, goal, state, key_node.start_mark.line + 1,
                       key_node.start_mark.column + 1)

    def check_ground(self, atom: AtomExpr, src: Src, what: str) -> None:
        for arg, offset in zip(atom.args, atom.arg_offsets, strict=False):
            if isinstance(arg, Var):
                raise self.error(f"{what} must be ground: variable ?{arg.name} not allowed here", src.locate(offset))


def _node_kind(node: yaml.Node, flow_starts: set[int] | None = None) -> str:
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    if flow_starts and node.start_mark.index in flow_starts:
        return "a list"
    if node.tag == "tag:yaml.org,2002:null":
        return "nothing"
    return f"the value {node.value!r}"


def domain_roots(extra: Iterable[str | Path] = ()) -> list[Path]:
    """The folders besides a task file's own in which its ``domain_file:`` may lie: ``extra`` and the folders of
    ``$BT_META_DOMAIN_ROOTS`` (separated by ``os.pathsep``; empty entries ignored)."""
    listed = [entry for entry in os.environ.get(DOMAIN_ROOTS_ENV, "").split(os.pathsep) if entry.strip()]
    roots = []
    for entry in [*extra, *listed]:
        try:
            roots.append(Path(check_path_text(entry, "domain root", TaskFileError)).expanduser().resolve())
        except (OSError, RuntimeError):
            continue
    return roots


def load_task_text(text: str, path: str = "<string>", base_dir: str | Path | None = None, *,
                   allowed_roots: Iterable[str | Path] = ()) -> TaskFile:
    """Load a task file from text; ``base_dir`` resolves a ``domain_file:`` (default: the path's folder, else the
    current folder), which must lie under ``base_dir`` or one of :func:`domain_roots` (``allowed_roots`` added)."""
    if base_dir is None and path != "<string>":
        base_dir = Path(path).resolve().parent
    return _Loader(text, path, Path(base_dir) if base_dir is not None else None, domain_roots(allowed_roots)).load()


def load_task_file(path: str | Path, *, allowed_roots: Iterable[str | Path] = ()) -> TaskFile:
    """Load and validate a YAML task file; every problem raises :class:`TaskFileError` with its position.

    The file must be a regular file of at most 8 MiB (:func:`bt_meta.user_files.read_user_text`); a
    ``domain_file:`` it names must lie under its folder or one of :func:`domain_roots` (``allowed_roots`` added).
    """
    return _load_file(path, domain_roots(allowed_roots), ())


def _load_file(path: str | Path, roots: Sequence[Path], chain: tuple[str, ...]) -> TaskFile:
    text = read_user_text(path, what="task file", error=TaskFileError)
    file_path = Path(path)
    try:
        resolved = file_path.resolve()
    except (OSError, RuntimeError):
        raise TaskFileError("cannot resolve the task file's path (symlink loop)", str(path)) from None
    return _Loader(text, str(path), resolved.parent, roots, (*chain, str(resolved))).load()


def problem_from_atoms(domain: Domain, name: str, *, init: Iterable[Sequence[str]], tasks: Iterable[Sequence[str]],
                       goal: Iterable[Sequence[str]] = (), objects: dict[str, list[str]] | None = None) -> Problem:
    """Build and validate a problem from atoms given as tuples (generated problems, benchmarks).

    Raises :class:`~bt_meta.errors.TaskFileError` (without a position) naming the offending atom.
    """
    where = f"<problem {name}>"
    context = domain.context

    def check(atom: Sequence[str], what: str, allowed_derived: bool) -> Atom:
        atom_t = tuple(str(a) for a in atom)
        if not atom_t:
            raise TaskFileError(f"empty atom in the {what}", where)
        pred = atom_t[0]
        if pred in context.external or (pred in context.derived and not allowed_derived):
            raise TaskFileError(f"{pred} cannot appear in the {what}", where)
        arity = context.arities.get(pred)
        if arity is None:
            raise TaskFileError(f"unknown predicate {pred!r} in the {what}", where)
        if arity != len(atom_t) - 1:
            raise TaskFileError(f"predicate {pred} takes {arity} argument(s), got {len(atom_t) - 1} in the {what}",
                                where)
        return atom_t

    facts: list[Atom] = []
    for type_name, names in (objects or {}).items():
        if type_name not in domain.types:
            raise TaskFileError(f"unknown type {type_name!r} in the objects", where)
        for obj in names:
            cursor: str | None = type_name
            while cursor is not None:
                facts.append((cursor, str(obj)))
                cursor = domain.types.get(cursor)
    init_atoms = [check(a, "initial facts", False) for a in init]
    goal_atoms = [check(a, "goal", True) for a in goal]
    task_atoms: list[Atom] = []
    for task in tasks:
        task_t = tuple(str(a) for a in task)
        decl = domain.primitives.get(task_t[0]) or domain.tasks.get(task_t[0])
        if decl is None:
            raise TaskFileError(f"unknown task or primitive {task_t[0]!r} in the tasks", where)
        if len(decl.parameters) != len(task_t) - 1:
            raise TaskFileError(f"{task_t[0]} takes {len(decl.parameters)} argument(s), got {len(task_t) - 1}", where)
        task_atoms.append(task_t)
    return Problem(name, dict(objects or {}), init_atoms, task_atoms, goal_atoms, State([*facts, *init_atoms]))


def method_from_text(domain: Domain, *, name: str, task: str, precondition: str | Sequence[str] = "true",
                     subtasks: Sequence[str] = (), unordered: bool = False) -> Method:
    """Build and check a method written in the task-file syntax, e.g. a repaired plan saved as a refinement.

    Add it with :meth:`~bt_meta.htn.model.Domain.add_method`. Errors are :class:`TaskFileError` located at
    ``<method NAME>:1:column`` inside the offending string.
    """
    where = f"<method {name}>"
    loader = _Loader("", where, None)

    def src(text: str) -> Src:
        return Src(text, lambda off: (1, off + 1))

    head_src = src(task)
    head = loader.parse_atom(head_src)
    if head.pred not in domain.tasks:
        known = ", ".join(sorted(domain.tasks)) or "none declared"
        raise loader.error(f"unknown task {head.pred!r} in method {name} (declared tasks: {known})", (1, 1))
    loader.check_call(head, head_src, domain.primitives, domain.tasks, f"method {name}")
    if not isinstance(precondition, str):
        precondition = " and ".join(f"({part})" for part in precondition) or "true"
    condition = loader.compile(src(precondition), domain.context, {a.name for a in head.args if isinstance(a, Var)})
    templates: list[tuple] = []
    for text in subtasks:
        sub_src = src(text)
        atom = loader.parse_atom(sub_src)
        loader.check_call(atom, sub_src, domain.primitives, domain.tasks, f"the subtasks of method {name}")
        loader.check_bound(atom, condition.variables_bound, sub_src, f"subtask {atom.pred} of method {name}",
                           "the task head or the precondition")
        templates.append((atom.pred, *atom.args))
    return Method(name, head.pred, head.args, condition, templates, not unordered)
