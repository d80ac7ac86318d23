"""Safe parsing of BehaviorTree.CPP v4 XML into elements that remember their line and column.

The parser is expat with every DTD feature refused: a DOCTYPE, an entity declaration or an external entity is an
error, so entity-expansion bombs and external fetches cannot happen. No structure beyond XML well-formedness is
checked here except the shape of ``<root>`` (see :mod:`bt_meta.bt.xml.reader` for the tree semantics).

Offers:

* :class:`XMLElement` -- tag, attributes, child elements, 1-based line and column
* :class:`ModelEntry` -- one ``<TreeNodesModel>`` declaration (ID, category, ports)
* :class:`TreeDocument` -- the ``<BehaviorTree>`` elements by ID, ``main_tree_to_execute``, the node models
* :func:`parse_text`, :func:`parse_file` -- XML text or file -> :class:`TreeDocument` (raise ``TreeXMLError``)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from bt_meta.bt.registry import CATEGORIES, DIRECTIONS, PortSpec
from bt_meta.errors import TreeXMLError


@dataclass
class XMLElement:
    tag: str
    attrib: dict[str, str]
    line: int
    column: int
    children: list[XMLElement] = field(default_factory=list)


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

    def error(self, message: str, element: XMLElement | None = None) -> TreeXMLError:
        if element is None:
            return TreeXMLError(message, self.path)
        return TreeXMLError(message, self.path, element.line, element.column)


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

    def where() -> tuple[int, int]:
        return parser.CurrentLineNumber, parser.CurrentColumnNumber + 1

    def start(tag: str, attrib: dict[str, str]) -> None:
        line, column = where()
        element = XMLElement(tag, dict(attrib), line, column)
        if stack:
            stack[-1].children.append(element)
        else:
            top.append(element)
        stack.append(element)

    def end(tag: str) -> None:
        stack.pop()

    def refuse_doctype(*_args: object) -> None:
        raise _Refused("DOCTYPE declarations are not allowed in tree XML (no DTDs, no entities)", *where())

    def refuse_entity(*_args: object) -> None:
        raise _Refused("entity declarations are not allowed in tree XML (entity expansion is disabled)", *where())

    def refuse_external(*_args: object) -> int:
        raise _Refused("external entities are not allowed in tree XML", *where())

    parser.StartElementHandler = start
    parser.EndElementHandler = end
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
    return top[0]


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


def parse_text(text: str | bytes, path: str = "<string>") -> TreeDocument:
    """Parse XML text; checks ``<root>``, ``BTCPP_format``, ``<BehaviorTree ID>`` and ``<TreeNodesModel>``."""
    root = _parse_elements(text, path)
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
            raise TreeXMLError("<include> is not supported; put every tree in one file", path, child.line, child.column)
        else:
            raise TreeXMLError(
                f"unexpected <{child.tag}> under <root>; expected <BehaviorTree> or <TreeNodesModel>",
                path,
                child.line,
                child.column,
            )
    if not trees:
        raise TreeXMLError("no <BehaviorTree> in the document", path, root.line, root.column)
    main_tree = root.attrib.get("main_tree_to_execute")
    if main_tree is not None and main_tree not in trees:
        raise TreeXMLError(
            f"main_tree_to_execute={main_tree!r} names no <BehaviorTree>; trees: {', '.join(trees)}",
            path,
            root.line,
            root.column,
        )
    return TreeDocument(path, root, trees, main_tree, models)


def parse_file(path: str | Path) -> TreeDocument:
    from bt_meta.user_files import read_user_bytes  # regular files only, size-bounded, never blocks

    data = read_user_bytes(path, what="tree XML file", error=TreeXMLError)
    return parse_text(data, str(path))
