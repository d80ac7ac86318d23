"""BehaviorTree.CPP v4 XML for bt-meta.

Modules:

* :mod:`~bt_meta.bt.xml.document` -- safe parsing (no DTDs/entities) into positioned elements
* :mod:`~bt_meta.bt.xml.reader` -- XML -> py_trees behaviours (:func:`load_tree_file`, :func:`load_tree_text`)
* :mod:`~bt_meta.bt.xml.writer` -- py_trees behaviours -> XML with a TreeNodesModel (:func:`tree_to_xml`)
"""

from __future__ import annotations

from bt_meta.bt.xml.reader import load_tree_file, load_tree_text
from bt_meta.bt.xml.writer import tree_to_xml, write_tree

__all__ = ["load_tree_file", "load_tree_text", "tree_to_xml", "write_tree"]
