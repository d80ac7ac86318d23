"""Worlds a behaviour tree acts on: the protocol, a fake symbolic world for tests, the simulated Baxter.

Modules (import them explicitly):

* :mod:`bt_meta.world.base` -- the :class:`~bt_meta.world.base.World` and :class:`~bt_meta.world.base.Skill`
  protocols every world implements (fake, pybullet, a robot adapter)
* :mod:`bt_meta.world.fake` -- :class:`~bt_meta.world.fake.FakeWorld`: symbolic state from a problem, skills that
  take a configurable number of ticks, scripted faults
* :mod:`bt_meta.world.robot` -- robot descriptions (``robots/*.yaml``) checked against the URDF
* :mod:`bt_meta.world.kinematics` -- Pinocchio forward kinematics and Jacobians
* :mod:`bt_meta.world.collision` -- coal self- and scene-collision checks (SRDF pairs removed)
* :mod:`bt_meta.world.ik` -- mink inverse kinematics with restarts and collision-aware acceptance
* :mod:`bt_meta.world.objects` -- Mega Bloks, magnetic parts, task board, housing and shaft models
* :mod:`bt_meta.world.sim` -- the headless pybullet :class:`~bt_meta.world.sim.Simulation`
* :mod:`bt_meta.world.camera` -- top-view and eye-in-hand cameras (RGB, depth, pixel <-> table)
* :mod:`bt_meta.world.scenes` -- scenes and variants as data (``trees/scenes/*.yaml``)
* :mod:`bt_meta.world.skills` -- MoveTo, Grasp, Place, Insert as tick-by-tick skills
* :mod:`bt_meta.world.sim_world` -- :class:`~bt_meta.world.sim_world.SimWorld`, the World over the simulator
"""
