"""Groot2 live monitoring and log replay for py_trees trees, speaking BehaviorTree.CPP's protocol.

Modules:

* :mod:`~bt_meta.bt.groot2.protocol` -- header, status and transition bytes of ``groot2_protocol.h``
* :mod:`~bt_meta.bt.groot2.published_tree` -- a py_trees tree numbered and described as BehaviorTree.CPP builds it
* :mod:`~bt_meta.bt.groot2.tree_xml` -- the full-tree XML with ``_uid`` / ``_fullpath`` (``WriteTreeToXML``)
* :mod:`~bt_meta.bt.groot2.observer` -- every status change as it happens (resets to IDLE included)
* :mod:`~bt_meta.bt.groot2.msgpack` -- MessagePack as nlohmann::json writes it (blackboard replies)
* :mod:`~bt_meta.bt.groot2.server` -- the ZeroMQ REP/PUB server (``Groot2Publisher``)
* :mod:`~bt_meta.bt.groot2.btlog` -- ``.btlog`` files (``FileLogger2``)
* :mod:`~bt_meta.bt.groot2.session` -- all of it for one run (``--groot2``, ``--hold``, ``--btlog``)

Nothing is imported here, so the CLI can read the default port without loading ZeroMQ.
"""
