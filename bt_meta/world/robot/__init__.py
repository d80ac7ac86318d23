"""Robot descriptions as data: which URDF/SRDF, arms, cameras, home pose and IK settings a robot has.

Modules (import them explicitly):

* :mod:`bt_meta.world.robot.description` -- :class:`~bt_meta.world.robot.description.RobotDescription` and
  :func:`~bt_meta.world.robot.description.load_robot` (``robots/*.yaml`` checked against the URDF)
"""
