"""``bt-meta bench perception``: camera perception (HSV blobs on the top view) against the simulator's ground truth.

Offers:

* :func:`register` -- adds ``bt-meta bench perception [--n 40] [--blocks 6] [--seed 0] [--json]``
* :func:`run` -- the benchmark itself, returning the figures as a dict
* :func:`random_scene` -- seeded, non-overlapping red/blue 1x1/1x2 blocks inside the top camera's view

For each of ``n`` seeded scenes the pybullet simulator (headless, robot hidden from the top view) gets ``blocks``
random Mega Bloks (colour red or blue, shape 1x1 or 1x2, position and yaw uniform over the visible table, no two
closer than their circumscribed circles plus 1 cm), lets them settle, and renders one top view. Camera
perception (:func:`bt_meta.perception.topview.analyse`: HSV blobs, shape, centroid, orientation, a grid-map per
block) runs on it twice: with the depth image (top-surface points) and RGB only (pixels cast onto the blocks'
top-face plane). Each ground-truth block is matched to the nearest detection within half a block: missed and
spurious detections are counted, and for matches the centroid error (mm), orientation error (degrees, modulo
180 for a 1x2 and 90 for a 1x1) and shape and colour accuracy. Times per frame: rendering, analysis, and the
baseline measured in the same run -- reading the ground truth (``Simulation.object_states``), what the
ground-truth perception plugin costs -- with the ratio camera / ground truth.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

import numpy as np

from bt_meta.commands._common import print_json
from bt_meta.errors import UserInputError
from bt_meta.world.simulation.objects import LB

MATCH_RADIUS = 0.5 * LB
CLEARANCE = 0.01
MARGIN = 0.03


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("perception", help="camera perception (HSV blobs, grid-maps) vs ground truth")
    parser.add_argument("--n", type=int, default=40, help="random scenes (default 40)")
    parser.add_argument("--blocks", type=int, default=6, help="blocks per scene (default 6)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the scenes (default 0)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if args.n < 1 or not 1 <= args.blocks <= 20:
        raise UserInputError("--n must be >= 1 and --blocks between 1 and 20", path="<command line>")
    result = run(args.n, blocks=args.blocks, seed=args.seed)
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0


def _radius(shape: str) -> float:
    return LB * (math.sqrt(5.0) if shape == "1x2" else math.sqrt(2.0)) / 2.0


def random_scene(rng: np.random.Generator, count: int, bounds: tuple[tuple[float, float], tuple[float, float]]
                 ) -> list[tuple[str, str, float, float, float]]:
    """``count`` blocks ``(shape, colour, x, y, yaw)`` with centres inside ``bounds`` ((x0, x1), (y0, y1)) shrunk by
    each block's circumscribed radius, pairwise clear of each other."""
    placed: list[tuple[str, str, float, float, float]] = []
    for _ in range(count):
        for _attempt in range(1000):
            shape = str(rng.choice(["1x1", "1x2"]))
            colour = str(rng.choice(["red", "blue"]))
            r = _radius(shape)
            x = float(rng.uniform(bounds[0][0] + r, bounds[0][1] - r))
            y = float(rng.uniform(bounds[1][0] + r, bounds[1][1] - r))
            yaw = float(rng.uniform(-math.pi, math.pi))
            if all(math.hypot(x - px, y - py) > r + _radius(ps) + CLEARANCE for ps, _, px, py, _ in placed):
                placed.append((shape, colour, x, y, yaw))
                break
        else:
            raise UserInputError(f"cannot place {count} blocks without overlap in the view; use fewer --blocks",
                                 path="<command line>")
    return placed


def _angle_error(a: float, b: float, period: float) -> float:
    d = (a - b) % period
    return min(d, period - d)


def _score(blocks: list[Any], truth: dict[str, Any]) -> dict[str, Any]:
    """Match ground truth to detections (nearest within MATCH_RADIUS, each detection used once)."""
    used: set[int] = set()
    centroid, angle, shape_ok, colour_ok, missed = [], [], [], [], 0
    for state in truth.values():
        x, y, yaw = state.pose[0], state.pose[1], state.pose[5]
        candidates = [(math.hypot(b.centroid[0] - x, b.centroid[1] - y), i) for i, b in enumerate(blocks)
                      if i not in used]
        distance, index = min(candidates, default=(math.inf, -1))
        if distance > MATCH_RADIUS:
            missed += 1
            continue
        used.add(index)
        block = blocks[index]
        centroid.append(distance)
        period = math.pi if state.shape == "1x2" else math.pi / 2.0
        angle.append(_angle_error(block.orientation, yaw, period))
        shape_ok.append(block.shape == state.shape)
        colour_ok.append(block.colour == state.colour)
    return {"centroid": centroid, "angle": angle, "shape": shape_ok, "colour": colour_ok, "missed": missed,
            "spurious": len(blocks) - len(used)}


def _summary(scores: list[dict[str, Any]], times: list[float], truth_count: int) -> dict[str, Any]:
    centroid = np.array([e for s in scores for e in s["centroid"]]) * 1e3
    angle = np.degrees(np.array([e for s in scores for e in s["angle"]]))
    shape = [ok for s in scores for ok in s["shape"]]
    colour = [ok for s in scores for ok in s["colour"]]
    matched = len(shape)
    return {
        "blocks": truth_count,
        "found": matched,
        "missed": sum(s["missed"] for s in scores),
        "spurious": sum(s["spurious"] for s in scores),
        "centroid_error_mm": {"mean": float(centroid.mean()) if matched else None,
                              "p95": float(np.percentile(centroid, 95)) if matched else None,
                              "max": float(centroid.max()) if matched else None},
        "orientation_error_deg": {"mean": float(angle.mean()) if matched else None,
                                  "p95": float(np.percentile(angle, 95)) if matched else None},
        "shape_accuracy": sum(shape) / matched if matched else None,
        "colour_accuracy": sum(colour) / matched if matched else None,
        "analysis_ms_per_frame": {"mean": float(np.mean(times) * 1e3), "p95": float(np.percentile(times, 95) * 1e3)},
    }


def run(n: int, *, blocks: int = 6, seed: int = 0) -> dict[str, Any]:
    """Run the benchmark over ``n`` scenes of ``blocks`` blocks; returns the figures (see the module docstring)."""
    from bt_meta.perception.hsv import PlaneProjection
    from bt_meta.perception.topview import analyse
    from bt_meta.world.simulation.camera import TopViewCamera
    from bt_meta.world.simulation.objects import megablok
    from bt_meta.world.simulation.sim import Simulation
    from bt_meta.world.simulation.sim_world import quiet_stdout

    rng = np.random.default_rng(seed)
    with quiet_stdout():
        sim = Simulation(seed=seed)
    try:
        camera = TopViewCamera(sim)
        k = camera.intrinsics
        corners = [camera.pixel_to_plane(u, v) for u, v in ((0, 0), (k.width, k.height))]
        bounds = ((min(c[0] for c in corners) + MARGIN, max(c[0] for c in corners) - MARGIN),
                  (min(c[1] for c in corners) + MARGIN, max(c[1] for c in corners) - MARGIN))
        body_top = sim.table.top_z + megablok("1x1", "red").info["body_height"]
        modes: dict[str, dict[str, list[Any]]] = {"depth": {"scores": [], "times": []},
                                                 "rgb_only": {"scores": [], "times": []}}
        render_times, truth_times, total = [], [], 0
        for scene in range(n):
            sim.clear_objects()
            for i, (shape, colour, x, y, yaw) in enumerate(random_scene(rng, blocks, bounds)):
                sim.spawn(f"s{scene}_b{i}", megablok(shape, colour), (x, y, 0.0, 0.0, 0.0, yaw), on_table=True)
            sim.settle(60)
            started = time.perf_counter()
            truth = sim.object_states()
            truth_times.append(time.perf_counter() - started)
            total += len(truth)
            started = time.perf_counter()
            image = camera.capture(depth=True, segmentation=False)
            render_times.append(time.perf_counter() - started)
            for mode, depth, plane in (("depth", image.depth, sim.table.top_z), ("rgb_only", None, body_top)):
                started = time.perf_counter()
                view = analyse(image.rgb, PlaneProjection.from_image(image, plane), depth=depth)
                modes[mode]["times"].append(time.perf_counter() - started)
                modes[mode]["scores"].append(_score(view.blocks, truth))
    finally:
        sim.close()
    truth_ms = float(np.mean(truth_times) * 1e3)
    render_ms = float(np.mean(render_times) * 1e3)
    result: dict[str, Any] = {
        "scenes": n,
        "blocks_per_scene": blocks,
        "seed": seed,
        "image": f"{k.width}x{k.height}",
        "metres_per_pixel": camera.metres_per_pixel(),
        "render_ms_per_frame": render_ms,
        "baseline": {"name": "ground truth (Simulation.object_states)", "ms_per_frame": truth_ms},
    }
    for mode, data in modes.items():
        summary = _summary(data["scores"], data["times"], total)
        analysis = summary["analysis_ms_per_frame"]["mean"]
        summary["ratio_analysis_vs_ground_truth"] = analysis / truth_ms
        summary["ratio_render_plus_analysis_vs_ground_truth"] = (analysis + render_ms) / truth_ms
        result[mode] = summary
    return result


def _print(result: dict[str, Any]) -> None:
    print(f"bench perception: {result['scenes']} scenes x {result['blocks_per_scene']} random red/blue 1x1/1x2 "
          f"blocks (seed {result['seed']}), top view {result['image']} at "
          f"{result['metres_per_pixel'] * 1e3:.2f} mm/pixel")
    baseline = result["baseline"]
    for mode, title in (("depth", "camera perception, RGB-D (top-surface points)"),
                        ("rgb_only", "camera perception, RGB only (pixels on the top-face plane)")):
        s = result[mode]
        c, o = s["centroid_error_mm"], s["orientation_error_deg"]
        print(f"  {title}:")
        print(f"    found {s['found']}/{s['blocks']} blocks, {s['missed']} missed, {s['spurious']} spurious; "
              f"shape accuracy {s['shape_accuracy']:.1%}, colour accuracy {s['colour_accuracy']:.1%}")
        print(f"    centroid error mean {c['mean']:.2f} mm, p95 {c['p95']:.2f} mm, max {c['max']:.2f} mm; "
              f"orientation error mean {o['mean']:.2f} deg, p95 {o['p95']:.2f} deg")
        print(f"    analysis {s['analysis_ms_per_frame']['mean']:.2f} ms/frame (p95 "
              f"{s['analysis_ms_per_frame']['p95']:.2f}) + render {result['render_ms_per_frame']:.1f} ms; "
              f"vs {baseline['name']} {baseline['ms_per_frame']:.3f} ms/frame: analysis "
              f"{s['ratio_analysis_vs_ground_truth']:.0f}x, render + analysis "
              f"{s['ratio_render_plus_analysis_vs_ground_truth']:.0f}x the ground-truth cost")
