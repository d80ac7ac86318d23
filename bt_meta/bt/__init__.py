"""Behaviour trees for bt-meta: BehaviorTree.CPP v4 semantics on top of py_trees.

Subpackages and modules (import them explicitly; this package imports nothing heavy):

* :mod:`bt_meta.bt.registry` -- node types, their ports, and the registry the XML loader instantiates from
* :mod:`bt_meta.bt.nodes` -- py_trees behaviours that tick exactly like BehaviorTree.CPP's built-in nodes
* :mod:`bt_meta.bt.xml` -- BehaviorTree.CPP v4 XML reader and writer
"""

from __future__ import annotations
