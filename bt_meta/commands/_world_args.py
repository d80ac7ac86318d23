"""Command-line options shared by every command that builds a simulated world.

Offers:

* :func:`add_world_arguments` -- ``--robot NAME|FILE``
* :func:`world_options` -- the keyword arguments those options give
  :class:`~bt_meta.world.simulation.sim_world.SimWorld`
"""

from __future__ import annotations

import argparse
from typing import Any


def add_world_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", help="robot to run on: a shipped name (baxter, panda) or a robot description "
                                        "YAML file (default: the grounding file's `robot:`, else baxter)")


def world_options(args: argparse.Namespace) -> dict[str, Any]:
    """``robot`` for the SimWorld (loaded here so a bad name or file is reported before anything is built)."""
    from bt_meta.world.robot.description import load_robot

    robot = getattr(args, "robot", None)
    return {"robot": load_robot(robot) if robot else None}
