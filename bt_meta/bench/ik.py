"""``bt-meta bench ik``: bt-meta's collision-aware mink IK against pybullet's IK, same targets, same run.

Targets are reachable by construction: the forward kinematics of random collision-free configurations of one
arm (seeded; every other joint at home). Both solvers start from the home pose and must bring the end effector
within the same tolerance (0.1 mm and 0.001 rad by default), verified with Pinocchio forward kinematics.

* bt-meta: :class:`~bt_meta.world.kinematics.ik.InverseKinematics` (mink frame task, joint limits, restarts, stall
  detection), which rejects colliding solutions; every solution it returns is checked again here for collisions
  (robot against itself, SRDF pairs removed), limits and accuracy.
* pybullet: ``calculateInverseKinematics`` in a DIRECT client (damped least squares, joint damping 0.01), called
  repeatedly from its own last answer (clamped to the joint limits) until the pose is within tolerance or
  ``--pybullet-calls`` calls were made. It knows nothing of collisions, so its successes are split into
  collision-free and colliding.

The published anchor is TRAC-IK on Baxter's arm: 99.62 % success, 0.43 ms mean (C++, no collision checking;
Beeson and Ames, 2015). It is quoted, not measured.

Offers:

* :func:`register` -- adds ``bt-meta bench ik [--n N] [--seed S] [--robot R] [--arm A] [--json]
  [--pybullet-calls K]``
* :func:`make_targets` -- seeded reachable targets
* :func:`run_benchmark` -- the JSON-able report ``--json`` prints
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from bt_meta.commands._common import print_json
from bt_meta.errors import UserInputError
from bt_meta.world.kinematics.collision import CollisionChecker
from bt_meta.world.kinematics.forward import Kinematics
from bt_meta.world.kinematics.ik import InverseKinematics
from bt_meta.world.kinematics.mujoco_model import mujoco_urdf_text
from bt_meta.world.robot.description import RobotDescription, available_robots, load_robot

GOAL_SUCCESS = 0.999
GOAL_MEAN_S = 1e-3
TRAC_IK = {"name": "TRAC-IK (published, Baxter arm, C++, no collisions)", "success": 0.9962, "mean_ms": 0.43}
PYBULLET_DAMPING = 0.01
PYBULLET_INNER_ITERATIONS = 20


def make_targets(
    kinematics: Kinematics, collision: CollisionChecker, arm: str, n: int, seed: int
) -> tuple[list[pin.SE3], int]:
    """``n`` end-effector poses of random collision-free arm configurations, and how many draws collided."""
    rng = np.random.default_rng(seed)
    targets: list[pin.SE3] = []
    rejected = 0
    while len(targets) < n:
        q = kinematics.random_q(rng, arm)
        if collision.check(q) is not None:
            rejected += 1
            continue
        targets.append(kinematics.end_effector_pose(q, arm))
    return targets, rejected


def _stats(times: list[float]) -> dict[str, float | None]:
    if not times:
        return {"mean_ms": None, "median_ms": None, "p95_ms": None, "max_ms": None}
    array = np.asarray(times) * 1e3
    return {
        "mean_ms": float(array.mean()),
        "median_ms": float(np.median(array)),
        "p95_ms": float(np.percentile(array, 95)),
        "max_ms": float(array.max()),
    }


class _TimedChecks:
    """Counts and times the collision checks the IK makes, to say where a solve's time goes."""

    def __init__(self, collision: CollisionChecker) -> None:
        self.collision = collision
        self.calls = 0
        self.seconds = 0.0

    def __enter__(self) -> _TimedChecks:
        original = self.collision.check

        def timed(q: np.ndarray, **kwargs: Any) -> Any:
            started = time.perf_counter()
            try:
                return original(q, **kwargs)
            finally:
                self.seconds += time.perf_counter() - started
                self.calls += 1

        self.collision.check = timed  # type: ignore[method-assign]
        return self

    def __exit__(self, *exc: object) -> None:
        del self.collision.check  # back to the class's method


def _run_ours(
    kinematics: Kinematics, collision: CollisionChecker, arm: str, targets: list[pin.SE3], seed: int
) -> dict[str, Any]:
    ik = InverseKinematics(kinematics, collision)
    settings = ik.settings
    frame = kinematics.end_effector(arm)
    ik.solve(arm, kinematics.end_effector_pose(kinematics.home, arm))  # warm-up: builds the MuJoCo arm model
    times: list[float] = []
    cpu_times: list[float] = []
    results = []
    with _TimedChecks(collision) as checks:
        for i, target in enumerate(targets):
            started, started_cpu = time.perf_counter(), time.process_time()
            result = ik.solve(arm, target, kinematics.home, seed=seed + i)
            times.append(time.perf_counter() - started)
            cpu_times.append(time.process_time() - started_cpu)
            results.append(result)
    successes = 0
    failures: Counter[str] = Counter()
    violations: list[str] = []
    examples: list[dict[str, Any]] = []
    for i, (target, result) in enumerate(zip(targets, results, strict=True)):
        if not result.success:
            failures[result.kind or "unknown"] += 1
            if len(examples) < 5:
                examples.append({"target": i, "kind": result.kind, "message": result.message})
            continue
        assert result.q is not None
        # Checked again independently of the solver: Pinocchio FK, and every pair without the broad phase.
        position, rotation = kinematics.pose_error(kinematics.frame_pose(result.q, frame), target)
        contacts = collision.all_contacts(result.q)
        problems = []
        if position > settings.position_tolerance or rotation > settings.orientation_tolerance:
            problems.append(f"off target by {position * 1000:.4f} mm / {rotation:.5f} rad")
        if contacts:
            problems.append(f"collides: {contacts[0]}")
        if not kinematics.within_limits(result.q):
            problems.append("outside the joint limits")
        if problems:
            violations.append(f"target {i}: " + "; ".join(problems))
            continue
        successes += 1
    n = len(targets)
    total = sum(times)
    steps = sum(r.iterations for r in results)
    return {
        "solver": "bt-meta mink IK (collision-aware)",
        "success": successes / n,
        "successes": successes,
        "failures": dict(failures),
        "returned_but_invalid": violations,
        "every_returned_solution_collision_free": not any("collides" in v for v in violations),
        "mean_iterations": steps / n,
        "mean_attempts": float(np.mean([r.attempts for r in results])),
        "first_attempt_solved": sum(r.success and r.attempts == 1 for r in results) / n,
        "escaped_collisions": sum(bool(r.evidence.get("escaped_collision")) for r in results),
        "rejected_colliding_solutions": sum(int(r.evidence.get("rejected_colliding", 0)) for r in results),
        "time_split": {
            "collision_checks_per_solve": checks.calls / n,
            "collision_share": checks.seconds / total if total else 0.0,
            "collision_us_per_check": checks.seconds / checks.calls * 1e6 if checks.calls else None,
            "us_per_ik_step_incl_overhead": (total - checks.seconds) / steps * 1e6 if steps else None,
        },
        "cpu_mean_ms": float(np.mean(cpu_times) * 1e3),
        "failure_examples": examples,
        **_stats(times),
    }


@contextlib.contextmanager
def _quiet_output() -> Iterator[None]:
    """Silence what the pybullet C library prints on file descriptors 1 and 2 (build time, URDF warnings)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)


def _run_pybullet(
    robot: RobotDescription,
    kinematics: Kinematics,
    collision: CollisionChecker,
    arm: str,
    targets: list[pin.SE3],
    max_calls: int,
) -> dict[str, Any]:
    with _quiet_output():
        import pybullet  # prints its build time on first import

    settings = kinematics.robot.ik
    frame = kinematics.end_effector(arm)
    with tempfile.TemporaryDirectory() as folder, _quiet_output():
        urdf = Path(folder) / f"{robot.name}.urdf"
        urdf.write_text(mujoco_urdf_text(kinematics), encoding="utf-8")  # meshes stripped: kinematics only
        client = pybullet.connect(pybullet.DIRECT)
        body = pybullet.loadURDF(str(urdf), useFixedBase=True, physicsClientId=client)
    try:
        link_of: dict[str, int] = {}
        dof_names: list[str] = []
        for j in range(pybullet.getNumJoints(body, physicsClientId=client)):
            info = pybullet.getJointInfo(body, j, physicsClientId=client)
            link_of[info[12].decode()] = j
            if info[2] != pybullet.JOINT_FIXED:
                dof_names.append(info[1].decode())
        ee_link = link_of[frame]
        pin_of_dof = np.array([kinematics.q_index(name) for name in dof_names])
        arm_dofs = np.array([dof_names.index(name) for name in robot.arm(arm).joints])
        lower = kinematics.lower[pin_of_dof]
        upper = kinematics.upper[pin_of_dof]
        home_dofs = kinematics.home[pin_of_dof]
        damping = [PYBULLET_DAMPING] * len(dof_names)
        times: list[float] = []
        calls_used: list[int] = []
        successes = 0
        colliding = 0
        for target in targets:
            position = target.translation.tolist()
            quaternion = pin.Quaternion(target.rotation).coeffs().tolist()  # x, y, z, w: pybullet's order
            current = home_dofs.copy()
            started = time.perf_counter()
            solved = False
            calls = 0
            q = kinematics.home.copy()
            for calls in range(1, max_calls + 1):  # noqa: B007 - the count is recorded below
                answer = pybullet.calculateInverseKinematics(
                    body,
                    ee_link,
                    position,
                    quaternion,
                    jointDamping=damping,
                    solver=pybullet.IK_DLS,
                    currentPositions=current.tolist(),
                    maxNumIterations=PYBULLET_INNER_ITERATIONS,
                    residualThreshold=settings.position_tolerance / 10,
                    physicsClientId=client,
                )
                proposal = home_dofs.copy()
                proposal[arm_dofs] = np.asarray(answer)[arm_dofs]
                current = np.clip(proposal, lower, upper)
                q[pin_of_dof] = current
                position_error, rotation_error = kinematics.pose_error(kinematics.frame_pose(q, frame), target)
                if position_error <= settings.position_tolerance and rotation_error <= settings.orientation_tolerance:
                    solved = True
                    break
            times.append(time.perf_counter() - started)
            calls_used.append(calls)
            if solved:
                successes += 1
                if collision.check(q) is not None:
                    colliding += 1
    finally:
        pybullet.disconnect(physicsClientId=client)
    n = len(targets)
    return {
        "solver": f"pybullet.calculateInverseKinematics (DLS, damping {PYBULLET_DAMPING}, "
        f"{PYBULLET_INNER_ITERATIONS} inner iterations per call, up to {max_calls} calls)",
        "success": successes / n,
        "successes": successes,
        "success_collision_free": (successes - colliding) / n,
        "successes_colliding": colliding,
        "mean_calls": float(np.mean(calls_used)),
        **_stats(times),
    }


def run_benchmark(
    n: int, seed: int, arm: str | None, pybullet_calls: int, robot_name: str = "baxter"
) -> dict[str, Any]:
    robot = load_robot(robot_name)
    arm = arm or robot.default_arm
    if arm not in robot.arms:
        raise UserInputError(f"--arm: robot {robot.name!r} has no arm {arm!r}; arms: {', '.join(robot.arms)}")
    kinematics = Kinematics(robot)
    collision = CollisionChecker(kinematics)
    started = time.perf_counter()
    targets, rejected = make_targets(kinematics, collision, arm, n, seed)
    targets_time = time.perf_counter() - started
    ours = _run_ours(kinematics, collision, arm, targets, seed)
    baseline = _run_pybullet(robot, kinematics, collision, arm, targets, pybullet_calls)
    settings = robot.ik
    goal_met = ours["success"] >= GOAL_SUCCESS and ours["mean_ms"] is not None and ours["mean_ms"] <= GOAL_MEAN_S * 1e3
    return {
        "benchmark": "ik",
        "robot": robot.name,
        "arm": arm,
        "n": n,
        "seed": seed,
        "tolerance": {"position_m": settings.position_tolerance, "orientation_rad": settings.orientation_tolerance},
        "targets": {"collision_free_draws": n, "colliding_draws_rejected": rejected, "seconds": targets_time},
        "ours": ours,
        "pybullet": baseline,
        "ratio_mean_time_pybullet_over_ours": (
            baseline["mean_ms"] / ours["mean_ms"] if ours["mean_ms"] and baseline["mean_ms"] else None
        ),
        "anchor": TRAC_IK,
        "goal": {"success": GOAL_SUCCESS, "mean_ms": GOAL_MEAN_S * 1e3, "met": bool(goal_met)},
        "machine": {"python": platform.python_version(), "processor": platform.machine(), "cpus": os.cpu_count()},
    }


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _print_table(report: dict[str, Any]) -> None:
    ours, base = report["ours"], report["pybullet"]
    tol = report["tolerance"]
    print(
        f"IK benchmark: {report['robot']} {report['arm']} arm, {report['n']} reachable targets "
        f"(seed {report['seed']}), tolerance {tol['position_m'] * 1000:g} mm / {tol['orientation_rad']:g} rad"
    )
    print(
        f"  targets: FK of collision-free random configurations ({report['targets']['colliding_draws_rejected']} "
        "colliding draws rejected)"
    )
    header = f"  {'solver':<34} {'success':>9} {'mean ms':>9} {'median':>9} {'p95':>9} {'max':>9}"
    print(header)
    for name, row in (("bt-meta mink IK (collision-aware)", ours), ("pybullet DLS (repeated calls)", base)):
        print(
            f"  {name:<34} {row['success'] * 100:>8.2f}% {_fmt(row['mean_ms']):>9} {_fmt(row['median_ms']):>9} "
            f"{_fmt(row['p95_ms']):>9} {_fmt(row['max_ms']):>9}"
        )
    anchor = report["anchor"]
    print(f"  {'TRAC-IK (published, no collisions)':<34} {anchor['success'] * 100:>8.2f}% {anchor['mean_ms']:>9.3f}")
    print(
        f"  bt-meta: {ours['mean_iterations']:.1f} IK steps and {ours['mean_attempts']:.2f} attempts per solve; "
        f"failures {ours['failures'] or 'none'}; every returned solution collision-free: "
        f"{'yes' if ours['every_returned_solution_collision_free'] else 'NO'}"
        + (f"; invalid returned solutions: {len(ours['returned_but_invalid'])}" if ours["returned_but_invalid"] else "")
    )
    split = ours["time_split"]
    print(
        f"  bt-meta time: {ours['first_attempt_solved'] * 100:.1f}% solved by the first attempt (from home); "
        f"{split['collision_checks_per_solve']:.2f} collision checks per solve "
        f"({_fmt(split['collision_us_per_check'], 0)} us each, {split['collision_share'] * 100:.0f}% of the time); "
        f"{_fmt(split['us_per_ik_step_incl_overhead'], 1)} us per IK step (incl. per-solve overhead); "
        f"CPU mean {ours['cpu_mean_ms']:.3f} ms; {ours['rejected_colliding_solutions']} colliding solutions rejected, "
        f"{ours['escaped_collisions']} escaped along the self-motion"
    )
    print(
        f"  pybullet: {base['mean_calls']:.1f} calls per target; of its successes {base['successes_colliding']} "
        f"collide (collision-free success {base['success_collision_free'] * 100:.2f}%)"
    )
    ratio = report["ratio_mean_time_pybullet_over_ours"]
    print(f"  ratio (pybullet mean time / bt-meta mean time): {_fmt(ratio, 2)}")
    goal = report["goal"]
    print(
        f"  goal (>= {goal['success'] * 100:.1f}% success, mean <= {goal['mean_ms']:g} ms, collision-free): "
        f"{'met' if goal['met'] else 'NOT met'}"
    )


def _main(args: argparse.Namespace) -> int:
    if args.n < 1:
        raise UserInputError("--n must be at least 1")
    if args.pybullet_calls < 1:
        raise UserInputError("--pybullet-calls must be at least 1")
    report = run_benchmark(args.n, args.seed, args.arm, args.pybullet_calls, args.robot)
    if args.json:
        print_json(report)
    else:
        _print_table(report)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("ik", help="collision-aware mink IK against pybullet IK on random reachable targets")
    parser.add_argument("--n", type=int, default=10_000, help="number of targets (default 10000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the targets and of the IK restarts")
    parser.add_argument("--robot", default="baxter",
                        help=f"robot: a shipped name ({', '.join(available_robots())}) or a robot description "
                             "YAML file (default baxter)")
    parser.add_argument("--arm", help="arm to solve for (default: the robot's first, the Baxter's right)")
    parser.add_argument(
        "--pybullet-calls", type=int, default=50, help="cap on repeated pybullet IK calls per target (default 50)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    parser.set_defaults(func=_main)
