"""What BehaviorTree.CPP's parser (tinyxml2) accepts outside the root element, made readable by a strict parser.

tinyxml2 reads a document as a flat list of nodes, and BehaviorTree.CPP uses only the first element. Text there
(``// clang-format off`` before ``<root>``) is a text node; a CDATA section too; after the root, further elements
are read and ignored, and an end tag with no element open ends the reading (the rest of the file is never looked
at). BehaviorTree.CPP then prints the document and parses it again (``VerifyXML``), so text must be followed by some
markup. XML declarations and processing instructions are accepted only before anything else; whitespace before the
XML declaration is skipped. Everything else (unterminated comments, text with nothing after it) is an error there
too, and stays the strict parser's error here. A DOCTYPE, which tinyxml2 skips, stays refused: bt-meta reads no DTD.

This module blanks what tinyxml2 skips -- each character becomes a space, line breaks stay, so every line and
column the strict parser reports afterwards is the file's own -- and says where, one warning each.

Offers:

* :func:`blank_outside_root` -- XML text -> (text a strict parser reads, warnings), or ``None`` when tinyxml2
  would refuse the text around the root too (or there is nothing to blank)
* :func:`element_end` -- where an element ends, by balancing its tags
* :data:`DOCTYPE_REFUSED` -- the error for a DOCTYPE
"""

from __future__ import annotations

import re
from collections.abc import Callable

from bt_meta.errors import TreeXMLError

DOCTYPE_REFUSED = "DOCTYPE declarations are not allowed in tree XML (no DTDs, no entities)"
_SPACE = " \t\r\n"
_NOT_LINE_BREAK = re.compile(r"[^\r\n]")
_END_TAG = re.compile(r"</([^\s/>]+)[^>]*>")
_NAME = re.compile(r"<([^\s/>]+)")
_XML_DECLARATION = re.compile(r"<\?xml[\s?]")


class _Lines:
    """1-based line and column of increasing indexes, counted once over the text."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.index, self.line, self.line_start = 0, 1, 0

    def __call__(self, index: int) -> tuple[int, int]:
        self.line += self.text.count("\n", self.index, index)
        self.line_start = max(self.line_start, self.text.rfind("\n", self.index, index) + 1)
        self.index = index
        return self.line, index - self.line_start + 1


def _tag_end(text: str, index: int) -> int | None:
    """The index after the ``>`` closing the tag that starts at ``index`` (quoted attribute values skipped)."""
    quote = ""
    for position in range(index + 1, len(text)):
        char = text[position]
        if quote:
            if char == quote:
                quote = ""
        elif char in "\"'":
            quote = char
        elif char == ">":
            return position + 1
    return None


def element_end(text: str, index: int) -> int | None:
    """The index after the element that starts at ``index``, found by balancing its tags (``None``: unclosed)."""
    depth = 0
    position = index
    size = len(text)
    while position < size:
        if text[position] != "<":
            position = text.find("<", position)
            if position < 0:
                return None
            continue
        for opening, closing in (("<!--", "-->"), ("<![CDATA[", "]]>"), ("<?", "?>"), ("<!", ">")):
            if text.startswith(opening, position):
                end = text.find(closing, position + len(opening))
                if end < 0:
                    return None
                position = end + len(closing)
                break
        else:
            end = _tag_end(text, position)
            if end is None:
                return None
            if text.startswith("</", position):
                depth -= 1
            elif text[end - 2] != "/":
                depth += 1
            position = end
            if depth <= 0:
                return position
    return None


def _blank(text: str, ranges: list[tuple[int, int]]) -> str:
    pieces: list[str] = []
    done = 0
    for start, end in ranges:
        pieces.append(text[done:start])
        pieces.append(_NOT_LINE_BREAK.sub(" ", text[start:end]))
        done = end
    pieces.append(text[done:])
    return "".join(pieces)


def blank_outside_root(text: str, path: str, well_formed: Callable[[str], bool]) -> tuple[str, list[str]] | None:
    """Blank what tinyxml2 reads and BehaviorTree.CPP ignores around the root element (see the module docstring).

    ``well_formed(element_text) -> bool`` checks an element found after the root (tinyxml2 parses it, so it must
    be well formed). Raises :class:`TreeXMLError` for an XML declaration after other content, which tinyxml2 refuses.
    """
    ranges: list[tuple[int, int]] = []
    warnings: list[str] = []
    line_of = _Lines(text)

    def note(start: int, end: int, what: str) -> None:
        line, column = line_of(start)
        ranges.append((start, end))
        warnings.append(f"{path}:{line}:{column}: warning: {what}")

    start = 1 if text.startswith("\ufeff") else 0
    position, size = start, len(text)
    root: tuple[int, int] | None = None
    only_declarations = True  # tinyxml2 accepts declarations only before every other node
    declarations = 0
    after_text = False  # the last node read was text (BehaviorTree.CPP's second parse needs markup after text)
    while True:
        while position < size and text[position] in _SPACE:
            position += 1
        if position >= size:
            break
        where = "before" if root is None else "after"
        if text.startswith("<?", position):
            end = text.find("?>", position + 2)
            if end < 0:
                return None
            if not only_declarations:
                if _XML_DECLARATION.match(text, position):
                    line, column = line_of(position)
                    raise TreeXMLError("the XML declaration must come first in the file (BehaviorTree.CPP refuses "
                                       "it after other content too)", path, line, column)
                return None
            if position > start and _XML_DECLARATION.match(text, position):
                what = "a second XML declaration" if declarations else "whitespace before the XML declaration"
                note(position, end + 2, f"{what} (BehaviorTree.CPP accepts it; the declaration is ignored and the "
                                        "file read as UTF-8)")
            position, after_text, declarations = end + 2, False, declarations + 1
            continue
        only_declarations = False
        if text.startswith("<!--", position):
            end = text.find("-->", position + 4)
            if end < 0:
                return None
            position, after_text = end + 3, False
        elif text.startswith("<![CDATA[", position):
            end = text.find("]]>", position + 9)
            if end < 0:
                return None
            note(position, end + 3, f"CDATA section {where} the root element (BehaviorTree.CPP ignores it)")
            position, after_text = end + 3, False
        elif text.startswith("<!", position):
            line, column = line_of(position)  # BehaviorTree.CPP skips a DOCTYPE; bt-meta reads no DTD
            raise TreeXMLError(DOCTYPE_REFUSED, path, line, column)
        elif text.startswith("</", position):
            match = _END_TAG.match(text, position)
            if root is None or match is None or after_text:
                return None
            note(position, size, f"end tag </{match.group(1)}> after the root element: BehaviorTree.CPP stops "
                                 "reading there and ignores the rest of the file")
            break
        elif text[position] == "<":
            end = element_end(text, position)
            if end is None:
                return None
            if root is None:
                root = (position, end)
            else:
                if not well_formed(text[position:end]):
                    return None
                name = _NAME.match(text, position)
                tag = name.group(1) if name else "?"
                note(position, end, f"element <{tag}> after the root element (BehaviorTree.CPP reads only the "
                                    "first element and ignores it)")
            position, after_text = end, False
        else:
            end = text.find("<", position)
            if end < 0:
                return None  # text that ends the file: BehaviorTree.CPP refuses it
            note(position, end, f"text {where} the root element (BehaviorTree.CPP ignores it)")
            position, after_text = end, True
    if root is None or not ranges:
        return None
    return _blank(text, ranges), warnings
