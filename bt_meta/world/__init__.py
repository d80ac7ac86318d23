"""Worlds a behaviour tree acts on: the protocol, a fake symbolic world for tests, the simulated Baxter.

Modules (import them explicitly):

* :mod:`bt_meta.world.base` -- the :class:`~bt_meta.world.base.World` and :class:`~bt_meta.world.base.Skill`
  protocols every world implements (fake, pybullet, a robot adapter)
* :mod:`bt_meta.world.fake` -- :class:`~bt_meta.world.fake.FakeWorld`: symbolic state from a problem, skills that
  take a configurable number of ticks, scripted faults
* kinematics, collision and simulation modules of the simulator issue
"""
