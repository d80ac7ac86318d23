"""Kinematics of a robot description, independent of any simulator.

Modules (import them explicitly):

* :mod:`bt_meta.world.kinematics.forward` -- Pinocchio forward kinematics and Jacobians
* :mod:`bt_meta.world.kinematics.collision` -- coal self- and scene-collision checks (SRDF pairs removed)
* :mod:`bt_meta.world.kinematics.mujoco_model` -- the MuJoCo model mink solves on, built from the URDF
* :mod:`bt_meta.world.kinematics.ik` -- mink inverse kinematics with restarts and collision-aware acceptance
"""
