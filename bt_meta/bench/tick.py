"""``bt-meta bench tick``: what monitors cost per tick, against plain py_trees in the same run.

A 1,000-primitive tree of no-op leaves (``py_trees.behaviours.Success``), shaped like a compiled plan (a root
sequence of compound-task sequences), is ticked to completion over and over, in three configurations built from the
same composites and leaves:

* ``plain`` -- py_trees only: the baseline
* ``monitored`` -- every leaf in a :class:`~bt_meta.bt.monitor.Monitor`, inside a run with no plugins: the
  monitor's own cost (the goal: at most 10% over plain)
* ``monitored-generic`` -- the same monitors made to tick their leaf through py_trees' generic ``Behaviour.tick``
  (``inline_leaf=False``): the cost of the extra decorator level alone, for comparison
* ``monitored+checks`` -- every monitor also checks a precondition (``ready(?i)`` with its argument bound) against
  the belief state and calls the shipped plugins' hooks (entry points: perception, expectations, reporting)

Configurations are interleaved round by round so machine load hits them alike; the figure per configuration is
the median per-tick time, and the ratio is against ``plain`` from the same rounds.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
from typing import Any

import py_trees

from bt_meta.commands._common import print_json

DEFAULT_LEAVES = 1000
DEFAULT_GROUP = 20
DEFAULT_ROUNDS = 30
GOAL = 1.10

_DOMAIN = """
domain:
  name: bench
  predicates:
    ready: [item]
    item: []
  primitives:
    noop:
      parameters: [?i]
      precondition: ready(?i)
      add: []
      delete: []
"""


def build_tree(leaves: int, group: int, wrap: Any = None) -> py_trees.behaviour.Behaviour:
    """Root sequence of ``leaves / group`` memoryful sequences of ``group`` Success leaves (wrapped by ``wrap``)."""
    groups = []
    for g in range(0, leaves, group):
        children = []
        for i in range(g, min(g + group, leaves)):
            leaf: py_trees.behaviour.Behaviour = py_trees.behaviours.Success(name=f"n{i} noop(i{i})")
            children.append(wrap(leaf, i) if wrap is not None else leaf)
        groups.append(py_trees.composites.Sequence(name=f"task {g // group}", memory=True, children=children))
    return py_trees.composites.Sequence(name="plan", memory=True, children=groups)


def _configurations(leaves: int, group: int) -> dict[str, tuple[py_trees.behaviour.Behaviour, Any]]:
    from bt_meta.bt.context import RunContext
    from bt_meta.bt.monitor import Monitor
    from bt_meta.htn import State, load_task_text
    from bt_meta.plugins import PluginHost, create_plugin_host

    domain = load_task_text(_DOMAIN, "<bench>").domain
    condition = domain.primitives["noop"].precondition
    state = State([("ready", f"i{i}") for i in range(leaves)])

    plain = build_tree(leaves, group)
    monitored = build_tree(leaves, group, lambda leaf, i: Monitor(leaf))
    generic = build_tree(leaves, group, lambda leaf, i: Monitor(leaf, inline_leaf=False))
    checked = build_tree(leaves, group, lambda leaf, i: Monitor(leaf, condition=condition, bindings={"i": f"i{i}"}))
    empty_run = RunContext(None, PluginHost(), state=state)
    full_run = RunContext(None, create_plugin_host(), state=state)
    return {"plain": (plain, empty_run), "monitored": (monitored, empty_run),
            "monitored-generic": (generic, empty_run), "monitored+checks": (checked, full_run)}


def run_benchmark(leaves: int = DEFAULT_LEAVES, group: int = DEFAULT_GROUP, rounds: int = DEFAULT_ROUNDS,
                  ticks_per_round: int = 5) -> dict[str, Any]:
    configs = _configurations(leaves, group)
    samples: dict[str, list[float]] = {name: [] for name in configs}
    for name, (root, run) in configs.items():  # warm up, and check every tick really runs every leaf
        run.install()
        root.tick_once()
        if root.status is not py_trees.common.Status.SUCCESS:
            raise RuntimeError(f"benchmark tree {name} did not succeed: {root.status}")
        if run.failures:
            raise RuntimeError(f"benchmark tree {name} recorded failures: {run.failures[0].summary()}")
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for _ in range(rounds):
            for name, (root, run) in configs.items():
                run.install()
                tick = root.tick_once
                start = time.perf_counter()
                for _ in range(ticks_per_round):
                    tick()
                samples[name].append((time.perf_counter() - start) / ticks_per_round)
    finally:
        if gc_was:
            gc.enable()
    base = statistics.median(samples["plain"])
    results = {}
    for name, values in samples.items():
        median = statistics.median(values)
        results[name] = {
            "median_ms_per_tick": round(median * 1e3, 4),
            "min_ms_per_tick": round(min(values) * 1e3, 4),
            "us_per_leaf": round(median / leaves * 1e6, 3),
            "ratio_vs_plain": round(median / base, 3),
        }
    overhead = results["monitored"]["ratio_vs_plain"] - 1.0
    return {
        "benchmark": "tick",
        "leaves": leaves,
        "group": group,
        "rounds": rounds,
        "ticks_per_round": ticks_per_round,
        "results": results,
        "monitor_overhead_percent": round(overhead * 100, 1),
        "goal_percent": round((GOAL - 1) * 100),
        "goal_met": results["monitored"]["ratio_vs_plain"] <= GOAL,
    }


def handle(args: argparse.Namespace) -> int:
    report = run_benchmark(args.leaves, args.group, args.rounds)
    if args.json:
        print_json(report)
        return 0
    print(f"bench tick: {report['leaves']} no-op primitives in sequences of {report['group']}, "
          f"{report['rounds']} interleaved rounds x {report['ticks_per_round']} ticks (median per tick)")
    print(f"{'configuration':<18} {'ms/tick':>9} {'us/leaf':>8} {'ratio':>7}")
    for name, row in report["results"].items():
        print(f"{name:<18} {row['median_ms_per_tick']:>9.3f} {row['us_per_leaf']:>8.3f} {row['ratio_vs_plain']:>7.3f}")
    verdict = "met" if report["goal_met"] else "NOT met"
    print(f"monitor overhead: {report['monitor_overhead_percent']:+.1f}% vs plain py_trees "
          f"(goal <= {report['goal_percent']}%: {verdict})")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("tick", help="monitor overhead per tick vs plain py_trees (same run)")
    parser.add_argument("--leaves", type=int, default=DEFAULT_LEAVES, help="primitives in the tree (default 1000)")
    parser.add_argument("--group", type=int, default=DEFAULT_GROUP, help="primitives per compound task (20)")
    parser.add_argument("--rounds", type=int, default=DEFAULT_ROUNDS, help="interleaved measurement rounds (30)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.set_defaults(func=handle)
