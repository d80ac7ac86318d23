"""Reading HDDL text into located S-expressions, the first stage of the HDDL importer.

Offers:

* :class:`Sym` -- a symbol (name, ``?variable``, ``:keyword``, ``-``, ``<``, ``=``) with its line and column
* :class:`SList` -- a parenthesised list with the position of its ``(``
* :class:`HddlError` -- a :class:`~bt_meta.errors.TaskFileError` for HDDL input, ``path:line:column: message``
* :func:`read_sexprs` -- text to the top-level S-expressions, comments (``;`` to end of line) skipped

HDDL (like PDDL) is case-insensitive; symbols keep their spelling as written and offer :attr:`Sym.key`
(case-folded) for comparisons, so the importer can keep every name as the author wrote it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from bt_meta.errors import TaskFileError


class HddlError(TaskFileError):
    """An HDDL domain or problem that does not parse or cannot be imported."""


@dataclass(frozen=True)
class Sym:
    text: str
    line: int
    column: int

    @property
    def key(self) -> str:
        return self.text.casefold()

    @property
    def is_var(self) -> bool:
        return self.text.startswith("?")


@dataclass
class SList:
    items: list[SList | Sym] = field(default_factory=list)
    line: int = 0
    column: int = 0

    def head(self) -> str | None:
        """The case-folded first symbol, or None when the list is empty or starts with a list."""
        if self.items and isinstance(self.items[0], Sym):
            return self.items[0].key
        return None


SExpr = SList | Sym

_TOKEN = re.compile(r"[()]|;[^\n]*|[^\s();]+")


def read_sexprs(text: str, path: str) -> list[SExpr]:
    """Parse ``text`` into its top-level S-expressions; unbalanced parentheses are located errors."""
    top: list[SExpr] = []
    stack: list[SList] = []
    line, line_start = 1, 0  # the current line and the offset where it starts
    newline = text.find("\n")
    for match in _TOKEN.finditer(text):
        start = match.start()
        while 0 <= newline < start:
            line, line_start = line + 1, newline + 1
            newline = text.find("\n", line_start)
        token = match.group()
        column = start - line_start + 1
        if token == "(":
            stack.append(SList([], line, column))
        elif token == ")":
            if not stack:
                raise HddlError("unbalanced ')': no '(' is open here", path, line, column)
            done = stack.pop()
            (stack[-1].items if stack else top).append(done)
        elif token[0] != ";":
            (stack[-1].items if stack else top).append(Sym(token, line, column))
    if stack:
        opened = stack[-1]
        raise HddlError(f"'(' opened at line {opened.line}, column {opened.column} is never closed",
                        path, opened.line, opened.column)
    return top
