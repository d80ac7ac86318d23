"""Command-line options shared by the commands that read tree XML: which tree, where other trees come from, stubs.

``--tree ID`` picks a ``<BehaviorTree>``; ``--include-path DIR`` is searched for ``<include path>`` files that are
not next to the including file; ``--subtrees PATH`` adds the trees of a file or of every ``*.xml`` in a folder;
``--stub-unknown`` stands a stub in for every node no plugin implements, ``--stub ID=STATUS,...`` scripts it;
``--ros2-leaves FILE.yaml`` registers the ROS leaves a ``ros2_leaves:`` file declares (docs/ros2.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_tree_arguments(parser: argparse.ArgumentParser, *, stubs: bool = True) -> None:
    parser.add_argument("--tree", metavar="ID", help="the <BehaviorTree ID> to use (default: main_tree_to_execute)")
    parser.add_argument("--include-path", action="append", default=[], metavar="DIR",
                        help="search DIR for <include path=...> files (repeatable)")
    parser.add_argument("--subtrees", action="append", default=[], metavar="PATH",
                        help="also read the trees of this XML file, or of every *.xml in this folder (repeatable)")
    parser.add_argument("--ros2-leaves", action="append", default=[], metavar="FILE.yaml",
                        help="register the ROS 2 action, service and topic leaves this ros2_leaves: file declares "
                             "(repeatable; needs pip install 'bt-meta[ros2]', docs/ros2.md)")
    if stubs:
        parser.add_argument("--stub-unknown", action="store_true",
                            help="stub every node that is only declared in <TreeNodesModel> (or not at all)")
        parser.add_argument("--stub", action="append", default=[], metavar="ID=STATUS[,STATUS...]",
                            help="what a stubbed node returns, tick after tick (default SUCCESS; repeatable)")


def tree_sources_from_args(args: argparse.Namespace) -> Any:
    from bt_meta.bt.xml.document import TreeSources

    return TreeSources(tuple(Path(p) for p in args.include_path), tuple(Path(p) for p in args.subtrees))


def stubs_from_args(args: argparse.Namespace) -> Any:
    from bt_meta.bt.nodes.stubs import StubPolicy
    from bt_meta.errors import UserInputError

    if getattr(args, "stub", None) and not args.stub_unknown:
        raise UserInputError("--stub needs --stub-unknown")
    if not getattr(args, "stub_unknown", False):
        return None
    return StubPolicy.from_specs(args.stub)


def ros2_leaves_from_args(args: argparse.Namespace, *, register: bool = False) -> list[Any]:
    """The node types of every ``--ros2-leaves`` file; ``register``: also for every registry built from now on
    (what ``tick`` needs, its registry is built with the plugins')."""
    files = getattr(args, "ros2_leaves", None) or []
    if not files:
        return []
    from bt_meta.bt.python_nodes import register_node_type
    from bt_meta.ros2.leaves import load_leaves_file

    types = [node_type for path in files for node_type in load_leaves_file(path)]
    for node_type in types if register else ():
        register_node_type(node_type)
    return types
