"""``bt-meta show tree.xml [--tree ID]``: print a BehaviorTree.CPP v4 XML tree as a unicode tree with its ports.

SubTrees are expanded under their ``SubTree`` line. Custom nodes only need a ``<TreeNodesModel>`` entry (no plugin):
the file is validated exactly as the loader would, except that nothing is instantiated. A file that does not load
exits 2 with one ``path:line:column: message`` line.
"""

from __future__ import annotations

import argparse

from bt_meta.bt.registry import default_registry
from bt_meta.bt.xml.document import parse_file
from bt_meta.bt.xml.reader import ResolvedNode, resolve_document, select_tree


def _label(node: ResolvedNode) -> str:
    parts = [f"SubTree {node.subtree_id}"] if node.subtree_id is not None else [node.node_type.id]
    if node.name != node.id:
        parts.append(f'"{node.name}"')
    parts.extend(f'{port}="{value}"' for port, value in node.ports.items())
    if node.category == "Action" and not node.node_type.builtin and not node.monitor:
        parts.append("[no monitor]")
    return " ".join(parts)


def render(node: ResolvedNode) -> list[str]:
    """The lines of ``node`` drawn with box-drawing characters."""
    lines = [_label(node)]

    def walk(children: list[ResolvedNode], prefix: str) -> None:
        for index, child in enumerate(children):
            last = index == len(children) - 1
            lines.append(prefix + ("└── " if last else "├── ") + _label(child))
            walk(child.children, prefix + ("    " if last else "│   "))

    walk(node.children, "")
    return lines


def run(args: argparse.Namespace) -> int:
    document = parse_file(args.file)
    tree_id = select_tree(document, args.tree)
    root = resolve_document(document, default_registry(), tree_id=tree_id, allow_models=True)
    print(f"{tree_id} ({args.file})")
    for line in render(root):
        print(line)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("show", help="print a BehaviorTree.CPP XML tree as a unicode tree")
    parser.add_argument("file", help="BehaviorTree.CPP v4 XML file")
    parser.add_argument("--tree", metavar="ID", help="the <BehaviorTree ID> to show (default: main_tree_to_execute)")
    parser.set_defaults(func=run)
