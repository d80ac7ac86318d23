"""``bt-meta sim serve --ros2``: the pybullet simulator served over ROS 2, to prove the ROS 2 world against.

``bt-meta sim serve --ros2 --robot R --scene S [--variant V] [--seed K] [--joint NAME=VALUE ...] [--ros2 CONFIG]``
builds the scene as ``bt-meta run`` would and serves it (:mod:`bt_meta.ros2.sim_server`): ``/joint_states``,
``/<controller>/follow_joint_trajectory`` per arm, GripperCommand per gripper, the top-view camera and the
ground-truth object poses (simulation only). Discovery stays on localhost unless the environment sets
``ROS_AUTOMATIC_DISCOVERY_RANGE``. It prints one ``ready`` line on stderr once serving and ends with status 0 on
Ctrl-C or SIGTERM. See docs/ros2.md.

Offers:

* :func:`register` -- adds ``sim serve``
"""

from __future__ import annotations

import argparse
import contextlib
import sys

from bt_meta.errors import UserInputError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("sim", help="serve the simulator to other processes (over ROS 2)")
    commands = parser.add_subparsers(dest="sim_command", metavar="COMMAND")
    serve = commands.add_parser("serve", help="serve a robot in a scene over ROS 2 until Ctrl-C or SIGTERM")
    serve.add_argument("--ros2", action="store_true", required=True,
                       help="serve over ROS 2 (the only transport; needs pip install 'bt-meta[ros2]')")
    serve.add_argument("--robot", default="baxter", help="a shipped robot name or a robot description YAML")
    serve.add_argument("--scene", required=True, help="scene file or shipped scene name")
    serve.add_argument("--variant", help="scene variant (default nominal)")
    serve.add_argument("--seed", type=int, default=0, help="seed of the scene's random draws (default 0)")
    serve.add_argument("--joint", action="append", default=[], metavar="NAME=VALUE",
                       help="start value of a joint over the robot's home pose (a grounding file's robot_pose)")
    serve.add_argument("--config", dest="ros2_config", metavar="CONFIG.yaml",
                       help="controllers, joints and topics to serve (default: the robot's defaults, docs/ros2.md)")
    serve.add_argument("--fault", action="append", default=[], metavar="SPEC",
                       help="make a controller fail on purpose: reject@N, abort@N[:CODE] (the N-th trajectory goal), "
                            "no-feedback (goals succeed, feedback is never sent)")
    serve.add_argument("--camera-rate", type=float, default=20.0,
                       help="camera checks per second while subscribed: a frame when the scene moved and rested, "
                            "else one a second (0: no camera; default 20)")
    serve.set_defaults(func=serve_command)
    parser.set_defaults(func=lambda _args: parser.print_help() or 2)


def _joints(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise UserInputError(f"bad --joint {item!r}: expected NAME=VALUE (radians or metres)", "--joint") from None
        if not sep or not name.strip():
            raise UserInputError(f"bad --joint {item!r}: expected NAME=VALUE", "--joint")
    return out


def serve_command(args: argparse.Namespace) -> int:
    from bt_meta.cli import Terminated
    from bt_meta.ros2.config import load_config
    from bt_meta.ros2.sim_server import Faults, SimServer
    from bt_meta.world.robot.description import load_robot
    from bt_meta.world.simulation.scenes import load_scene

    if args.camera_rate < 0:
        raise UserInputError("--camera-rate must be 0 or more", "--camera-rate")
    faults = Faults.parse(args.fault)
    robot = load_robot(args.robot)
    scene = load_scene(args.scene)
    if args.variant not in (None, "nominal") and args.variant not in scene.variants:
        raise UserInputError(f"scene {scene.name!r} has no variant {args.variant!r}; variants: "
                             f"{', '.join(['nominal', *scene.variants])}", "--variant")
    config = load_config(args.ros2_config, robot)
    server = SimServer(robot, scene, variant=args.variant, seed=args.seed, start=_joints(args.joint), config=config,
                       faults=faults, camera_rate=args.camera_rate)

    def ready() -> None:
        actions = ", ".join(config.trajectory_action(arm) for arm in config.arms)
        print(f"bt-meta sim: ready -- {robot.name} in {scene.name} ({args.variant or 'nominal'}, seed {args.seed}); "
              f"{actions}; {config.joint_states}", file=sys.stderr, flush=True)

    with contextlib.suppress(KeyboardInterrupt, Terminated):
        server.serve(ready)
    print("bt-meta sim: stopped", file=sys.stderr, flush=True)
    return 0
