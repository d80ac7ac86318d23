"""``bt-meta show tree.xml [--tree ID] [--include-path DIR] [--subtrees PATH] [--stub-unknown] [--plugins DIR]
[--ros2-leaves FILE.yaml]``:
print a BehaviorTree.CPP v4 XML tree as a unicode tree with its ports.

SubTrees are expanded under their ``SubTree`` line, whichever file defines them. Custom nodes only need a
``<TreeNodesModel>`` entry, or a plugin (``--plugins``) that registers them: the file is validated exactly as the
loader would, except that nothing is instantiated; ``--stub-unknown`` also accepts nodes declared nowhere. A file
that does not load exits 2 with one ``path:line:column: message`` line.
"""

from __future__ import annotations

import argparse

from bt_meta.bt.registry import default_registry
from bt_meta.bt.xml.document import parse_file
from bt_meta.bt.xml.reader import ResolvedNode, resolve_document, select_tree
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.commands._tree_args import (
    add_tree_arguments,
    ros2_leaves_from_args,
    stubs_from_args,
    tree_sources_from_args,
)


def _label(node: ResolvedNode) -> str:
    parts = [f"SubTree {node.subtree_id}"] if node.subtree_id is not None else [node.node_type.id]
    if node.name != node.id:
        parts.append(f'"{node.name}"')
    parts.extend(f'{port}="{value}"' for port, value in node.ports.items())
    parts.extend(f'{name}="{script.source}"' for name, script in node.conditions.items())
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
    from bt_meta.bt.domain_nodes import domain_registry

    document = parse_file(args.file, tree_sources_from_args(args))
    tree_id = select_tree(document, args.tree)
    registry = default_registry()
    if args.plugins:
        registry = domain_registry(None, plugin_host_from_args(args, args.file))
    for node_type in ros2_leaves_from_args(args):
        registry.register(node_type, replace=True)
    root = resolve_document(document, registry, tree_id=tree_id, allow_models=True, stubs=stubs_from_args(args))
    print(f"{tree_id} ({args.file})")
    for line in render(root):
        print(line)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("show", help="print a BehaviorTree.CPP XML tree as a unicode tree")
    parser.add_argument("file", help="BehaviorTree.CPP v4 XML file")
    add_tree_arguments(parser)
    add_plugin_arguments(parser)
    parser.set_defaults(func=run)
