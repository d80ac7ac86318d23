"""Worlds a behaviour tree acts on: the protocol, a fake symbolic world for tests, the simulated robots.

Split by concern; lower layers never import higher ones (robot <- kinematics <- simulation <-> skills):

* :mod:`bt_meta.world.base` -- the :class:`~bt_meta.world.base.World` and :class:`~bt_meta.world.base.Skill`
  protocols every world implements (fake, pybullet, a robot adapter)
* :mod:`bt_meta.world.fake` -- :class:`~bt_meta.world.fake.FakeWorld`: symbolic state from a problem, skills that
  take a configurable number of ticks, scripted faults
* :mod:`bt_meta.world.robot` -- robot descriptions as data (``robots/*.yaml``) checked against the URDF
* :mod:`bt_meta.world.kinematics` -- forward kinematics, collision checking, the MuJoCo model and IK
* :mod:`bt_meta.world.simulation` -- the pybullet simulator, cameras, object models, scenes and the SimWorld
* :mod:`bt_meta.world.skills` -- MoveTo, Grasp, Place, Insert as tick-by-tick skills
"""
