"""Safe parsing of BehaviorTree.CPP v4 XML into elements that remember their line and column.

The parser is expat with every DTD feature refused: a DOCTYPE, an entity declaration or an external entity is an
error, so entity-expansion bombs and external fetches cannot happen. What BehaviorTree.CPP's tinyxml2 accepts and a
strict parser does not -- an unescaped ``&&`` or ``<`` inside an attribute value, text such as ``// clang-format
off`` before or after the root element (:mod:`~bt_meta.bt.xml.around_root`) -- is accepted with a warning naming
its line (``TreeDocument.warnings``, also logged on ``bt_meta.xml``). Elements nest at most :data:`MAX_NESTING` deep.
No structure beyond XML well-formedness is checked here except the shape of ``<root>`` (see
:mod:`bt_meta.bt.xml.reader` for the tree semantics). Trees may span several files: ``<include path="x.xml"/>``
(relative to the including file, then :class:`TreeSources` ``include_path``), and extra files whose trees are
merged in; every element remembers its file, so errors name the right one.

Offers:

* :class:`XMLElement` -- tag, attributes, child elements, 1-based line and column
* :class:`ModelEntry` -- one ``<TreeNodesModel>`` declaration (ID, category, ports)
* :class:`TreeDocument` -- the ``<BehaviorTree>`` elements by ID, ``main_tree_to_execute``, the node models
* :class:`TreeSources` -- where trees of other files come from (``--include-path``, extra files or folders)
* :func:`parse_text`, :func:`parse_file` -- XML text or file -> :class:`TreeDocument` (raise ``TreeXMLError``)
* :func:`escape_attribute_values` -- the repair behind that leniency
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from bt_meta.bt.registry import CATEGORIES, DIRECTIONS, PortSpec
from bt_meta.bt.xml.around_root import DOCTYPE_REFUSED, blank_outside_root
from bt_meta.errors import TreeXMLError

# Deeper element nesting is refused while parsing: every later stage (resolving, building, ticking) recurses over
# the tree, and real trees are a few dozen levels deep.
MAX_NESTING = 256
_LOG = logging.getLogger("bt_meta.xml")


@dataclass
class XMLElement:
    tag: str
    attrib: dict[str, str]
    line: int
    column: int
    children: list[XMLElement] = field(default_factory=list)
    path: str | None = None  # the file it came from, when the document spans several


@dataclass
class ModelEntry:
    id: str
    category: str
    ports: list[PortSpec]
    line: int
    description: str = ""


@dataclass
class TreeDocument:
    path: str
    root: XMLElement
    trees: dict[str, XMLElement]
    main_tree: str | None
    models: dict[str, ModelEntry]
    # "path:line:column: message" for XML that was accepted although it is not well formed
    warnings: list[str] = field(default_factory=list)
    # every file whose trees are in this document (included or given on the command line)
    files: list[str] = field(default_factory=list)

    def error(self, message: str, element: XMLElement | None = None) -> TreeXMLError:
        if element is None:
            return TreeXMLError(message, self.path)
        return TreeXMLError(message, element.path or self.path, element.line, element.column)


class _Refused(Exception):
    def __init__(self, message: str, line: int, column: int) -> None:
        super().__init__(message)
        self.message = message
        self.line = line
        self.column = column


def _parse_elements(text: str | bytes, path: str) -> XMLElement:
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[XMLElement] = []
    top: list[XMLElement] = []
    # tinyxml2 reads processing instructions as declarations: only before any comment or element.
    started = [False]

    def where() -> tuple[int, int]:
        return parser.CurrentLineNumber, parser.CurrentColumnNumber + 1

    def start(tag: str, attrib: dict[str, str]) -> None:
        line, column = where()
        if len(stack) >= MAX_NESTING:
            raise _Refused(f"elements nested deeper than {MAX_NESTING} levels", line, column)
        started[0] = True
        element = XMLElement(tag, dict(attrib), line, column)
        if stack:
            stack[-1].children.append(element)
        else:
            top.append(element)
        stack.append(element)

    def end(tag: str) -> None:
        stack.pop()

    def comment(_data: str) -> None:
        started[0] = True

    def instruction(target: str, _data: str) -> None:
        if started[0]:
            raise _Refused(f"processing instruction <?{target} ...?> after a comment or an element (BehaviorTree.CPP "
                           "accepts them only at the start of the file)", *where())

    def refuse_doctype(*_args: object) -> None:
        raise _Refused(DOCTYPE_REFUSED, *where())

    def refuse_entity(*_args: object) -> None:
        raise _Refused("entity declarations are not allowed in tree XML (entity expansion is disabled)", *where())

    def refuse_external(*_args: object) -> int:
        raise _Refused("external entities are not allowed in tree XML", *where())

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CommentHandler = comment
    parser.ProcessingInstructionHandler = instruction
    parser.StartDoctypeDeclHandler = refuse_doctype
    parser.EntityDeclHandler = refuse_entity
    parser.UnparsedEntityDeclHandler = refuse_entity
    parser.ExternalEntityRefHandler = refuse_external
    try:
        parser.Parse(text, True)
    except _Refused as refused:
        raise TreeXMLError(refused.message, path, refused.line, refused.column) from None
    except expat.ExpatError as error:
        message = expat.ErrorString(error.code) if error.code is not None else str(error)
        raise TreeXMLError(f"malformed XML: {message}", path, error.lineno, error.offset + 1) from None
    except (LookupError, ValueError) as error:
        # expat asks Python for an encoding it does not know itself; an unknown name ends up here.
        raise TreeXMLError(f"malformed XML: unsupported encoding ({error})", path, 1, 1) from None
    if not top:
        raise TreeXMLError("malformed XML: no element found", path, 1, 1)
    return top[0]


# Anything shaped like an entity reference is left to expat (an undefined one stays an error); only a bare '&', as
# in "a && b", is escaped.
_ENTITY = re.compile(r"&(?:[A-Za-z_:][\w.:-]*|#[0-9]+|#x[0-9a-fA-F]+);")


def escape_attribute_values(text: str) -> tuple[str, list[tuple[int, int, str]]]:
    """Escape what BT.CPP's tinyxml2 accepts unescaped inside attribute values (``&&``, ``<``): returns the fixed
    text and, per fix, the 1-based line and column of the character and what it was."""
    out: list[str] = []
    fixes: list[tuple[int, int, str]] = []
    index, size, line, line_start = 0, len(text), 1, 0
    quote = ""
    in_tag = False
    while index < size:
        char = text[index]
        if char == "\n":
            line, line_start = line + 1, index + 1
        if not in_tag:
            for opening, closing in (("<!--", "-->"), ("<![CDATA[", "]]>"), ("<?", "?>")):
                if text.startswith(opening, index):
                    end = text.find(closing, index)
                    end = size if end < 0 else end + len(closing)
                    chunk = text[index:end]
                    line += chunk.count("\n")
                    if "\n" in chunk:
                        line_start = index + chunk.rindex("\n") + 1
                    out.append(chunk)
                    index = end
                    break
            else:
                in_tag = char == "<"
                out.append(char)
                index += 1
            continue
        if quote:
            if char == quote:
                quote = ""
            elif char == "<":
                fixes.append((line, index - line_start + 1, "<"))
                out.append("&lt;")
                index += 1
                continue
            elif char == "&" and not _ENTITY.match(text, index):
                fixes.append((line, index - line_start + 1, "&"))
                out.append("&amp;")
                index += 1
                continue
        elif char in "\"'":
            quote = char
        elif char == ">":
            in_tag = False
        out.append(char)
        index += 1
    return "".join(out), fixes


def _well_formed(text: str, path: str) -> bool:
    try:
        _parse_elements(escape_attribute_values(text)[0], path)
    except TreeXMLError:
        return False
    return True


def _parse_lenient(text: str | bytes, path: str) -> tuple[XMLElement, list[str]]:
    """Parse strictly; if that fails, accept what tinyxml2 accepts -- text and more around the root element
    (:mod:`~bt_meta.bt.xml.around_root`), unescaped ``&`` / ``<`` in attribute values -- and say so in warnings.
    Anything else keeps the strict parser's error (or, once the text around the root was blanked, the error
    inside the root, at the same line and column)."""
    try:
        return _parse_elements(text, path), []
    except TreeXMLError as strict:
        try:
            decoded = text.decode("utf-8") if isinstance(text, bytes) else text
        except UnicodeDecodeError:
            raise strict from None
        error = strict
        warnings: list[str] = []
        outside = blank_outside_root(decoded, path, lambda fragment: _well_formed(fragment, path))
        if outside is not None:
            decoded, warnings = outside
            try:
                element = _parse_elements(decoded, path)
            except TreeXMLError as inside:
                error = inside
            else:
                return element, _logged(warnings)
        fixed, fixes = escape_attribute_values(decoded)
        if not fixes:
            raise error from None
        try:
            element = _parse_elements(fixed, path)
        except TreeXMLError:
            raise error from None
        warnings += [
            f"{path}:{line}:{column}: warning: unescaped {char!r} in an attribute value (BehaviorTree.CPP accepts "
            f"it; write {'&amp;' if char == '&' else '&lt;'} to make the XML well formed)"
            for line, column, char in fixes
        ]
        return element, _logged(warnings)


def _logged(warnings: list[str]) -> list[str]:
    for warning in warnings:
        _LOG.warning(warning)
    return warnings


def _parse_model(element: XMLElement, doc_path: str) -> list[ModelEntry]:
    entries: list[ModelEntry] = []
    for child in element.children:
        if child.tag not in CATEGORIES:
            raise TreeXMLError(
                f"<TreeNodesModel> entries must be one of {', '.join(CATEGORIES)}, got <{child.tag}>",
                doc_path,
                child.line,
                child.column,
            )
        node_id = child.attrib.get("ID")
        if not node_id:
            raise TreeXMLError(f"<{child.tag}> in <TreeNodesModel> needs an ID", doc_path, child.line, child.column)
        ports: list[PortSpec] = []
        description = ""
        declared: dict[str, int] = {}
        for port in child.children:
            if port.tag == "MetadataFields":
                continue
            direction = port.tag.removesuffix("_port")
            if not port.tag.endswith("_port") or direction not in DIRECTIONS:
                raise TreeXMLError(
                    f"<{port.tag}> in the model of {node_id!r}: expected input_port, output_port or inout_port",
                    doc_path,
                    port.line,
                    port.column,
                )
            name = port.attrib.get("name")
            if not name:
                raise TreeXMLError(f"<{port.tag}> of {node_id!r} needs a name", doc_path, port.line, port.column)
            if name in declared:
                raise TreeXMLError(
                    f"port {name!r} of {node_id!r} is declared twice (first on line {declared[name]})",
                    doc_path,
                    port.line,
                    port.column,
                )
            declared[name] = port.line
            ports.append(
                PortSpec(
                    name,
                    direction,  # type: ignore[arg-type]
                    port.attrib.get("type", "std::string"),
                    port.attrib.get("default"),
                    "",
                )
            )
        entries.append(ModelEntry(node_id, child.tag, ports, child.line, description))
    return entries


@dataclass(frozen=True)
class TreeSources:
    """Where trees of other files come from: ``include_path`` is searched for an ``<include path>`` that is not found
    next to the including file; every XML file in ``extra`` (files, or folders of ``*.xml``) adds its trees and
    models, as BT.CPP's ``registerBehaviorTreeFromFile`` does."""

    include_path: tuple[Path, ...] = ()
    extra: tuple[Path, ...] = ()


# An <include> chain longer than this is refused (a cycle is refused at once and named).
MAX_INCLUDE_DEPTH = 32


def _parse_one(text: str | bytes, path: str) -> tuple[TreeDocument, list[XMLElement]]:
    """One file's document and its ``<include>`` elements; nothing checked across files yet."""
    root, warnings = _parse_lenient(text, path)
    if root.tag != "root":
        raise TreeXMLError(f"the top element must be <root>, got <{root.tag}>", path, root.line, root.column)
    fmt = root.attrib.get("BTCPP_format")
    if fmt is not None and fmt.strip() != "4":
        raise TreeXMLError(
            f'BTCPP_format="{fmt}" is not supported; bt-meta reads BehaviorTree.CPP v4 XML (BTCPP_format="4")',
            path,
            root.line,
            root.column,
        )
    trees: dict[str, XMLElement] = {}
    models: dict[str, ModelEntry] = {}
    includes: list[XMLElement] = []
    behavior_trees = [c for c in root.children if c.tag == "BehaviorTree"]
    for child in root.children:
        if child.tag == "BehaviorTree":
            tree_id = child.attrib.get("ID")
            if not tree_id:
                if len(behavior_trees) > 1:
                    raise TreeXMLError("<BehaviorTree> needs an ID attribute", path, child.line, child.column)
                tree_id = "MainTree"
            if tree_id in trees:
                raise TreeXMLError(f"a <BehaviorTree ID={tree_id!r}> is defined twice", path, child.line, child.column)
            if len(child.children) != 1:
                raise TreeXMLError(
                    f"<BehaviorTree ID={tree_id!r}> must have exactly one child node, got {len(child.children)}",
                    path,
                    child.line,
                    child.column,
                )
            trees[tree_id] = child
        elif child.tag == "TreeNodesModel":
            for entry in _parse_model(child, path):
                models[entry.id] = entry
        elif child.tag == "include":
            if not child.attrib.get("path"):
                raise TreeXMLError('<include> needs a path="..." attribute', path, child.line, child.column)
            if "ros_pkg" in child.attrib:
                raise TreeXMLError("<include ros_pkg> needs ROS; give the path, or --include-path", path,
                                   child.line, child.column)
            includes.append(child)
        else:
            raise TreeXMLError(
                f"unexpected <{child.tag}> under <root>; expected <BehaviorTree>, <TreeNodesModel> or <include>",
                path,
                child.line,
                child.column,
            )
    _tag_path(root, path)
    return TreeDocument(path, root, trees, root.attrib.get("main_tree_to_execute"), models, warnings), includes


def _tag_path(root: XMLElement, path: str) -> None:
    """Remember on every element the file it came from (trees of several files end up in one document)."""
    stack = [root]
    while stack:
        element = stack.pop()
        element.path = path
        stack.extend(element.children)


def _merge(into: TreeDocument, other: TreeDocument) -> None:
    for tree_id, element in other.trees.items():
        if tree_id in into.trees:
            first = into.trees[tree_id]
            raise TreeXMLError(
                f"a <BehaviorTree ID={tree_id!r}> is already defined in {first.path or into.path}:{first.line}",
                other.path,
                element.line,
                element.column,
            )
        into.trees[tree_id] = element
    for model_id, entry in other.models.items():
        into.models.setdefault(model_id, entry)
    into.warnings.extend(other.warnings)
    into.files.extend(f for f in other.files if f not in into.files)


# Tree XML files larger than this are refused before reading (real trees are a few hundred KB at most).
MAX_FILE_BYTES = 16 * 1024 * 1024


def _read(path: Path) -> bytes:
    """The one place tree XML files are read (the main file, includes, extra files): regular files only, bounded,
    never blocking on a pipe or a device (:func:`bt_meta.user_files.read_user_bytes`)."""
    from bt_meta.user_files import read_user_bytes

    return read_user_bytes(path, what="tree XML file", max_bytes=MAX_FILE_BYTES, error=TreeXMLError)


def _resolve_includes(
    document: TreeDocument, includes: list[XMLElement], base: Path, sources: TreeSources, stack: tuple[Path, ...]
) -> None:
    for element in includes:
        name = element.attrib["path"].strip()
        candidates = [base / name] + [Path(folder) / name for folder in sources.include_path]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            searched = ", ".join(str(c.parent) for c in candidates)
            raise document.error(f"<include path={name!r}>: no such file (searched {searched})", element)
        resolved = found.resolve()
        if resolved in stack:
            chain = " -> ".join(str(p) for p in (*stack[stack.index(resolved):], resolved))
            raise document.error(f"<include> cycle: {chain}", element)
        if len(stack) >= MAX_INCLUDE_DEPTH:
            raise document.error(f"<include> nested deeper than {MAX_INCLUDE_DEPTH} files", element)
        included, nested = _parse_one(_read(found), str(found))
        included.files.append(str(found))
        _resolve_includes(included, nested, found.parent, sources, (*stack, resolved))
        _merge(document, included)


def _extra_files(sources: TreeSources) -> list[Path]:
    files: list[Path] = []
    for item in sources.extra:
        item = Path(item)
        if item.is_dir():
            files.extend(sorted(p for p in item.glob("*.xml") if p.is_file()))
        elif item.is_file():
            files.append(item)
        else:
            raise TreeXMLError("no such file or folder of tree XML", str(item))
    return files


def _finish(document: TreeDocument) -> TreeDocument:
    path, root = document.path, document.root
    if not document.trees:
        raise TreeXMLError("no <BehaviorTree> in the document", path, root.line, root.column)
    main_tree = document.main_tree
    if main_tree is not None and main_tree not in document.trees:
        raise TreeXMLError(
            f"main_tree_to_execute={main_tree!r} names no <BehaviorTree>; trees: {', '.join(document.trees)}",
            path,
            root.line,
            root.column,
        )
    return document


def _parse_with_sources(
    text: str | bytes, path: str, base: Path, sources: TreeSources | None, own: Path | None
) -> TreeDocument:
    sources = sources or TreeSources()
    document, includes = _parse_one(text, path)
    stack = (own.resolve(),) if own is not None else ()
    _resolve_includes(document, includes, base, sources, stack)
    seen = {p for p in stack}
    for extra in _extra_files(sources):
        if extra.resolve() in seen:
            continue
        seen.add(extra.resolve())
        other, nested = _parse_one(_read(extra), str(extra))
        other.files.append(str(extra))
        _resolve_includes(other, nested, extra.parent, sources, (extra.resolve(),))
        _merge(document, other)
    return _finish(document)


def parse_text(text: str | bytes, path: str = "<string>", sources: TreeSources | None = None) -> TreeDocument:
    """Parse XML text; checks ``<root>``, ``BTCPP_format``, ``<BehaviorTree ID>`` and ``<TreeNodesModel>``;
    ``<include path>`` is relative to the current folder (to the file's folder for :func:`parse_file`)."""
    return _parse_with_sources(text, path, Path.cwd(), sources, None)


def parse_file(path: str | Path, sources: TreeSources | None = None) -> TreeDocument:
    path = Path(path)
    document = _parse_with_sources(_read(path), str(path), path.parent, sources, path)
    document.files.insert(0, str(path))
    return document
