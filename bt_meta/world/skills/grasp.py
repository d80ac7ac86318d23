"""Grasp: toggle the gripper -- hold the object within reach, or release the held one.

How the simulator holds it is the robot's (:meth:`bt_meta.world.simulation.sim.Simulation.grasp`): the Baxter's
gripper opens 4.62 cm, less than a Mega Blok, and grasps by constraint; the Panda's fingers close on a part that
fits and hold it by friction, and a part too heavy or slippery slips out (a ``physical`` failure of the skill
that carries it). Toggling is the paper's primitive (section 7.1); ``start([])`` toggles,
``start([object])`` grasps that object (or releases it when it is the one held); a grounding file's
``mode: close`` / ``mode: open`` makes it a CloseGripper / OpenGripper primitive. After a release the skill lets the
physics run a few ticks so the object comes to rest (and the magnetic attach rule, checked at every physics step,
can join parts that meet). Fails with kind ``physical`` when there is nothing within reach, the named object is
not the one held, or the object slipped out during the settling ticks; with kind ``collision`` (the gripper and
the obstacle as the pair) when an object the robot did not put there and not joined to the part to grasp -- the
named one, or the one the last ``MoveTo`` went above -- lies on it: the grasp would close on the obstacle, an
empty grasp of the part.

Offers:

* :class:`Grasp` -- the skill; ``begin(obj=None, release=None)`` for use by other skills
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bt_meta.bt.failures import FailureKind
from bt_meta.world.base import RUNNING, SUCCESS
from bt_meta.world.skills.base import SimSkill, SkillAbort, rounded

__all__ = ["Grasp"]

_MODES: dict[str, bool | None] = {"toggle": None, "close": False, "open": True}
"""Grounding-file ``mode`` -> ``release`` (``None``: toggle, the paper's Grasp)."""


class Grasp(SimSkill):
    """Close on (hold) or open from (release) an object."""

    name = "grasp"

    def __init__(self, world: Any, arm: str | None = None, *, settle_ticks: int = 2, reach: float = 0.03) -> None:
        super().__init__(world, arm)
        self.settle_ticks = settle_ticks
        self.reach = reach
        self.object: str | None = None
        self.release: bool | None = None
        self._done = False

    def ground(self, args: tuple[str, ...]) -> None:
        if len(args) > 1:
            raise SkillAbort(FailureKind.INTERNAL, f"grasp takes at most one object, got {list(args)}")
        obj = self.world.object_name(args[0]) if args else None
        mode = str(self.spec.get("mode", "toggle"))
        if mode not in _MODES:
            raise SkillAbort(FailureKind.INTERNAL, f"grasp mode {mode!r}: expected one of {', '.join(_MODES)}")
        self.begin(obj, _MODES[mode])

    def begin(self, obj: str | None = None, release: bool | None = None) -> Grasp:
        self.begin_ground()
        self.object = obj
        self.release = release
        self._done = False
        return self

    def step(self) -> str:
        world, sim = self.world, self.world.sim
        if not self._done:
            self._done = True
            held = sim.held(self.arm)
            release = self.release if self.release is not None else held is not None
            if release:
                if held is None:
                    raise SkillAbort(FailureKind.PHYSICAL, "grasp: asked to release, but the gripper holds nothing",
                                     {"held": None})
                if self.object is not None and self.object != held:
                    raise SkillAbort(FailureKind.PHYSICAL, f"grasp: the gripper holds {held!r}, not {self.object!r}",
                                     {"held": held, "expected": self.object})
                world.release(self.arm)
                placed = getattr(world, "placed_by_robot", None)
                world.placed_by_robot = {*(placed or ()), held}  # the task put it there: part of its work
                self.info.update(action="release", object=held)
            else:
                if held is not None:
                    raise SkillAbort(FailureKind.PHYSICAL, f"grasp: the gripper already holds {held!r}",
                                     {"held": held})
                name = self._pick()
                self.info.update(action="grasp", object=name)
            world.advance()
            return RUNNING if self.settle_ticks > 0 else self._finish()
        world.advance()
        if self.ticks > self.settle_ticks:
            return self._finish()
        return RUNNING

    def _pick(self) -> str:
        world, sim = self.world, self.world.sim
        gripper = sim.link_transform(world.end_effector(self.arm))[:3, 3]
        intended = self.object or getattr(world, "grasp_target", None)
        if intended is not None and intended in sim.object_names():
            obstacle = self._obstacle_over(intended)
            if obstacle is not None:  # the approach ends on what lies on the part: closing would hold that instead
                raise SkillAbort(FailureKind.COLLISION, f"grasp: {obstacle!r} lies on {intended!r}: the approach to "
                                 f"it is obstructed", {"colliding_pair": [world.end_effector(self.arm), obstacle],
                                                       "obstacle": obstacle, "target": intended,
                                                       "gripper": rounded(gripper)})
        names = [self.object] if self.object is not None else list(sim.object_names())
        candidates = sorted(names, key=lambda n: float(np.linalg.norm(sim.object_transform(n)[:3, 3] - gripper)))
        for name in candidates:
            if world.grasp(name, self.arm, self.reach):
                return name
        nearest = candidates[0] if candidates else None
        evidence: dict[str, Any] = {"gripper": rounded(gripper), "reach": self.reach, "nearest": nearest}
        if nearest is not None:
            offset = sim.object_transform(nearest)[:3, 3] - gripper
            evidence["nearest_distance"] = rounded(float(np.linalg.norm(offset)))
        what = f"{self.object!r} is" if self.object is not None else "nothing is"
        raise SkillAbort(FailureKind.PHYSICAL, f"grasp: {what} within {self.reach * 100:.0f} cm of the gripper",
                         evidence)

    def _obstacle_over(self, target: str) -> str | None:
        """An object resting on ``target`` around its centroid that is neither magnetically joined to it nor put
        there by the robot (a part the task placed on it is lifted with it, as the verification's staging move
        does), or ``None``."""
        sim = self.world.sim
        state = sim.object_state(target)
        centre = sim.object_transform(target)[:3, 3]
        low, high = sim.object_model(target).extent()
        radius = 0.5 * float(min(high[0] - low[0], high[1] - low[1]))
        joined = set(state.attached_to) | set(getattr(self.world, "placed_by_robot", None) or ())
        for other in sim.object_names():
            if other == target or other in joined or other in {sim.held(a) for a in sim.robot.arms}:
                continue
            position = sim.object_transform(other)[:3, 3]
            if np.linalg.norm(position[:2] - centre[:2]) < radius and position[2] > centre[2]:
                return other
        return None

    def _finish(self) -> str:
        sim = self.world.sim
        if self.info.get("action") == "grasp" and sim.held(self.arm) != self.info.get("object"):
            raise SkillAbort(FailureKind.PHYSICAL, f"grasp: lost {self.info.get('object')!r} right after grasping it",
                             {"object": self.info.get("object")})
        obj = self.info.get("object")
        if obj is not None:
            self.info["final_pose"] = rounded(sim.object_pose(obj))
        return SUCCESS
