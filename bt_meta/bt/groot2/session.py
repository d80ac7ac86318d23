"""One run watched by Groot2: the published tree, its status observer, the live server and/or the ``.btlog`` file.

What ``bt-meta tick/run --groot2 [PORT] [--hold] --btlog FILE`` use, so both commands stay a few lines each.

Offers:

* :class:`Groot2Session` -- :meth:`~Groot2Session.start` (checks the port and log path before anything ticks),
  :meth:`~Groot2Session.after_tick`, :meth:`~Groot2Session.follow` (publish the next tree of a run that replaces
  its tree), :meth:`~Groot2Session.hold`, :meth:`~Groot2Session.close`
* :func:`check_options` -- validate ``--groot2`` / ``--btlog`` values before any work starts
"""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path
from types import FrameType
from typing import TextIO

import py_trees

from bt_meta.bt.groot2.btlog import BtlogWriter, check_btlog_path
from bt_meta.bt.groot2.observer import StatusObserver
from bt_meta.bt.groot2.published_tree import PublishedTree
from bt_meta.bt.groot2.server import Groot2Server, check_port, probe_ports
from bt_meta.bt.groot2.tree_xml import full_tree_xml
from bt_meta.bt.registry import NodeRegistry
from bt_meta.errors import UserInputError


def check_options(port: int | None, btlog: str | Path | None, hold: bool = False, host: str | None = None) -> None:
    """Raise a :class:`UserInputError` for a bad port, an unwritable log path, or ``--hold`` without a server.

    With ``host``, the ports are also probed: one in use is reported before any work starts.
    """
    if port is not None:
        check_port(port)
        if host is not None:
            probe_ports(port, host)
    if btlog is not None:
        check_btlog_path(btlog)
    if hold and port is None:
        raise UserInputError("--hold keeps the Groot2 server up: it needs --groot2", "--hold")


class Groot2Session:
    """Publishes one tree while it ticks; close it (or use ``with``) to release the port and finish the log."""

    def __init__(self, tree: PublishedTree, observer: StatusObserver, server: Groot2Server | None,
                 log: BtlogWriter | None, registry: NodeRegistry | None = None) -> None:
        self.tree = tree
        self.observer = observer
        self.server = server
        self.log = log
        self.registry = registry

    @classmethod
    def start(cls, root: py_trees.behaviour.Behaviour, *, registry: NodeRegistry | None = None,
              port: int | None = None, btlog: str | Path | None = None, host: str = "*",
              seed: int | None = None) -> Groot2Session:
        """Number and observe ``root``; serve it on ``host:port`` and/or log it to ``btlog`` (either may be None)."""
        check_options(port, btlog)
        tree = PublishedTree.build(root, registry=registry)
        observer = StatusObserver(tree)
        server = log = None
        try:
            if port is not None:
                server = Groot2Server(tree, observer, port, seed=seed, host=host)
            if btlog is not None:
                log = BtlogWriter(btlog, server.tree_xml if server is not None else full_tree_xml(tree))
                observer.subscribe(log.record)
        except BaseException:
            if server is not None:
                server.close()
            observer.close()
            raise
        return cls(tree, observer, server, log, registry)

    def follow(self, root: py_trees.behaviour.Behaviour, registry: NodeRegistry | None = None) -> None:
        """Publish ``root`` instead if it is not the tree being published (a repaired run ticks a new tree per segment).

        A ``.btlog`` file holds one tree, so a session with a log cannot follow.
        """
        if root is self.tree.root.behaviour:
            return
        if self.log is not None:
            raise UserInputError("a .btlog file holds one tree; this run replaces its tree", "--btlog")
        self.observer.close()
        self.registry = registry if registry is not None else self.registry
        self.tree = PublishedTree.build(root, registry=self.registry)
        self.observer = StatusObserver(self.tree)
        if self.server is not None:
            self.server.publish(self.tree, self.observer)

    def after_tick(self, status: object) -> None:
        """Call after each root tick with the root's status (resets a finished root, flushes the log)."""
        self.observer.tick_finished(status)
        if self.log is not None:
            self.log.flush()

    def hold(self, out: TextIO = sys.stderr) -> None:
        """Keep serving until SIGTERM or Ctrl-C (returns normally on either)."""
        if self.server is None:
            return
        stop = threading.Event()

        def on_signal(_signum: int, _frame: FrameType | None) -> None:
            stop.set()

        # Signal handlers can only be set from the main thread; elsewhere only Ctrl-C / close() end the hold.
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGTERM, on_signal) if main else None
        print(f"groot2: serving the finished tree on port {self.server.port}; Ctrl-C or SIGTERM to stop",
              file=out, flush=True)
        try:
            while not stop.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            if main:
                signal.signal(signal.SIGTERM, previous)

    def close(self) -> None:
        if self.server is not None:
            self.server.close()
        if self.log is not None:
            self.log.close()
        self.observer.close()

    def __enter__(self) -> Groot2Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
