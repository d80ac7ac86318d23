"""``bt-meta experiment keypoints``: Tables 2 and 3 of the paper (section 7.5) in the pybullet simulator.

The MagneticAttach plan (``trees/magnetic_attach.yaml``, problem ``attach_only``: pick the active part from
above, carry it onto the reference part, release) is run tick by tick with its real skills (IK, joint
trajectories, the robot's grasp, the simulator's magnetic attach rule) on
:class:`~bt_meta.world.simulation.sim_world.SimWorld`.
The keypoint relations of the two parts are read from the simulator's object states (AP and AN in the robot base
frame) at two moments: before any motion (``start``) and after the attach motion (``end``):
``R_p = |AP(active) - AP(reference)|``, ``R_n = arccos(AN(active) . AN(reference))``.

* **Table 2** -- the same object in different poses: ``traces`` nominal runs (the active part upright, its start
  pose jittered by a few millimetres and degrees with the seed, as an instructor's demonstrations vary) give the
  expectation, the means Exp_p, Exp_n; two variant poses of the same part (the scene's ``active_on_side`` and
  ``active_upside_down``) run the same nominal plan.
* **Table 3** -- a second object whose attachment normal lies on another axis of its frame: a 6 x 4 x 4 cm part
  with its magnet on the -x face (object 1's is on -z). Its nominal pose stands it on that face (pitch -90
  degrees, magnet down), its variant lies flat (magnet sideways). Both are compared with object 1's expectation:
  because AN is modelled per object, R_n of object 2's nominal matches object 1's, and its variant does not.

For every case the output gives R_p and R_n, their distance to the expectation, whether each relation is within
its tolerance (1 cm, 15 degrees: the attach rule's) and the ground truth of success (the parts are joined), and
says which relation separates nominal from failing states at each moment.

Offers:

The active part starts where the scene puts it (``active`` in ``trees/scenes/magnetic_attach.yaml``, placed in the
robot's base frame by its workcell offset), so ``--robot panda`` runs the same experiment on the Panda and
``--scene FILE`` on a scene of one's own with an ``active`` and a ``reference`` part.

* :func:`register` -- adds ``bt-meta experiment keypoints [--traces 3] [--seed 0] [--robot R] [--scene FILE]
  [--json]``
* :func:`run` -- the experiment, returning the tables as a dict
* :func:`side_magnet_part` -- object 2's model
"""

from __future__ import annotations

import argparse
import functools
import math
from typing import Any

import numpy as np

from bt_meta.commands._common import print_json
from bt_meta.commands._world_args import add_world_arguments, world_options
from bt_meta.errors import UserInputError
from bt_meta.world.simulation.objects import ObjectModel

POSITION_TOLERANCE = 0.01
ANGLE_TOLERANCE = math.radians(15.0)
JITTER_POSITION = 0.004
JITTER_YAW = math.radians(3.0)
MAX_TICKS = 3000


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("keypoints", help="Tables 2 and 3: R_p and R_n for nominal and variant poses")
    parser.add_argument("--traces", type=int, default=3, help="nominal traces averaged into the expectation")
    parser.add_argument("--seed", type=int, default=0, help="seed of the nominal traces' start-pose jitter")
    add_world_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if not 1 <= args.traces <= 20:
        raise UserInputError("--traces must be between 1 and 20", path="<command line>")
    options = world_options(args)
    if options["scene"] is not None:
        from bt_meta.world.simulation.scenes import load_scene

        scene = load_scene(options["scene"])
        names = {o.name for o in scene.objects}
        missing = sorted({"active", "reference"} - names)
        if missing:
            raise UserInputError(f"scene {scene.name!r} has no object {' or '.join(map(repr, missing))}: the "
                                 "experiment measures the relation of an `active` and a `reference` part",
                                 path=scene.path)
    result = run(traces=args.traces, seed=args.seed, **options)
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0


def side_magnet_part(colour: str = "orange") -> ObjectModel:
    """Object 2: a 6 x 4 x 4 cm active part whose magnet is on its -x face (normal -x in its own frame), the
    object catalogue's ``magnet_active_side``."""
    from bt_meta.world.simulation.catalogue import shipped_catalogue

    return shipped_catalogue()["magnet_active_side"].model(colour)


def _relation(sim: Any) -> dict[str, float]:
    from bt_meta.perception.keypoints import relation

    states = sim.object_states()
    r = relation(states["active"], states["reference"])
    return {"r_p": r.r_p, "r_n": r.r_n}


def attach_case(*, model: ObjectModel | None = None, rpy: tuple[float, float, float] = (0.0, 0.0, 0.0),
                offset: tuple[float, float] = (0.0, 0.0), seed: int = 0, robot: Any = None,
                scene: Any = None) -> dict[str, Any]:
    """Run ``attach_only`` with the active part (``model``, default the scene's) resting at its start position in
    the scene (+ ``offset``) turned by ``rpy``; the relation at the start and after the attach motion, and the
    outcome. ``robot`` and ``scene`` as for :class:`~bt_meta.world.simulation.sim_world.SimWorld`."""
    from py_trees.common import Status

    from bt_meta.plugins import create_plugin_host
    from bt_meta.resources import trees_dir
    from bt_meta.testing import TreeHarness
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    path = trees_dir() / "magnetic_attach.yaml"
    with quiet_stdout():
        world = SimWorld.from_task_file(path, "attach_only", seed=seed, robot=robot, scene=scene)
    try:
        sim = world.sim
        start_x, start_y = sim.object_pose("active")[:2]  # where the scene puts it, in this robot's base frame
        if model is not None:
            sim.remove("active")
            world.sync_collision()
        else:
            model = sim.object_model("active")
        pose = sim.resting_pose(model, (start_x + offset[0], start_y + offset[1], 0.0, *rpy))
        if "active" in sim.object_names():
            sim.move_object("active", pose)
        else:
            sim.spawn("active", model, pose)
        sim.settle(120)
        world.sync_collision()
        start = _relation(sim)
        harness = TreeHarness.from_file(path, "attach_only", world=world,
                                        plugins=create_plugin_host(entry_points=False))
        status, ticks = Status.RUNNING, 0
        while status is Status.RUNNING and ticks < MAX_TICKS:
            status = harness.run.tick(harness.root)
            ticks += 1
        end = _relation(sim)
        return {
            "start": start,
            "end": end,
            "attached": ("active", "reference") in sim.attachments(),
            "plan_status": status.value,
            "ticks": ticks,
            "failures": [f.get("message") for f in harness.run.failure_records],
            "active_pose": [float(v) for v in pose],
        }
    finally:
        world.close()


def _judge(relation: dict[str, float], expected: dict[str, float]) -> dict[str, Any]:
    dp = abs(relation["r_p"] - expected["r_p"])
    dn = abs(relation["r_n"] - expected["r_n"])
    return {"delta_p": dp, "delta_n": dn, "p_ok": dp <= POSITION_TOLERANCE, "n_ok": dn <= ANGLE_TOLERANCE}


def _mean(cases: list[dict[str, Any]], moment: str) -> dict[str, float]:
    p = np.array([c[moment]["r_p"] for c in cases])
    n = np.array([c[moment]["r_n"] for c in cases])
    return {"r_p": float(p.mean()), "r_n": float(n.mean()), "r_p_std": float(p.std()), "r_n_std": float(n.std())}


def _separation(nominal: list[dict[str, Any]], failing: list[dict[str, Any]], moment: str) -> dict[str, bool]:
    """A relation separates when every nominal case is within its tolerance and every failing one outside."""
    return {
        rel: all(c["judged"][moment][f"{rel}_ok"] for c in nominal)
        and all(not c["judged"][moment][f"{rel}_ok"] for c in failing)
        for rel in ("p", "n")
    }


def run(*, traces: int = 3, seed: int = 0, robot: Any = None, scene: Any = None) -> dict[str, Any]:
    """Tables 2 and 3 (see the module docstring) on ``robot`` (default the grounding's) in ``scene`` (default
    the magnetic-attach scene)."""
    case_of = functools.partial(attach_case, robot=robot, scene=scene)
    rng = np.random.default_rng(seed)
    nominal = []
    for j in range(traces):
        dx, dy = rng.uniform(-JITTER_POSITION, JITTER_POSITION, 2)
        yaw = float(rng.uniform(-JITTER_YAW, JITTER_YAW))
        case = case_of(rpy=(0.0, 0.0, yaw), offset=(float(dx), float(dy)), seed=seed + j)
        case["label"] = f"nominal trace {j + 1}"
        nominal.append(case)
    expected = {moment: _mean(nominal, moment) for moment in ("start", "end")}
    half = math.pi / 2.0
    table2 = [
        {"label": "object 1, on its side (active_on_side)", **case_of(rpy=(half, 0.0, 0.0), seed=seed)},
        {"label": "object 1, upside down (active_upside_down)", **case_of(rpy=(math.pi, 0.0, 0.0), seed=seed)},
    ]
    side = side_magnet_part()
    table3 = [
        {"label": "object 2, nominal (magnet down)", **case_of(model=side, rpy=(0.0, -half, 0.0), seed=seed)},
        {"label": "object 2, lying flat (magnet sideways)", **case_of(model=side, seed=seed)},
    ]
    for case in [*nominal, *table2, *table3]:
        case["judged"] = {moment: _judge(case[moment], expected[moment]) for moment in ("start", "end")}
    separation2 = {m: _separation(nominal, table2, m) for m in ("start", "end")}
    table3_nominal = [c for c in table3 if c["attached"]]
    table3_failing = [c for c in table3 if not c["attached"]]
    separation3 = {m: _separation(table3_nominal, table3_failing, m) for m in ("start", "end")}
    return {
        "method": "simulator object states (AP, AN in the robot base frame) before and after running the "
                  "attach_only plan's skills on SimWorld",
        "traces": traces,
        "seed": seed,
        "tolerances": {"r_p_m": POSITION_TOLERANCE, "r_n_rad": ANGLE_TOLERANCE},
        "expectation": expected,
        "nominal": nominal,
        "table2": table2,
        "table3": table3,
        "separates": {"table2": separation2, "table3": separation3},
    }


def _row(label: str, case: dict[str, Any], moment: str) -> str:
    r, judged = case[moment], case["judged"][moment]
    mark_p = "ok" if judged["p_ok"] else "OFF"
    mark_n = "ok" if judged["n_ok"] else "OFF"
    return (f"  {label:<44} {r['r_p'] * 1e3:8.1f} {judged['delta_p'] * 1e3:8.1f} {mark_p:>4}  "
            f"{r['r_n']:6.3f} {math.degrees(judged['delta_n']):7.1f} {mark_n:>4}  "
            f"{'joined' if case['attached'] else 'not joined':>11}")


def _print(result: dict[str, Any]) -> None:
    print(f"experiment keypoints: R_p = |AP(active) - AP(reference)|, R_n = arccos(AN(active) . AN(reference)), "
          f"from {result['method']}")
    tol = result["tolerances"]
    print(f"expectation = means over {result['traces']} nominal traces (seed {result['seed']}); tolerances "
          f"{tol['r_p_m'] * 1e3:.0f} mm, {math.degrees(tol['r_n_rad']):.0f} deg")
    header = (f"  {'case':<44} {'R_p mm':>8} {'|dR_p|':>8} {'':>4}  {'R_n rad':>6} {'|dR_n|°':>7} {'':>4}  "
              f"{'outcome':>11}")
    for moment, title in (("end", "after the attach motion"), ("start", "before any motion")):
        e = result["expectation"][moment]
        for number, key, cases in (("2", "table2", result["table2"]), ("3", "table3", result["table3"])):
            what = "same object, variant poses" if number == "2" else "object 2: attachment normal on its -x axis"
            print(f"\nTable {number} ({what}), {title}:")
            print(header)
            print(f"  {'expectation (object 1 nominal, mean)':<44} {e['r_p'] * 1e3:8.1f} {'':>8} {'':>4}  "
                  f"{e['r_n']:6.3f}")
            if number == "2":
                for case in result["nominal"]:
                    print(_row(case["label"], case, moment))
            for case in cases:
                print(_row(case["label"], case, moment))
            sep = result["separates"][key][moment]
            names = [name for name, ok in (("R_p", sep["p"]), ("R_n", sep["n"])) if ok] or ["neither"]
            print(f"  separates nominal from failing: {', '.join(names)}")
