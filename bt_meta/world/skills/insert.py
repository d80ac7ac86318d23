"""Insert(part, target): pick a part up and lower it straight down into the target's hole feature.

The paper's motivating example (section 2): the nominal skill grasps the housing from the top and lowers it into
the task board. The skill does not look at how the part is turned: it lowers the part's lowest point onto the
hole. It succeeds only when the part's insertable end (its primary attachment feature: the housing's narrow end,
the shaft's tip) then sits in the hole, facing it. Otherwise it fails with evidence (distance between the
insertable end and the hole, angle between their normals, how high the part stopped):

* ``unexpected_configuration`` -- the insertable end does not face the hole (upside-down housing, a shaft lying
  on its side): a known object in a configuration the skill was not made for;
* ``physical`` -- it faces the hole but did not go in (jammed);
* ``unknown_entity`` -- the part named is not in the world (e.g. a shaft lies where the housing was).

Offers:

* :class:`Insert` -- the skill (grounding-file options: ``target_features`` type -> feature, ``tolerance``)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bt_meta.bt.failures import FailureKind
from bt_meta.world.poses import matrix_to_pose
from bt_meta.world.skills.base import PhasedSkill, SkillAbort, rounded
from bt_meta.world.skills.grasp import Grasp
from bt_meta.world.skills.move_to import MoveTo
from bt_meta.world.skills.place import top_down

__all__ = ["Insert"]


class Insert(PhasedSkill):
    """Put ``part``'s insertable end into ``target``'s hole feature."""

    name = "insert"
    def __init__(self, world: Any, arm: str | None = None, *, approach_height: float = 0.10, tolerance: float = 0.005,
                 angle_tolerance: float = math.radians(15.0)) -> None:
        super().__init__(world, arm)
        self.approach_height = approach_height
        self.tolerance = tolerance
        self.angle_tolerance = angle_tolerance
        self.part = ""
        self.target = ""
        self.feature: str | None = None
        self.held_at_start = False

    def ground(self, args: tuple[str, ...]) -> None:
        if len(args) != 2:
            raise SkillAbort(FailureKind.INTERNAL, f"insert takes (part, target), got {list(args)}")
        self.tolerance = float(self.spec.get("tolerance", self.tolerance))
        part = self.world.object_name(args[0])
        target, feature = self.world.feature_of(args[1])
        self.begin(part, target, feature)

    def begin(self, part: str, target: str, feature: str | None = None) -> Insert:
        """Insert ``part`` into ``feature`` of ``target`` (default: the grounding's feature for the target's type,
        else its primary feature). A part already held is only lowered in and checked (the housing task file's
        Insert primitive); otherwise it is picked up and carried over the target first."""
        self.begin_ground()
        sim = self.world.sim
        present = list(sim.object_names())
        for name in (part, target):
            if name not in present:
                raise SkillAbort(FailureKind.UNKNOWN_ENTITY, f"insert: there is no object {name!r} in the world",
                                 {"object": name, "present": present})
        self.part, self.target = part, target
        target_type = sim.object_model(target).type
        self.feature = feature or (self.spec.get("target_features") or {}).get(target_type)
        self.held_at_start = sim.held(self.arm) == part
        self.info.update(part=part, target=target, target_feature=self.feature or sim.object_model(target).primary,
                         held_at_start=self.held_at_start)
        self.begin_phases()
        return self

    def reached_object(self) -> str | None:
        return self.part or None

    def phases(self) -> list[tuple[str, Any]]:
        if self.held_at_start:
            return [("insert", self._insert), ("check", self._check)]
        return [
            ("approach", lambda: self._move(self._over_part(self.approach_height), "above " + self.part)),
            ("descend", self._descend),
            ("grasp", lambda: Grasp(self.world, self.arm).begin(self.part, release=False)),
            ("lift", lambda: self._move(self._shifted(0.0, 0.0, self.approach_height), "lift " + self.part)),
            ("carry", lambda: self._move(self._over_hole(self.approach_height), "above " + self.target)),
            ("insert", self._insert),
            ("check", self._check),
            ("release", lambda: Grasp(self.world, self.arm).begin(self.part, release=True)),
            ("retreat", lambda: self._move(self._shifted(0.0, 0.0, self.approach_height), "retreat")),
        ]

    def _move(self, pose: np.ndarray, label: str, **options: Any) -> MoveTo:
        return MoveTo(self.world, self.arm, **options).begin(pose, label)

    def _over_part(self, height: float) -> np.ndarray:
        x, y = self.world.grasp_xy(self.part)  # its catalogue grasp frame, else its centroid
        return top_down(x, y, self.world.object_top(self.part) + height,
                        self.world.sim.robot.arm(self.arm).top_down_yaw)

    def _descend(self) -> MoveTo:
        self.world.allow_hand(self.part, self.arm)
        return self._move(self._over_part(self.world.grasp_height(self.part, self.arm, 0.002)),
                          "grasp " + self.part)

    def _shifted(self, dx: float, dy: float, dz: float) -> np.ndarray:
        pose = self.world.sim.link_transform(self.world.end_effector(self.arm)).copy()
        pose[:3, 3] += (dx, dy, dz)
        return pose

    def _hole(self) -> tuple[np.ndarray, np.ndarray]:
        return self.world.sim.feature(self.target, self.feature)

    def _lowest(self) -> np.ndarray:
        sim = self.world.sim
        t = sim.object_transform(self.part)
        points = sim.object_model(self.part).points() @ t[:3, :3].T + t[:3, 3]
        return points[int(np.argmin(points[:, 2]))]

    def _over_hole(self, height: float) -> np.ndarray:
        hole, _ = self._hole()
        centre = self.world.sim.object_transform(self.part)[:3, 3]
        lowest = self._lowest()
        shift = np.array([hole[0] - centre[0], hole[1] - centre[1], hole[2] + height - lowest[2]])
        return self._shifted(*shift)

    def _insert(self) -> MoveTo:
        # The part goes into the target: they may touch in collision checks; the motion is guarded (it may stop
        # short when the part meets the target), the check phase judges the result.
        self.world.allow_objects(self.part, [self.target])
        # A part whose insertable end faces the hole goes down the straight line (a joint-space line bends: the
        # UR5's swung the housing into the hole's rim); one that does not face it fails the check either way.
        return self._move(self._over_hole(0.001), "insert " + self.part, require_arrival=False, check_path=False,
                          check_held=False, settle_ticks=8, straight=self._facing())

    def _facing(self) -> bool:
        """Whether the part's insertable end faces the target's hole (normals opposed within the tolerance)."""
        _, hole_normal = self._hole()
        _, end_normal = self.world.sim.feature(self.part)
        angle = math.acos(max(-1.0, min(1.0, float(np.dot(end_normal, hole_normal)))))
        return (math.pi - angle) <= self.angle_tolerance

    def _check(self) -> None:
        sim = self.world.sim
        hole, hole_normal = self._hole()
        end, end_normal = sim.feature(self.part)
        distance = float(np.linalg.norm(end - hole))
        angle = math.acos(max(-1.0, min(1.0, float(np.dot(end_normal, hole_normal)))))
        facing = (math.pi - angle) <= self.angle_tolerance
        evidence = {
            "part": self.part, "target": self.target, "insert_feature": sim.object_model(self.part).primary,
            "distance": rounded(distance, 5), "normal_angle": rounded(angle), "end_point": rounded(end),
            "end_normal": rounded(end_normal), "hole_point": rounded(hole), "hole_normal": rounded(hole_normal),
            "stopped_above_hole": rounded(float(self._lowest()[2] - hole[2]), 5),
            "part_pose": rounded(matrix_to_pose(sim.object_transform(self.part))),
        }
        self.info["result"] = evidence
        if distance <= self.tolerance and facing:
            return None
        if not facing:
            raise SkillAbort(
                FailureKind.UNEXPECTED_CONFIGURATION,
                f"insert: {self.part}'s insertable end ({evidence['insert_feature']}) does not face the hole of "
                f"{self.target} (normals {math.degrees(angle):.0f} deg apart, 180 expected); the part stopped "
                f"{distance * 100:.1f} cm from the hole",
                evidence,
            )
        raise SkillAbort(FailureKind.PHYSICAL,
                         f"insert: {self.part} faces the hole but stopped {distance * 100:.1f} cm from it (jammed)",
                         evidence)
