"""The pybullet simulation a behaviour tree acts on: simulator, cameras, object models, scenes, the World.

Modules (import them explicitly):

* :mod:`bt_meta.world.simulation.objects` -- Mega Bloks, magnetic parts, task board, housing and shaft models
* :mod:`bt_meta.world.simulation.scenes` -- scenes and variants as data (``trees/scenes/*.yaml``)
* :mod:`bt_meta.world.simulation.sim` -- the headless pybullet :class:`~bt_meta.world.simulation.sim.Simulation`
* :mod:`bt_meta.world.simulation.camera` -- top-view and eye-in-hand cameras (RGB, depth, pixel <-> table)
* :mod:`bt_meta.world.simulation.sim_world` -- :class:`~bt_meta.world.simulation.sim_world.SimWorld`, the World
  over the simulator
"""
