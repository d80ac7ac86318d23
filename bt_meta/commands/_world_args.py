"""Command-line options shared by every command that builds a simulated world.

Offers:

* :func:`add_world_arguments` -- ``--robot NAME|FILE`` and ``--scene FILE``
* :func:`world_options` -- the keyword arguments those options give
  :class:`~bt_meta.world.simulation.sim_world.SimWorld`
"""

from __future__ import annotations

import argparse
from typing import Any


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
