"""Command-line options shared by every command that builds a simulated world.

Offers:

* :func:`add_world_arguments` -- ``--robot NAME|FILE`` and ``--scene FILE``
* :func:`world_options` -- the keyword arguments those options give
  :class:`~bt_meta.world.simulation.sim_world.SimWorld`
* :func:`add_ros2_arguments` -- ``--world sim|ros2`` and ``--ros2 CONFIG.yaml`` (commands that can act through ROS 2)
* :func:`world_factory` -- the world class those options choose (a RosWorld with its config, or the SimWorld)
"""

from __future__ import annotations

import argparse
import functools
from typing import Any

from bt_meta.errors import UserInputError


def add_world_arguments(parser: argparse.ArgumentParser) -> None:
    from bt_meta.resources import robots_dir

    shipped = ", ".join(sorted(path.stem for path in robots_dir().glob("*.yaml")))
    parser.add_argument("--robot", help=f"robot to run on: a shipped name ({shipped}) or a robot description "
                                        "YAML file (default: the grounding file's `robot:`, else baxter)")
    parser.add_argument("--scene", help="scene file (or shipped scene name) to build instead of the one the "
                                        "grounding file names for the problem")


def world_options(args: argparse.Namespace) -> dict[str, Any]:
    """``robot`` and ``scene`` for the SimWorld, loaded here so a bad name or file is reported before anything is
    built."""
    from bt_meta.world.robot.description import load_robot
    from bt_meta.world.simulation.scenes import load_scene

    robot = getattr(args, "robot", None)
    scene = getattr(args, "scene", None)
    if scene:
        load_scene(scene)
    return {"robot": load_robot(robot) if robot else None, "scene": scene or None}


def add_ros2_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", choices=("sim", "ros2"), default="sim",
                        help="sim: the in-process pybullet simulator (default); ros2: a robot (or `bt-meta sim serve "
                             "--ros2`) reached through ROS 2, needs pip install 'bt-meta[ros2]' (docs/ros2.md)")
    parser.add_argument("--ros2", metavar="CONFIG.yaml", dest="ros2_config",
                        help="with --world ros2: controllers, joints, topics and frames (default: what `bt-meta sim "
                             "serve --ros2` uses for the same robot)")


def world_factory(args: argparse.Namespace) -> Any:
    """The SimWorld class, or the RosWorld with ``--ros2``'s config bound, as ``--world`` says."""
    world = getattr(args, "world", "sim")
    if getattr(args, "ros2_config", None) and world != "ros2":
        raise UserInputError("--ros2 CONFIG needs --world ros2", "--ros2")
    if getattr(args, "record_mcap", None) and world != "ros2":
        raise UserInputError("--record-mcap records the ROS 2 messages of a run: it needs --world ros2",
                             "--record-mcap")
    if world != "ros2":
        from bt_meta.world.simulation.sim_world import SimWorld

        return SimWorld
    if getattr(args, "gui", False):
        raise UserInputError("--gui shows the in-process simulator; with --world ros2 watch the robot (or RViz)",
                             "--gui")
    from bt_meta.ros2.world import RosWorld

    return functools.partial(RosWorld, ros2_config=args.ros2_config, record_mcap=getattr(args, "record_mcap", None))
