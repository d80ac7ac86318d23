"""Skills of the simulated robot (Baxter, Panda, or a user's own), tick by tick, one per module; the registry the
grounding files name them by.

Offers:

* :data:`SKILLS` -- skill name (as written in ``trees/poses/*.yaml``) -> skill class
* :mod:`~bt_meta.world.skills.move_to` -- MoveTo(pose): IK + joint trajectory over several ticks
* :mod:`~bt_meta.world.skills.grasp` -- Grasp: toggle the gripper (hold / release)
* :mod:`~bt_meta.world.skills.place` -- Place(block, x, y): pick a block and put it down at a point
* :mod:`~bt_meta.world.skills.insert` -- Insert(part, target): put a part's insertable end into a hole feature
"""

from __future__ import annotations

from bt_meta.world.skills.base import SimSkill
from bt_meta.world.skills.grasp import Grasp
from bt_meta.world.skills.insert import Insert
from bt_meta.world.skills.move_to import MoveTo
from bt_meta.world.skills.place import Place

SKILLS: dict[str, type[SimSkill]] = {
    MoveTo.name: MoveTo,
    Grasp.name: Grasp,
    Place.name: Place,
    Insert.name: Insert,
}

__all__ = ["SKILLS", "Grasp", "Insert", "MoveTo", "Place", "SimSkill"]
