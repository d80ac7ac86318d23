"""``bt-meta bench ros2``: what acting through ROS 2 costs against the same work in-process, measured in one run.

The served simulator (``bt-meta sim serve --ros2``) runs in a network namespace with only loopback (``unshare -n``,
localhost discovery, a domain id of its own), as the ROS tests run it; the measuring process joins that namespace
(``nsenter --net``), so DDS never leaves the machine. Two figures, each with its in-process baseline:

* **tick**: the MoveTo tick's robot round trip -- ``drive_arm`` then ``advance(1)`` -- repeated ``--ticks`` times
  on the problem's world, in-process (``SimWorld``: the physics) and through ROS 2 (``RosWorld``: one
  FollowJointTrajectory goal, its result and the fresh joint states and object poses); the overhead per tick.
* **episode**: ``bt-meta run FILE --problem P`` as a fresh process both ways (the served simulator fresh too):
  simulated seconds / wall seconds, and the ROS 2 figure as a ratio of the in-process one.

Needs the ``[ros2]`` extra, ``unshare``/``nsenter``/``ip`` and the right to make a network namespace (root).

Offers:

* :func:`register` -- ``bench ros2 [--file F] [--problem P] [--ticks N] [--repeat N] [--json]``
* :func:`run` -- the figures as a dict
* :func:`tick_child` -- the timed ticks of one process (``python -m bt_meta.bench.ros2 FILE PROBLEM TICKS``)
* :class:`Served`, :func:`check_namespaces` -- the served simulator in a loopback-only namespace (also used by
  ``bt-meta experiment ros2-compare``)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bt_meta.commands._common import print_json
from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["Served", "check_namespaces", "register", "run", "tick_child"]

BT_META = [sys.executable, "-m", "bt_meta.cli"]
_AMPLITUDE = 0.05
"""rad: the first joint of the arm swings this much around its start value during the timed ticks."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("ros2", help="a tick's round trip and an episode through ROS 2 vs in-process")
    parser.add_argument("--file", default=None, help="task file (default: the shipped trees/letters.yaml)")
    parser.add_argument("--problem", default="A", help="problem of the task file (default A)")
    parser.add_argument("--ticks", type=int, default=200, help="timed ticks each way (10-5000, default 200)")
    parser.add_argument("--repeat", type=int, default=1, help="episodes each way (1-10, default 1)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if not 10 <= args.ticks <= 5000:
        raise UserInputError("--ticks must be between 10 and 5000", "--ticks")
    if not 1 <= args.repeat <= 10:
        raise UserInputError("--repeat must be between 1 and 10", "--repeat")
    result = run(args.file, args.problem, ticks=args.ticks, repeat=args.repeat)
    if args.json:
        print_json(result)
    else:
        _print(result)
    return 0


def _serve_arguments(file: str, problem: str) -> list[str]:
    """``sim serve`` options building what ``bt-meta run FILE --problem P`` builds (scene, variant, start pose)."""
    from bt_meta.htn import load_task_file
    from bt_meta.world.simulation.sim_world import load_grounding

    task_file = load_task_file(file)
    task_file.problem(problem)  # an unknown name lists the known ones (exit 2)
    grounding = load_grounding(task_file.domain.name, file, None)
    setup = grounding.problem(problem)
    robot = str(setup.get("robot") or "baxter")
    out = ["--robot", robot, "--scene", str(setup["scene"])]
    if setup.get("variant"):
        out += ["--variant", str(setup["variant"])]
    for joint, value in grounding.start_pose(robot).items():
        out += ["--joint", f"{joint}={value}"]
    return out


def check_namespaces(what: str = "bench ros2") -> None:
    from bt_meta.ros2.environment import import_rclpy

    import_rclpy()  # Ros2Unavailable names the extra
    for tool in ("unshare", "nsenter", "ip"):
        if shutil.which(tool) is None:
            raise BtMetaError(f"{what} needs {tool} (util-linux, iproute2): the served simulator runs in a "
                              "loopback-only network namespace")
    if subprocess.run(["unshare", "-n", "true"], capture_output=True, check=False).returncode != 0:
        raise BtMetaError(f"{what} cannot create a network namespace here (unshare -n needs root)")


class Served:
    """``sim serve --ros2`` in a fresh loopback-only namespace; ``command()`` runs a command inside it."""

    def __init__(self, serve_args: list[str], domain: int, log: Path) -> None:
        self.env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        self.env.pop("ROS_STATIC_PEERS", None)
        self.log = log
        # the camera on (its default rate): the world's perception looks through it
        script = "ip link set lo up && exec " + shlex.join([*BT_META, "sim", "serve", "--ros2", *serve_args])
        with open(log, "w") as err:
            self.process = subprocess.Popen(["unshare", "-n", "sh", "-c", script], env=self.env,
                                            stdout=subprocess.DEVNULL, stderr=err)
        deadline = time.monotonic() + 300  # a first start generates control_msgs
        while "ready" not in log.read_text():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise BtMetaError(f"sim serve did not start: {log.read_text()[-1000:]}")
            time.sleep(0.1)

    def command(self, *argv: str) -> list[str]:
        return ["nsenter", f"--net=/proc/{self.process.pid}/ns/net", *argv]

    def stop(self) -> int | None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode


def _checked(done: subprocess.CompletedProcess, what: str) -> dict[str, Any]:
    if done.returncode != 0:
        raise BtMetaError(f"{what} ended with status {done.returncode}: {done.stderr.strip()[-1000:]}")
    return json.loads(done.stdout)


def run(file: str | None, problem: str, *, ticks: int = 200, repeat: int = 1) -> dict[str, Any]:
    from bt_meta.resources import shipped_tree

    file = str(file or shipped_tree("letters.yaml"))
    serve_args = _serve_arguments(file, problem)
    check_namespaces()
    domain = 100 + os.getpid() % 100
    episode = [*BT_META, "run", file, "--problem", problem, "--json"]
    tick = [sys.executable, "-m", "bt_meta.bench.ros2", file, problem, str(ticks)]
    result: dict[str, Any] = {"file": file, "problem": problem, "ticks": ticks, "repeat": repeat}
    with tempfile.TemporaryDirectory(prefix="bt-meta-bench-ros2-") as folder:
        served = Served(serve_args, domain, Path(folder) / "serve-tick.log")
        try:
            result["tick"] = _checked(subprocess.run(served.command(*tick), env=served.env, capture_output=True,
                                                     text=True, check=False), "the timed ticks")
        finally:
            served.stop()
        local, ros = [], []
        for index in range(repeat):
            local.append(_timed(episode, None, result["tick"]["tick_seconds"]))
            served = Served(serve_args, domain, Path(folder) / f"serve-{index}.log")
            try:
                ros.append(_timed([*episode, "--world", "ros2"], served, result["tick"]["tick_seconds"]))
            finally:
                served.stop()
    per_tick = result["tick"]
    per_tick["overhead_ms"] = round(per_tick["ros2_ms"] - per_tick["in_process_ms"], 3)
    per_tick["ratio"] = round(per_tick["ros2_ms"] / per_tick["in_process_ms"], 2)
    rtf_local = statistics.median(r["real_time_factor"] for r in local)
    rtf_ros = statistics.median(r["real_time_factor"] for r in ros)
    result["episode"] = {"in_process": local, "ros2": ros, "in_process_real_time_factor": rtf_local,
                         "ros2_real_time_factor": rtf_ros, "ratio": round(rtf_ros / rtf_local, 3)}
    return result


def _timed(command: list[str], served: Served | None, tick_seconds: float) -> dict[str, Any]:
    started = time.perf_counter()
    if served is None:
        done = subprocess.run(command, capture_output=True, text=True, check=False)
    else:
        done = subprocess.run(served.command(*command), env=served.env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - started
    if done.returncode not in (0, 1):
        raise BtMetaError(f"`{' '.join(command[2:])}` ended with status {done.returncode}: "
                          f"{done.stderr.strip()[-1000:]}")
    report = json.loads(done.stdout)
    simulated = float(report["ticks"]) * tick_seconds
    return {"status": report["status"], "ticks": report["ticks"], "wall_seconds": round(wall, 3),
            "real_time_factor": round(simulated / wall, 3)}


def tick_child(file: str, problem_name: str, ticks: int) -> dict[str, Any]:
    """Time ``ticks`` drive_arm + advance(1) round trips in-process, then through ROS 2 (the same targets)."""
    from bt_meta.htn import load_task_file
    from bt_meta.ros2.world import RosWorld
    from bt_meta.world.simulation.sim_world import SimWorld, load_grounding, quiet_stdout

    task_file = load_task_file(file)
    problem = task_file.problem(problem_name)
    grounding = load_grounding(task_file.domain.name, file, None)
    out: dict[str, Any] = {}
    for key, make in (("in_process_ms", SimWorld), ("ros2_ms", RosWorld)):
        with quiet_stdout():
            world = make(task_file.domain, problem, grounding)
        try:
            arm = world.default_arm
            joints = world.sim.robot.arm(arm).joints
            start = world.sim.joint_positions()
            base = [start[j] for j in joints]
            started = time.perf_counter()
            for index in range(ticks):
                target = list(base)
                target[0] += _AMPLITUDE * math.sin(2 * math.pi * index / 40)
                world.drive_arm(arm, target)
                world.advance(1)
            elapsed = time.perf_counter() - started
            out[key] = round(1000 * elapsed / ticks, 3)
            out["tick_seconds"] = world.tick_seconds
        finally:
            world.close()
    return out


def _print(result: dict[str, Any]) -> None:
    tick, episode = result["tick"], result["episode"]
    print(f"bench ros2: {result['file']} problem {result['problem']}")
    print(f"  tick round trip ({result['ticks']} ticks): in-process {tick['in_process_ms']:.2f} ms, ROS 2 "
          f"{tick['ros2_ms']:.2f} ms -- overhead {tick['overhead_ms']:.2f} ms, {tick['ratio']:.1f}x")
    for name in ("in_process", "ros2"):
        for row in episode[name]:
            print(f"  episode {name}: {row['status']} in {row['ticks']} ticks, {row['wall_seconds']:.1f} s wall, "
                  f"{row['real_time_factor']:.2f}x real time")
    print(f"  episode real-time factor through ROS 2 / in-process: {episode['ratio']:.2f}")


if __name__ == "__main__":
    print(json.dumps(tick_child(sys.argv[1], sys.argv[2], int(sys.argv[3]))))
