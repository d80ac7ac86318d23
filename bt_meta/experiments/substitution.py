"""``bt-meta experiment substitution``: Table 1 of the paper (section 6.4) in the pybullet simulator.

The nominal plans for the letters A and H (``trees/letters.yaml``; H draws its crossbar with two 1x1 blocks) are
run on :class:`~bt_meta.world.simulation.sim_world.SimWorld` and recorded by
:class:`~bt_meta.memory.recorder.TraceRecorder`
(P_a, E_db with the placed blocks' grid-maps). Then A's plan is run in the three variant scenes where its blue
1x2 crossbar block is replaced: by a 1x2 of another colour (red); by two 1x1 of the same colour (red); by two 1x1
of different colours (red and blue). For each variant the output gives:

* **retrieval** -- the mismatch vector as the world shows it before the run (the missing entity, the unknown ones
  seen), the first step using the missing entity, and the ranked matches of the two matchers of
  :mod:`bt_meta_plugins.object_substitution`: grid-map nearest neighbours in E_db versus symbolic matching on
  shape/colour facts (which stored step of which task, its decomposition, distance, rank, and whether the unknown
  entities can carry it out);
* **run** -- A's plan run through :class:`~bt_meta.meta.MetaExecutor` with camera perception, grid-map
  expectations, the taxonomy rules and the substitution plugin with one matcher (no retry baseline): what the
  monitor saw, the repair applied, the final status, and whether the blocks lie where the letter A wants them
  (every cell of the nominal A covered, nothing else in the letter's area).

The goal check of problem A (``at(b5, 1.5, 1)``) names the crossbar block a substitution replaces, so the runs are
verified by the letter's cells instead (:func:`letter_verifier`).

Offers:

* :func:`register` -- adds ``bt-meta experiment substitution [--matchers gridmap,symbolic] [--variants V,..]
  [--seed 0] [--memory PATH] [--json]``
* :func:`run` -- the experiment, returning the table as a dict
* :func:`record_nominal` -- record A and H into a memory
* :func:`letter_cells` / :func:`letter_verifier` -- where the blocks are in letter cells; the check built on it
* :data:`VARIANTS`
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.commands._world_args import add_world_arguments, world_options
from bt_meta.errors import UserInputError

__all__ = ["VARIANTS", "letter_cells", "letter_verifier", "record_nominal", "register", "run"]

VARIANTS: tuple[tuple[str, str], ...] = (
    ("A_bar_other_colour", "1x2 of another colour"),
    ("A_two_1x1_same_colour", "two 1x1 of the same colour"),
    ("A_two_1x1_different_colours", "two 1x1 of different colours"),
)
MATCHERS = ("gridmap", "symbolic")
_CELL_TOLERANCE = 0.25  # lb: a block counts in a cell when its footprint centre is this close


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("substitution", help="Table 1: grid-map vs symbolic retrieval for A's variants, "
                                                        "and the repaired runs")
    parser.add_argument("--matchers", default="gridmap,symbolic",
                        help="comma-separated matchers whose repairs are run (default: gridmap,symbolic)")
    parser.add_argument("--variants", default=",".join(v for v, _ in VARIANTS),
                        help="comma-separated variants of A (default: all three)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed of every run")
    parser.add_argument("--memory", metavar="PATH", default=None,
                        help="episodic memory to use; A and H are recorded into it unless it already has them "
                             "(default: a temporary file)")
    add_world_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    matchers = [m.strip() for m in str(args.matchers).split(",") if m.strip()]
    unknown = [m for m in matchers if m not in MATCHERS]
    if unknown or not matchers:
        raise UserInputError(f"--matchers: expected a comma-separated subset of {', '.join(MATCHERS)}, "
                             f"got {args.matchers!r}", path="<command line>")
    variants = [v.strip() for v in str(args.variants).split(",") if v.strip()]
    known = [v for v, _ in VARIANTS]
    if not variants or any(v not in known for v in variants):
        raise UserInputError(f"--variants: expected a comma-separated subset of {', '.join(known)}, "
                             f"got {args.variants!r}", path="<command line>")
    options = world_options(args)
    if options["scene"] is not None:
        raise UserInputError("--scene: the substitution experiment runs letters A's own scene and its variants "
                             "(they replace its crossbar); run a scene of one's own with "
                             "`bt-meta run TASK --scene FILE`", path="<command line>")
    result = run(matchers=matchers, seed=args.seed, memory_path=args.memory, variants=variants,
                 robot=options["robot"])
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0


# -- recording --------------------------------------------------------------------------------------------------


def record_nominal(memory: Any, path: Path, problem: str, *, seed: int = 0, sim: Any = None) -> int:
    """Run ``problem``'s nominal plan on the simulator, record it into ``memory``, return the episode id."""
    from py_trees.common import Status

    from bt_meta.memory.recorder import TraceRecorder
    from bt_meta.plugins import create_plugin_host
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    with quiet_stdout():
        world = SimWorld.from_task_file(path, problem, seed=seed, sim=sim)
    try:
        recorder = TraceRecorder(memory, variant=world.variant, seed=seed, config={"demonstration": True})
        plugins = create_plugin_host(entry_points=False, plugins=[("recorder", recorder)])
        harness = TreeHarness.from_file(path, problem, world=world, plugins=plugins)
        recorder.tree = harness.compiled.plan_result.tree
        status = Status.RUNNING
        while status is Status.RUNNING and harness.run.tick_count < 20_000:
            status = harness.tick()
        harness.run.finish(status)
        harness.close()
        if recorder.error is not None:
            raise recorder.error
        if status is not Status.SUCCESS or recorder.episode_id is None:
            raise RuntimeError(f"the nominal {problem} did not succeed ({status.value}); nothing recorded")
        return recorder.episode_id
    finally:
        world.close()


# -- the letter's cells -------------------------------------------------------------------------------------------


def letter_cells(world: Any, frame: str = "letter") -> list[tuple[float, float]]:
    """The letter cells (u, v in lb) every block covers: a 1x1 one, a 1x2 two (its centre +- half a block along
    its long axis), rounded to half cells; blocks anywhere on the table."""
    import numpy as np

    origin = np.array(world.ground_cell(frame, "0", "0")[:2])
    ex = np.array(world.ground_cell(frame, "1", "0")[:2]) - origin
    ey = np.array(world.ground_cell(frame, "0", "1")[:2]) - origin
    to_letter = np.linalg.inv(np.column_stack([ex, ey]))
    sim = world.sim
    cells = []
    for name, state in sim.object_states().items():
        if state.shape is None:
            continue
        low, high = sim.object_model(name).extent()
        size = high - low
        centre = np.array(state.pose[:2])
        yaw = state.pose[5]
        if size[0] > 1.5 * size[1] or size[1] > 1.5 * size[0]:
            axis = 0 if size[0] > size[1] else 1
            half = 0.25 * float(size[axis])  # half of one of the two cells' spacing
            direction = np.array([math.cos(yaw), math.sin(yaw)]) if axis == 0 else \
                np.array([-math.sin(yaw), math.cos(yaw)])
            points = [centre - half * direction, centre + half * direction]
        else:
            points = [centre]
        for point in points:
            u, v = to_letter @ (point - origin)
            cells.append((float(u), float(v)))
    return cells


def _in_area(cell: tuple[float, float], area: tuple[float, float, float, float]) -> bool:
    return area[0] <= cell[0] <= area[1] and area[2] <= cell[1] <= area[3]


def letter_verifier(expected: Sequence[tuple[float, float]]) -> Any:
    """A :class:`~bt_meta.meta.MetaExecutor` verifier: the blocks cover exactly the ``expected`` cells in the
    letter's area (its bounding box grown by one cell), each within a quarter block."""
    from bt_meta.bt.failures import Failure, FailureKind

    us = [c[0] for c in expected]
    vs = [c[1] for c in expected]
    area = (min(us) - 1, max(us) + 1, min(vs) - 1, max(vs) + 1)

    def verify(world: Any, run: Any, plan_state: Any) -> Failure | None:
        seen = [c for c in letter_cells(world) if _in_area(c, area)]
        unmatched = list(seen)
        missing = []
        for cell in expected:
            near = next((s for s in unmatched if math.dist(s, cell) <= _CELL_TOLERANCE), None)
            if near is None:
                missing.append(cell)
            else:
                unmatched.remove(near)
        if not missing and not unmatched:
            return None
        steps = plan_state.steps()
        last = steps[-1] if steps else None
        return Failure(kind=FailureKind.VERIFICATION,
                       message=f"the letter's cells differ: missing {_cells_text(missing)}, extra "
                               f"{_cells_text(unmatched)}",
                       step=None if last is None else last.step, node_id=None if last is None else last.id,
                       action=None if last is None else last.task[0],
                       args=() if last is None else tuple(last.task[1:]),
                       evidence={"verifier": "letter_cells", "missing": [list(c) for c in missing],
                                 "extra": [list(c) for c in unmatched]})

    return verify


def _cells_text(cells: Sequence[tuple[float, float]]) -> str:
    return ", ".join(f"({u:.2f}, {v:.2f})" for u, v in cells) or "none"


# -- the experiment -----------------------------------------------------------------------------------------------


def _retrievals(world: Any, task_file: Any, memory: Any, matchers: Sequence[str]) -> dict[str, Any]:
    """The mismatch vector of the variant world before the run and each matcher's ranked matches."""
    import bt_meta_plugins.object_substitution as substitution

    from bt_meta.htn import plan
    from bt_meta.meta.proposals import PlanState

    problem = task_file.problem("A")
    planned = plan(task_file.domain, problem)
    steps = PlanState(planned.tree).describe()
    context = SimpleNamespace(world=world, run=SimpleNamespace(problem=problem))
    failure = SimpleNamespace(step=None, evidence={"plan": steps})
    vector = substitution.mismatch_vector(failure, context)
    out: dict[str, Any] = {"vector": None if vector is None else vector.to_dict(), "matchers": {}}
    if vector is None:
        return out
    for matcher in matchers:
        plugin = substitution.ObjectSubstitution(memory, matcher=matcher, k=5)
        retrieval = plugin.retrieve(vector, steps, memory, "draw_A")
        proposals = plugin.proposals(retrieval, steps)
        out["matchers"][matcher] = {**retrieval.to_dict(), "proposals": [
            {"action": p.action, "score": p.score, "changes": p.changes, "description": p.description}
            for p in proposals]}
    return out


def _run_variant(task_file: Any, variant: str, memory: Any, matcher: str, expected: Sequence[tuple[float, float]],
                 seed: int, sim: Any) -> dict[str, Any]:
    import bt_meta_plugins.camera_perception as camera_plugin
    import bt_meta_plugins.classification_rules as rules
    import bt_meta_plugins.gridmap_expectations as gridmap
    import bt_meta_plugins.object_substitution as substitution

    from bt_meta.meta import Limits, MetaExecutor
    from bt_meta.plugins import create_plugin_host
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    problem = task_file.problem("A")
    grounding = load_grounding(task_file.domain.name, task_file.path)
    with quiet_stdout():
        world = SimWorld(task_file.domain, problem, grounding, variant=variant, seed=seed, sim=sim)
    plugins = create_plugin_host(entry_points=False, plugins=[
        ("camera_perception", camera_plugin), ("gridmap_expectations", gridmap.GridMapExpectations(memory)),
        ("classification_rules", rules),
        ("object_substitution", substitution.ObjectSubstitution(memory, matcher=matcher))])
    try:
        started = time.perf_counter()
        report = MetaExecutor(task_file.domain, problem, world, plugins, task_file=task_file, variant=variant,
                              limits=Limits(max_attempts=3, max_seconds=120.0),
                              verifiers=[letter_verifier(expected)]).run()
        seconds = time.perf_counter() - started
        cells = [c for c in letter_cells(world)]
    finally:
        world.close()
    first = report.failures[0] if report.failures else None
    return {
        "matcher": matcher, "status": report.status, "stop_reason": report.stop_reason,
        "seconds": round(seconds, 2), "ticks": report.ticks,
        "monitor": None if first is None else {"step": first.get("step"), "kind": first.get("kind"),
                                               "message": first.get("message")},
        "repairs": [{"action": a.proposal.get("action"), "change": a.change, "score": a.proposal.get("score"),
                     "outcome": a.outcome} for a in report.attempts],
        "plan": report.plan,
        "letter_ok": report.status == "success",
        "letter_cells": [[round(u, 2), round(v, 2)] for u, v in cells if -1.5 <= u <= 4.5 and -1.5 <= v <= 3.5],
        "reported": [{"kind": r.get("kind"), "message": r.get("message")} for r in report.reported],
        "failures": [{"step": f.get("step"), "kind": f.get("kind"), "message": f.get("message")}
                     for f in report.failures],
    }


def run(*, matchers: Sequence[str] = MATCHERS, seed: int = 0, memory_path: str | Path | None = None,
        variants: Sequence[str] | None = None, robot: Any = None) -> dict[str, Any]:
    """Record A and H (unless the memory has them), then tabulate retrieval and repaired runs per variant, on
    ``robot`` (a description; default the Baxter). A memory holds one robot's episodes: give each its own."""
    from bt_meta.htn import load_task_file
    from bt_meta.memory import EpisodicMemory
    from bt_meta.resources import trees_dir
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    path = trees_dir() / "letters.yaml"
    task_file = load_task_file(path)
    chosen = [v for v, _ in VARIANTS if variants is None or v in variants]
    with tempfile.TemporaryDirectory(prefix="bt-meta-substitution-") as temporary:
        file = Path(memory_path) if memory_path is not None else Path(temporary) / "memory.sqlite"
        started = time.perf_counter()
        with quiet_stdout():  # pybullet prints its build time on import
            from bt_meta.world.simulation.sim import Simulation

            sim = Simulation(seed=seed, visuals="light", robot=robot)
        try:
            recorded: dict[str, Any] = {}
            with EpisodicMemory.open(file) as memory:
                for problem in ("A", "H"):
                    present = memory.episodes(task=f"draw_{problem}", outcome="success", limit=1)
                    recorded[problem] = (f"episode {present[0].episode.id} (already in memory)" if present else
                                         f"episode {record_nominal(memory, path, problem, seed=seed, sim=sim)}")
            with quiet_stdout():
                nominal = SimWorld(task_file.domain, task_file.problem("A"), _grounding(task_file), sim=sim)
            expected = _nominal_cells(memory_file=file, world=nominal)
            nominal.close()
            rows = []
            with EpisodicMemory.open(file, readonly=True) as memory:
                for variant in chosen:
                    with quiet_stdout():
                        world = SimWorld(task_file.domain, task_file.problem("A"), _grounding(task_file),
                                         variant=variant, seed=seed, sim=sim)
                    retrieval = _retrievals(world, task_file, memory, MATCHERS)
                    world.close()
                    runs = {m: _run_variant(task_file, variant, memory, m, expected, seed, sim) for m in matchers}
                    rows.append({"variant": variant, "description": dict(VARIANTS)[variant],
                                 "retrieval": retrieval, "runs": runs})
        finally:
            sim.close()
        return {"memory": str(file) if memory_path is not None else "temporary", "recorded": recorded,
                "expected_cells": [list(c) for c in expected], "rows": rows,
                "seconds": round(time.perf_counter() - started, 2)}


def _grounding(task_file: Any) -> Any:
    from bt_meta.world.simulation.sim_world import load_grounding

    return load_grounding(task_file.domain.name, task_file.path)


def _nominal_cells(*, memory_file: Path, world: Any) -> list[tuple[float, float]]:
    """The letter A's cells: where the nominal plan's blocks end, replayed from P_a onto the cell grid."""
    from bt_meta.memory import EpisodicMemory

    with EpisodicMemory.open(memory_file, readonly=True) as memory:
        rows = [r for r in memory.plan_executions("draw_A")]
        newest = max(r.episode_id for r in rows)
        attributes = {}
        for fact in memory.trace(newest).initial.facts:
            if fact[0] == "shape":
                attributes[str(fact[1])] = str(fact[2])
    cells = []
    for row in rows:
        if row.episode_id != newest or row.action != "place":
            continue
        block, x, y = str(row.args[0]), float(row.args[1]), float(row.args[2])
        if attributes.get(block) == "1x2":
            cells += [(x - 0.5, y), (x + 0.5, y)]
        else:
            cells.append((x, y))
    return cells


# -- printing -----------------------------------------------------------------------------------------------------


def _match_text(found: dict[str, Any] | None) -> str:
    if found is None:
        return "none"
    letter = str(found["task"]).removeprefix("draw_")
    return f"{letter}: {found['parent_task']} {found['call']} d={found['distance']} #{found['rank']}"


def _run_text(run: dict[str, Any] | None) -> str:
    if run is None:
        return "-"
    repairs = ", ".join(r["action"] for r in run["repairs"])
    if run["status"] == "success":
        how = repairs or ("no mismatch" if run["monitor"] is None else "no repair")
    else:
        how = repairs + (" then " if repairs else "") + ("no proposal" if "no repair proposed" in
                                                         run["stop_reason"] else run["stop_reason"])
    return f"{run['status'].upper()}, {how}, letter {'ok' if run['letter_ok'] else 'wrong'}"


def _print(result: dict[str, Any]) -> None:
    print("Table 1 (section 6.4): A's blue 1x2 crossbar replaced; first usable match in E_db (d = distance, "
          "# = rank)")
    print(f"memory: {result['memory']}; recorded A: {result['recorded']['A']}, H: {result['recorded']['H']}; "
          f"letter A's cells: {_cells_text([tuple(c) for c in result['expected_cells']])}")
    print()
    header = (f"{'variant':<30} {'grid-map retrieval':<40} {'symbolic retrieval':<20} "
              f"{'run: grid-map':<34} run: symbolic")
    print(header)
    print("-" * len(header))
    for row in result["rows"]:
        matchers = row["retrieval"]["matchers"]
        print(f"{row['description']:<30} {_match_text((matchers.get('gridmap') or {}).get('found')):<40} "
              f"{_match_text((matchers.get('symbolic') or {}).get('found')):<20} "
              f"{_run_text(row['runs'].get('gridmap')):<34} {_run_text(row['runs'].get('symbolic'))}")
    print()
    for row in result["rows"]:
        vector = row["retrieval"]["vector"] or {}
        print(f"{row['variant']}: missing {', '.join(vector.get('missing') or []) or 'nothing'}; unknown "
              f"{', '.join(vector.get('unknown') or []) or 'nothing'}")
        for matcher in MATCHERS:
            retrieval = row["retrieval"]["matchers"].get(matcher) or {}
            print(f"  {matcher}: query {retrieval.get('query_call')} (P_a episode {retrieval.get('query_episode')}:"
                  f" {retrieval.get('query')})")
            for m in retrieval.get("matches") or []:
                flag = "usable" if m["realisable"] else "not usable"
                binding = f" with {m['binding']}" if m["binding"] else f" ({m['reason']})"
                print(f"    #{m['rank']} d={m['distance']:<3} {m['task']} step {m['step']} {m['call']} "
                      f"[{m['parent_task']}: {m['decomposition']}] {flag}{binding}")
            for p in retrieval.get("proposals") or []:
                print(f"    -> {p['action']} {p['changes']}")
        for matcher, run in row["runs"].items():
            monitor = run["monitor"]
            seen = ("no mismatch" if monitor is None
                    else f"step {monitor['step']} {monitor['kind']}: {monitor['message']}")
            print(f"  run with {matcher}: {run['status']} in {run['seconds']} s; monitor: {seen}")
            for repair in run["repairs"]:
                print(f"    repair {repair['action']} ({repair['outcome']}): {repair['change']}")
            if run["stop_reason"]:
                print(f"    stopped: {run['stop_reason']}")
            print(f"    plan: {'; '.join(a[0] + '(' + ', '.join(a[1:]) + ')' for a in run['plan'])}")
            print(f"    blocks in the letter's area: {_cells_text([tuple(c) for c in run['letter_cells']])}")
    print(f"\ntotal {result['seconds']} s")
