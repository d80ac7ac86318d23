"""``bt-meta run FILE --problem P``: plan a task file's problem and run it tick by tick on the simulated Baxter.

Offers:

* :func:`register` -- adds ``run FILE [--problem P] [--variant V] [--seed S] [--json] [--plugins DIR]
  [--max-ticks N] [--gui] [--grounding FILE]``
* :func:`run` -- the handler

The problem is planned and compiled with a Monitor around every primitive, then ticked on a
:class:`~bt_meta.world.sim_world.SimWorld` built from the grounding file (``poses/<domain>.yaml``) and the
problem's scene with the chosen variant, headless unless ``--gui``. The tick log prints one line per tick in which
some primitive changed status. ``--json`` prints ``{status, ticks, failures: [{kind, step, node_id, action, args,
evidence, message}], objects (final object states), ...}``. Exit status: 0 SUCCESS, 1 FAILURE (a failed step, no
plan, or still running after ``--max-ticks``), 2 bad input (unknown problem or variant: the known ones are listed).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

from py_trees.common import Status

from bt_meta.commands._common import print_json
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.errors import PlanningError, UserInputError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("run", help="plan a problem and run it tick by tick in the pybullet simulator")
    parser.add_argument("file", help="YAML task file")
    parser.add_argument("--problem", help="problem name (required when the file has several)")
    parser.add_argument("--variant", help="scene variant (default: the grounding file's for the problem, else nominal)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    parser.add_argument("--max-ticks", type=int, default=5000, help="give up after this many ticks (default 5000)")
    parser.add_argument("--gui", action="store_true", help="open the pybullet window and run in real time")
    parser.add_argument("--grounding", help="grounding file (default: poses/<domain>.yaml beside FILE or shipped)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with the outcome")
    add_plugin_arguments(parser)
    parser.set_defaults(func=run)


def _shown(behaviour: Any) -> bool:
    from bt_meta.bt.actions import PrimitiveAction
    from bt_meta.bt.guards import CheckCondition

    return isinstance(behaviour, (PrimitiveAction, CheckCondition))


def run(args: argparse.Namespace) -> int:
    from bt_meta.bt.failures import Failure, FailureKind
    from bt_meta.htn import load_task_file
    from bt_meta.testing import TreeHarness
    from bt_meta.world.sim_world import SimWorld, load_grounding, quiet_stdout

    if args.max_ticks < 1:
        raise UserInputError("--max-ticks must be at least 1")
    task_file = load_task_file(args.file)
    problem = task_file.problem(args.problem)  # unknown names list the known ones (exit 2)
    grounding = load_grounding(task_file.domain.name, args.file, args.grounding)
    grounding.problem(problem.name)
    plugins = plugin_host_from_args(args, args.file)
    started = time.perf_counter()
    with quiet_stdout():
        world = SimWorld(task_file.domain, problem, grounding, variant=args.variant, seed=args.seed, gui=args.gui)
    built = time.perf_counter()
    out: dict[str, Any] = {"file": str(args.file), "problem": problem.name, "variant": world.variant,
                           "scene": world.scene.name, "seed": args.seed}
    try:
        try:
            harness = TreeHarness.from_file(args.file, problem.name, world=world, plugins=plugins)
        except PlanningError as error:
            failure = Failure(kind=FailureKind.PRECONDITION, message=str(error), evidence={"planner": str(error)})
            return _report(args, out, "FAILURE", 0, [failure.to_dict()], world, [], started, built)
        plan = [" ".join((p.name, *p.args)) for p in harness.compiled.plan_result.plan]
        if not args.json:
            print(f"{problem.name} in scene {world.scene.name} ({world.variant}), seed {args.seed}: "
                  f"{len(plan)} primitives planned")
        shown = {b.name for b in harness.root.iterate() if _shown(b)}
        last: dict[str, str] = {}
        status = Status.RUNNING
        reported = 0
        while harness.run.tick_count < args.max_ticks:
            status = harness.tick()
            seen = harness.statuses()
            nodes = {name: seen.get(f"Monitor<{name}>", value) for name, value in seen.items() if name in shown}
            changed = {name: value for name, value in nodes.items() if last.get(name) != value}
            last.update(nodes)
            new_failures = harness.failures[reported:]
            reported = len(harness.failures)
            if not args.json and (changed or new_failures or status is not Status.RUNNING):
                listed = "  ".join(f"{name}={value}" for name, value in changed.items())
                print(f"tick {harness.run.tick_count:>4}  {status.value:<8} {listed}")
                for failure in new_failures:
                    print(f"           failure {failure.summary()}")
            if status is not Status.RUNNING:
                break
        failures = [f.to_dict() for f in harness.failures]
        harness.close()
        return _report(args, out, status.value, harness.run.tick_count, failures, world, plan, started, built)
    finally:
        world.close()


def _report(args: argparse.Namespace, out: dict[str, Any], status: str, ticks: int, failures: list[dict[str, Any]],
            world: Any, plan: list[str], started: float, built: float) -> int:
    finished = time.perf_counter()
    observed = world.observe()
    keys = ("kind", "step", "node_id", "action", "args", "evidence", "message")
    out.update({
        "status": status,
        "ticks": ticks,
        "sim_steps": world.sim.steps,
        "build_seconds": round(built - started, 3),
        "run_seconds": round(finished - built, 3),
        "plan": plan,
        "failures": [{key: f.get(key) for key in keys} for f in failures],
        "objects": observed["objects"],
        "attachments": observed["attachments"],
        "held": observed["held"],
        "symbolic_state": [list(atom) for atom in sorted(world.symbolic_state())],
        "skills": world.executed,
    })
    if args.json:
        print_json(out)
    else:
        print(f"{status} after {ticks} ticks ({world.sim.steps} physics steps; built in {out['build_seconds']} s, "
              f"ran in {out['run_seconds']} s), {len(failures)} failure(s)")
        for failure in failures:
            print(f"  [{failure['kind']}] {failure.get('node_id') or ''} {failure.get('action') or ''}"
                  f"{tuple(failure.get('args') or ())}: {failure['message']}")
        for name, state in observed["objects"].items():
            pose = ", ".join(f"{v:.3f}" for v in state["pose"][:3])
            print(f"  {name:<10} at ({pose})" + (f" held by {state['held_by']}" if state["held_by"] else "")
                  + (f" joined to {', '.join(state['attached_to'])}" if state["attached_to"] else ""))
    return 0 if status == "SUCCESS" else 1


__all__ = ["register", "run"]
