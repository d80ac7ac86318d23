"""The seeded start-pose noise of a run: every object moved a little, as an instructor's demonstrations vary.

Demonstrations, demo variants and campaign episodes all start from it, and the labeller labels the scene an
episode of its seed runs, so it lives below all of them.

Offers:

* :func:`jitter` -- move every object of a world by noise drawn from a seed
* :data:`JITTER_POSITION` / :data:`JITTER_YAW` -- its bounds (m, rad)
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["JITTER_POSITION", "JITTER_YAW", "jitter"]

#: Seeded start-pose noise of every object (m, rad): demonstrations and runs vary as an instructor's would (the
#: shipped scenes have no jitter of their own).
JITTER_POSITION = 0.003
JITTER_YAW = math.radians(2.0)


def jitter(world: Any, seed: int, position: float = JITTER_POSITION, yaw: float = JITTER_YAW) -> None:
    """Move every object by seeded noise (x, y within ``position``, yaw within ``yaw``; about the base z axis)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    sim = world.sim
    for name in sorted(sim.object_names()):
        pose = list(sim.object_pose(name))
        dx, dy = rng.uniform(-position, position, 2)
        pose[0], pose[1] = pose[0] + float(dx), pose[1] + float(dy)
        pose[5] += float(rng.uniform(-yaw, yaw))
        sim.move_object(name, pose)
    sim.settle(60)
    world.sync_collision()
