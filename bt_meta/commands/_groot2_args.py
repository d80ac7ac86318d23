"""The ``--groot2 [PORT]``, ``--groot2-host``, ``--hold`` and ``--btlog FILE`` options shared by ``tick`` and ``run``.

Offers:

* :func:`add_groot2_arguments` -- adds the options to a subcommand's parser
* :func:`check_groot2_arguments` -- validates them before any work starts (bad or busy port, unwritable log:
  exit 2)
* :func:`start_groot2` -- a :class:`Groot2Run` for a harness's tree; a no-op when no option was given
* :func:`follow_groot2` -- a :class:`Groot2Follow` for a run that builds a new tree per segment (``run --repair``):
  :meth:`~Groot2Follow.watch` a :class:`~bt_meta.bt.context.RunContext` and whatever root it ticks is published

A command calls ``groot2.after_tick(status)`` after each tick and ``groot2.finish()`` after the last one (which
holds the server up with ``--hold`` until SIGTERM or Ctrl-C, then releases the port and closes the log).
"""

from __future__ import annotations

import argparse
from typing import Any

from bt_meta.bt.groot2.protocol import DEFAULT_PORT


def add_groot2_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("Groot2 monitoring")
    group.add_argument("--groot2", nargs="?", type=int, const=DEFAULT_PORT, default=None, metavar="PORT",
                       help=f"serve BehaviorTree.CPP's Groot2 protocol on PORT and PORT+1 while ticking "
                            f"(default {DEFAULT_PORT})")
    group.add_argument("--groot2-host", default="*", metavar="ADDRESS",
                       help="interface the Groot2 server listens on (default: all, as BehaviorTree.CPP)")
    group.add_argument("--hold", action="store_true",
                       help="with --groot2: keep serving after the last tick until SIGTERM or Ctrl-C")
    group.add_argument("--btlog", metavar="FILE",
                       help="write a Groot2 log (BehaviorTree.CPP FileLogger2 .btlog) of every status change")


def check_groot2_arguments(args: argparse.Namespace) -> None:
    from bt_meta.bt.groot2.session import check_options

    check_options(args.groot2, args.btlog, args.hold, host=args.groot2_host)


class Groot2Run:
    """What a command sees: forwards to a :class:`~bt_meta.bt.groot2.session.Groot2Session`, or does nothing."""

    def __init__(self, session: Any = None, hold: bool = False) -> None:
        self.session = session
        self.hold = hold

    def after_tick(self, status: object) -> None:
        if self.session is not None:
            self.session.after_tick(status)

    def finish(self) -> None:
        if self.session is None:
            return
        try:
            if self.hold:
                self.session.hold()
        finally:
            self.session.close()
            self.session = None


def start_groot2(args: argparse.Namespace, harness: Any) -> Groot2Run:
    """Publish ``harness.root`` (its registry gives ports and the TreeNodesModel) as the options ask."""
    if args.groot2 is None and args.btlog is None:
        return Groot2Run()
    from bt_meta.bt.groot2.session import Groot2Session

    registry = getattr(harness.compiled, "registry", None)
    session = Groot2Session.start(harness.root, registry=registry, port=args.groot2, btlog=args.btlog,
                                  host=args.groot2_host, seed=getattr(args, "seed", None))
    return Groot2Run(session, hold=args.hold)


class Groot2Follow(Groot2Run):
    """Publishes whatever tree a :class:`~bt_meta.bt.context.RunContext` ticks, switching when the tree changes."""

    def __init__(self, args: argparse.Namespace) -> None:
        super().__init__(None, hold=args.hold)
        self.args = args

    def watch(self, run: Any, registry: Any = None) -> None:
        """Route ``run.tick`` through Groot2 (once per run; a no-op without ``--groot2``)."""
        if self.args.groot2 is None or getattr(run, "_groot2_watched", False):
            return
        original = run.tick

        def tick(root: Any, visit: Any = None) -> Any:
            self._publish(root, registry)
            status = original(root, visit)
            self.after_tick(status)
            return status

        run.tick = tick
        run._groot2_watched = True

    def _publish(self, root: Any, registry: Any) -> None:
        from bt_meta.bt.groot2.session import Groot2Session

        if self.session is None:
            self.session = Groot2Session.start(root, registry=registry, port=self.args.groot2,
                                               host=self.args.groot2_host, seed=getattr(self.args, "seed", None))
        else:
            self.session.follow(root, registry)


def follow_groot2(args: argparse.Namespace) -> Groot2Follow:
    return Groot2Follow(args)
