"""Tokens of BehaviorTree.CPP 4's script language.

Offers:

* :class:`Token` -- kind, text, start offset, and whether whitespace preceded it
* :func:`tokenize` -- script text -> tokens (raises :class:`~bt_meta.bt.script.errors.ScriptSyntaxError`)

Numbers are lexed without a sign: whether ``-3`` is the literal -3 or the operator ``-`` applied to 3 depends on
where it stands, which the parser decides (BT.CPP's grammar does the same). ``true``/``false`` are matched as a
prefix, without a word boundary, exactly as BT.CPP's literal rule does (so ``trueish`` does not lex as one name).
"""

from __future__ import annotations

from dataclasses import dataclass

from bt_meta.bt.script.errors import ScriptSyntaxError

# Longest first: the lexer takes the longest operator that matches.
OPERATORS = (
    ":=", "+=", "-=", "*=", "/=", "==", "!=", "<=", ">=", "&&", "||", "..",
    "=", "<", ">", "+", "-", "*", "/", "&", "|", "^", "~", "!", "?", ":", "(", ")", ";",
)  # fmt: skip


@dataclass(frozen=True)
class Token:
    kind: str  # "name", "int", "real", "string", "bool", "op", "end"
    text: str
    start: int
    spaced: bool  # whitespace (or the start of the script) right before it
    value: object = None


def _is_name_start(char: str) -> bool:
    if char.isascii():
        return char in "_@" or char.isalpha()
    return char.isidentifier()


def _is_name_continue(char: str) -> bool:
    return char == "_" or char.isdigit() or ("a" + char).isidentifier()


def _number(text: str, start: int) -> tuple[Token, int]:
    """An unsigned integer, hex integer or real starting at ``start``; BT.CPP refuses a letter or '.' right after."""
    end = start
    size = len(text)
    if text.startswith(("0x", "0X"), start):
        end = start + 2
        while end < size and text[end] in "0123456789abcdefABCDEF":
            end += 1
        if end == start + 2:
            raise ScriptSyntaxError("expected hexadecimal digits after 0x", start)
        token = Token("int", text[start:end], start, False, int(text[start + 2 : end], 16))
    else:
        while end < size and text[end].isdigit():
            end += 1
        real = False
        if end + 1 < size and text[end] == "." and text[end + 1].isdigit():
            real = True
            end += 1
            while end < size and text[end].isdigit():
                end += 1
        if end < size and text[end] in "eE":
            probe = end + 1
            if probe < size and text[probe] in "+-":
                probe += 1
            if probe < size and text[probe].isdigit():
                real = True
                end = probe
                while end < size and text[end].isdigit():
                    end += 1
        literal = text[start:end]
        if real:
            token = Token("real", literal, start, False, float(literal))
        else:
            token = Token("int", literal, start, False, int(literal, 10))
    if end < size and (text[end] == "." or text[end].isalpha() or text[end] == "_"):
        raise ScriptSyntaxError(f"invalid suffix on number literal {text[start:end + 1]!r}", end)
    if token.kind == "int" and not -(2**63) <= token.value <= 2**63 - 1:  # type: ignore[operator]
        raise ScriptSyntaxError(f"integer literal {token.text} does not fit in 64 bits", start)
    return token, end


def tokenize(text: str) -> list[Token]:
    tokens: list[Token] = []
    index = 0
    size = len(text)
    spaced = True
    while index < size:
        char = text[index]
        if char in " \t\r\n\f\v":
            index += 1
            spaced = True
            continue
        if char == "\\" and index + 1 < size and text[index + 1] in "\r\n":
            index += 2
            spaced = True
            continue
        start = index
        if char in "'\"":
            end = text.find(char, index + 1)
            if end < 0:
                raise ScriptSyntaxError("unterminated string literal", start)
            body = text[index + 1 : end]
            if not body.isascii():
                raise ScriptSyntaxError("string literals may only hold ASCII characters", start)
            tokens.append(Token("string", text[start : end + 1], start, spaced, body))
            index = end + 1
        elif char.isdigit():
            token, index = _number(text, start)
            tokens.append(Token(token.kind, token.text, start, spaced, token.value))
        elif text.startswith("true", index) or text.startswith("false", index):
            word = "true" if text.startswith("true", index) else "false"
            tokens.append(Token("bool", word, start, spaced, 1 if word == "true" else 0))
            index += len(word)
        elif _is_name_start(char):
            index += 1
            while index < size and _is_name_continue(text[index]):
                index += 1
            tokens.append(Token("name", text[start:index], start, spaced))
        else:
            for op in OPERATORS:
                if text.startswith(op, index):
                    tokens.append(Token("op", op, start, spaced))
                    index += len(op)
                    break
            else:
                raise ScriptSyntaxError(f"unexpected character {char!r}", start)
        spaced = False
    tokens.append(Token("end", "", size, spaced))
    return tokens
