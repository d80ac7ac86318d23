"""Behaviour trees for bt-meta: BehaviorTree.CPP v4 semantics on top of py_trees.

Subpackages and modules (import them explicitly; this package imports nothing heavy):

* :mod:`bt_meta.bt.registry` -- node types, their ports, and the registry the XML loader and compiler build from
* :mod:`bt_meta.bt.nodes` -- py_trees behaviours that tick exactly like BehaviorTree.CPP's built-in nodes
* :mod:`bt_meta.bt.xml` -- BehaviorTree.CPP v4 XML reader and writer
* :mod:`bt_meta.bt.compiler` -- HTN decompositions to trees with a Monitor around every primitive
* :mod:`bt_meta.bt.monitor` -- the Monitor decorator (preconditions, expectations, structured failures)
* :mod:`bt_meta.bt.actions`, :mod:`bt_meta.bt.guards`, :mod:`bt_meta.bt.domain_nodes` -- primitive actions,
  method guards, and the node types a task file's domain registers
* :mod:`bt_meta.bt.context`, :mod:`bt_meta.bt.expectations`, :mod:`bt_meta.bt.failures` -- run context,
  expectation records, failure records
* :mod:`bt_meta.bt.loading` -- a runnable tree from a task file or XML
* :mod:`bt_meta.bt.groot2` -- Groot2 live monitoring (BehaviorTree.CPP's ZeroMQ protocol) and ``.btlog`` files
"""

from __future__ import annotations
