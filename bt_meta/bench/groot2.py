"""``bt-meta bench groot2``: what watching a tree in Groot2 costs per tick, against the same tree unwatched.

A tree XML of BehaviorTree.CPP built-ins (``--leaves`` AlwaysSuccess leaves in Sequences of ``--group``, each group
behind an Inverter pair, so every tick runs every node and every node changes status twice) is loaded once per
configuration and ticked to completion, configurations interleaved round by round:

* ``plain`` -- bt-meta's nodes, nothing watching: the baseline
* ``observed`` -- the :class:`~bt_meta.bt.groot2.observer.StatusObserver` installed, no subscriber (the cost of the
  status property and the hook check on every node)
* ``served`` -- a :class:`~bt_meta.bt.groot2.server.Groot2Server` on 127.0.0.1 keeping the status buffer
* ``served+btlog`` -- the server and a ``.btlog`` writer (every transition written)

The figure is the median per-tick time; the ratio is against ``plain`` from the same rounds. When behaviortreepy is
installed, BehaviorTree.CPP itself ticks the same XML with and without its ``Groot2Publisher`` and ``FileLogger2``
for comparison (its own ratio, its own baseline).
"""

from __future__ import annotations

import argparse
import gc
import socket
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json

DEFAULT_LEAVES = 500
DEFAULT_GROUP = 10
DEFAULT_ROUNDS = 15


def tree_xml(leaves: int, group: int) -> str:
    groups = []
    for start in range(0, leaves, group):
        body = "".join(f'<AlwaysSuccess name="leaf {i}"/>' for i in range(start, min(start + group, leaves)))
        groups.append(f"<Inverter><Inverter><Sequence>{body}</Sequence></Inverter></Inverter>")
    return (f'<root BTCPP_format="4"><BehaviorTree ID="MainTree"><Sequence name="plan">{"".join(groups)}'
            "</Sequence></BehaviorTree></root>")


def _free_port() -> int:
    for _ in range(100):
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        if port < 65000:
            return port
    raise RuntimeError("no free port")


def _ours(xml: str, folder: Path) -> tuple[dict[str, Callable[[], Any]], list[Any]]:
    from bt_meta.bt.groot2.btlog import BtlogWriter
    from bt_meta.bt.groot2.observer import StatusObserver
    from bt_meta.bt.groot2.published_tree import PublishedTree
    from bt_meta.bt.groot2.server import Groot2Server
    from bt_meta.bt.nodes.ticking import tick_once
    from bt_meta.bt.registry import default_registry
    from bt_meta.bt.xml.reader import load_tree_text

    registry = default_registry()
    ticks: dict[str, Callable[[], Any]] = {}
    closers: list[Any] = []
    for name in ("plain", "observed", "served", "served+btlog"):
        root = load_tree_text(xml, registry)
        if name == "plain":
            ticks[name] = lambda root=root: tick_once(root)
            continue
        tree = PublishedTree.build(root, registry=registry)
        observer = StatusObserver(tree)
        closers.append(observer)
        if name != "observed":
            server = Groot2Server(tree, observer, _free_port(), host="127.0.0.1", seed=0)
            closers.insert(0, server)
            if name == "served+btlog":
                log = BtlogWriter(folder / "bench.btlog", server.tree_xml)
                observer.subscribe(log.record)
                closers.insert(0, log)

        def tick(root: Any = root, observer: Any = observer) -> Any:
            status = tick_once(root)
            observer.tick_finished(status)
            return status

        ticks[name] = tick
    return ticks, closers


def _btcpp(xml: str, folder: Path) -> tuple[dict[str, Callable[[], Any]], list[Any]]:
    try:
        import behaviortreepy as btpy
    except ImportError:
        return {}, []
    factory = btpy.BehaviorTreeFactory()
    plain = factory.create_tree_from_text(xml)
    watched = factory.create_tree_from_text(xml)
    keep = [plain, watched, btpy.Groot2Publisher(watched, _free_port()), btpy.FileLogger(watched,
                                                                                         str(folder / "c.btlog"))]
    return {"BT.CPP plain": plain.tick_once, "BT.CPP served+btlog": watched.tick_once}, keep


def _measure(ticks: dict[str, Callable[[], Any]], rounds: int, per_round: int) -> dict[str, list[float]]:
    samples: dict[str, list[float]] = {name: [] for name in ticks}
    for name, tick in ticks.items():  # warm up, and check every tick runs the whole tree to SUCCESS
        status = tick()
        if getattr(status, "name", status) != "SUCCESS":
            raise RuntimeError(f"benchmark tree {name} did not succeed: {status}")
    enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(rounds):
            for name, tick in ticks.items():
                start = time.perf_counter()
                for _ in range(per_round):
                    tick()
                samples[name].append((time.perf_counter() - start) / per_round)
    finally:
        if enabled:
            gc.enable()
    return samples


def run_benchmark(leaves: int = DEFAULT_LEAVES, group: int = DEFAULT_GROUP, rounds: int = DEFAULT_ROUNDS,
                  per_round: int = 3) -> dict[str, Any]:
    xml = tree_xml(leaves, group)
    with tempfile.TemporaryDirectory(prefix="bt_meta_bench_groot2_") as folder:
        ours, closers = _ours(xml, Path(folder))
        theirs, keep = _btcpp(xml, Path(folder))
        try:
            samples = _measure({**ours, **theirs}, rounds, per_round)
        finally:
            for item in closers:
                item.close()
            keep.clear()
    results: dict[str, Any] = {}
    for name, values in samples.items():
        base = statistics.median(samples["BT.CPP plain" if name.startswith("BT.CPP") else "plain"])
        median = statistics.median(values)
        results[name] = {"median_ms_per_tick": round(median * 1e3, 4),
                         "ratio_vs_own_plain": round(median / base, 3)}
    nodes = 1 + 3 * -(-leaves // group) + leaves
    return {"benchmark": "groot2", "leaves": leaves, "nodes": nodes, "group": group, "rounds": rounds,
            "ticks_per_round": per_round, "results": results}


def handle(args: argparse.Namespace) -> int:
    report = run_benchmark(args.leaves, args.group, args.rounds)
    if args.json:
        print_json(report)
        return 0
    print(f"bench groot2: {report['nodes']} nodes ({report['leaves']} leaves), {report['rounds']} interleaved rounds "
          f"x {report['ticks_per_round']} ticks (median per tick)")
    print(f"{'configuration':<22} {'ms/tick':>9} {'ratio':>7}")
    for name, row in report["results"].items():
        print(f"{name:<22} {row['median_ms_per_tick']:>9.3f} {row['ratio_vs_own_plain']:>7.3f}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("groot2", help="cost of Groot2 monitoring and .btlog per tick vs unwatched")
    parser.add_argument("--leaves", type=int, default=DEFAULT_LEAVES, help=f"leaves (default {DEFAULT_LEAVES})")
    parser.add_argument("--group", type=int, default=DEFAULT_GROUP, help=f"leaves per Sequence ({DEFAULT_GROUP})")
    parser.add_argument("--rounds", type=int, default=DEFAULT_ROUNDS, help=f"measurement rounds ({DEFAULT_ROUNDS})")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.set_defaults(func=handle)
