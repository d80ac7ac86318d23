"""Place(block, x, y): pick a block up and put it down with its centroid at (x, y) -- the letters primitive.

Built from MoveTo and Grasp as a small state machine (paper, section 6.1: "grasps and then moves the block to
(x, y)"): approach above the block, descend, grasp, lift, move above the target, descend, release, retreat. The
grasp is top-down at the block's centroid; the block is turned on the way so its axes line up with the target
frame's (a 1x2 block lies along the letter's x axis); a catalogue type with grasp frames is held over its first
one instead of its centroid. The symbols x and y are grounded by the world through the
grounding file's frame (letters: lb = 6.1 cm from the scene's ``letter_origin`` anchor).

After the release the block must rest within ``tolerance`` of the target, on its base (within
:data:`FACE_TOLERANCE`) and at the target's heading up to its shape's yaw period (within
:data:`HEADING_TOLERANCE`), else kind ``physical``; a turn must leave it at least :data:`TURN_GAIN` nearer standing.
The target height is what is under it: the frame's ``support:`` (a tray, a fixture, the part to stack on), else
its anchor's height, else the table (docs/scenes.md, "Supports").

A grounding file's ``mode: turn`` makes it the re-orientation of a block lying on another face (the primitive
takes only the block): picked top-down at the face it now shows, turned in the gripper by at most a quarter
toward standing on its base (:meth:`~bt_meta.world.simulation.sim_world.SimWorld.turn_up`) over where it lay,
its lowest point ``drop`` (default 3 cm; higher, in 2 cm steps up to 15 cm, where the turned wrist does not
reach that low) over the table, and let go: it lands on its next face. A block a failed place left in the
gripper, carried with the wrist tilted to stand it up, is first taken back over where it was picked (the grasp
pose the world noted) and turned from there as a block lying there would be.

Offers:

* :class:`Place` -- the skill (grounding-file options: ``frame``, ``approach_height``, ``clearance``, ``mode``,
  ``drop``)
* :func:`top_down` -- a gripper pose pointing at the table at (x, y, z) with a yaw
* :func:`symmetry` -- the yaw period of an object's shape (1x1 block: 90 degrees, 1x2: 180 degrees)
* :func:`nearest_yaw` -- the yaw equivalent to one under a symmetry nearest to a preferred yaw
* :func:`turned_pose` -- the gripper pose that turns a held block toward standing on its base (mode ``turn``)
* :func:`place_overlap` -- how deep another object may reach into where a block is put down
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bt_meta.bt.failures import FailureKind
from bt_meta.world.kinematics.collision import SHRINK
from bt_meta.world.poses import matrix_to_pose, pose_to_matrix
from bt_meta.world.skills.base import PhasedSkill, SkillAbort, rounded
from bt_meta.world.skills.grasp import Grasp
from bt_meta.world.skills.move_to import MoveTo
from bt_meta.world.symmetry import heading_matters, yaw_period

__all__ = ["Place", "nearest_yaw", "place_overlap", "symmetry", "top_down", "turned_pose"]

_PAD_THICKNESS = 0.016
"""Thickness (m) of a finger pad along the closing axis, for checking what the fingers would touch."""
_PAD_HALF_WIDTH = 0.009
"""Half the width (m) of a finger pad across the closing axis (and how far it reaches above the hand frame)."""

GRIPPER_YAW = math.pi
"""Preferred world yaw of a top-down gripper (near Baxter's home orientation)."""
MAX_DROP = 0.15
DROP_STEP = 0.02
"""A turn lets the block go from ``drop`` over the table, raised by this until the arm reaches (at most MAX_DROP)."""
TURN_RISE = 0.03
"""The turn ends this much higher than it starts (m), and a held block is taken back two approach heights over
where it was picked: the wrist's quarter turn dips the block on the way. Measured on the 6 generated letters
variants with a block on its side (seed 0): with both and the half turn 5 repaired, with the half turn alone 4;
without the half turn letters_A 0040 collided whatever the height (0.3-2.2 mm into the table at 10-18 % of the
joint-space path)."""
CARRY_CLEARANCE = 0.005
"""The block carried from the lift to over the target keeps this much (m) from every other object: a block carried
tilted (picked on its side, the wrist turned to stand it up) grazed the block beside it, which the checker's
slightly smaller shapes let through, and tipped it over (generated letters_A and letters_H 0040). Only the
carry: lowering onto the target sets the block beside others."""
WITHDRAW_SPEED = 0.25
"""Fraction of the joint speed a block is drawn out from between blocks it touches (up its own height and 5 mm):
lifted at full speed out of a drawn letter, a block kicked its neighbour 2 cm aside (a re-tiling moving the 1x1 on
a leg's top, generated letters_A s1 0046); at half speed it did not."""
SET_DOWN = 0.015
"""m over the target where a block set down beside others slows to :data:`WITHDRAW_SPEED`: lowered at full speed
next to the block on the cell above, it shoved that block 5 mm into the apex's way (generated letters_A s1 0046)."""
BESIDE = 0.005
"""m: a block put down this close to another object is set down slowly."""
SNUG = 0.003
"""m a block lowered onto its target may press into a neighbour: placing the blocks beside it nudged them up to 3 mm
its way, and the lowering then collided with the apex 0.3 mm deep in the checker (letters_A s0 0020); the
simulator pushes the neighbour back. Not the table, not during the carry."""
FACE_TOLERANCE = math.radians(20.0)
"""A part placed (or standing) with its base more than this off level did not land on the face it was set down on."""
HEADING_TOLERANCE = math.radians(15.0)
"""A part placed more than this (about the vertical, up to its symmetry) off the target's heading is turned wrong."""
TURN_GAIN = math.radians(45.0)
"""A turn brings the part's base at least this much nearer standing (half its quarter turn)."""
FLIP_AXES = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))
"""Turn axes tried for a block upside down (base frame)."""


def place_overlap() -> float:
    """How deep (m) another object may reach into a block's footprint at its target before the place fails
    (``collision``, phase ``room``): 6 mm -- the collision shapes are ``SHRINK`` smaller on every side than the
    simulated ones (blocks side by side touch exactly), and a block lowered onto its target may press :data:`SNUG`
    into a movable neighbour, which the simulator pushes aside. The campaign labeller calls a letter cell occupied
    by the same measure."""
    return 2.0 * SHRINK + SNUG


def top_down(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """A gripper pose pointing straight down (approach axis -z) at (x, y, z), turned by ``yaw``."""
    return pose_to_matrix((x, y, z, math.pi, 0.0, yaw))


def symmetry(model: Any) -> float:
    """The yaw period of an object's shape and features (:func:`~bt_meta.world.symmetry.yaw_period`)."""
    return yaw_period(model)


def _lying_period(model: Any, transform: np.ndarray) -> float:
    """The yaw period of a part as it lies: its shape's about its own z axis when that is near vertical; on a side,
    its shape label's (the letters' blocks, as their re-orientations were measured), else none (a pin lying
    down is not symmetric about the vertical)."""
    if abs(float(transform[2, 2])) >= math.cos(math.radians(30.0)):
        return symmetry(model)
    return {"1x1": math.pi / 2.0, "1x2": math.pi}.get(getattr(model, "shape", None) or "", 2.0 * math.pi)


def nearest_yaw(yaw: float, period: float, preferred: float) -> float:
    k = round((preferred - yaw) / period)
    return yaw + k * period


def tilt(transform: np.ndarray) -> float:
    """How far (rad) an object's z axis (its base's normal, reversed) is from pointing up: 0 standing on its base."""
    return math.acos(max(-1.0, min(1.0, float(transform[2, 2]))))


def object_yaw(transform: np.ndarray) -> float:
    return math.atan2(transform[1, 0], transform[0, 0])


def lying_yaw(transform: np.ndarray) -> float:
    """The heading of an object's faces about the vertical: its x axis's (:func:`object_yaw`), or, where the x axis
    points (nearly) up or down -- a block on its side about its y axis -- that of its most horizontal other axis.
    There ``object_yaw`` is the angle of two rounding errors: the Panda's fingers closed 21 degrees off the faces
    of a 1x1 block lying so, and the block turned in them as they closed."""
    if float(np.linalg.norm(transform[:2, 0])) >= 0.5:
        return object_yaw(transform)
    axis = max((transform[:3, 1], transform[:3, 2]), key=lambda a: float(np.linalg.norm(a[:2])))
    return math.atan2(float(axis[1]), float(axis[0]))


def turned_pose(world: Any, block: str, arm: str, gripper: np.ndarray, held: np.ndarray, drop: float = 0.03
                ) -> tuple[np.ndarray, bool]:
    """(pose, reachable): the gripper at ``gripper`` holding ``block`` at ``held`` (its pose in the gripper frame)
    turned by at most a quarter toward standing the block on its base, over where the block is, its lowest point
    ``drop`` over the table -- or higher, where the turned wrist does not reach that low; upside down (any
    horizontal axis does) about the first axis of :data:`FLIP_AXES` the arm reaches. The place skill's turn and
    the campaign labeller's check of it."""
    sim = world.sim
    first = None
    for flip in FLIP_AXES:
        turned = np.asarray(gripper, float).copy()
        turned[:3, :3] = world.turn_up(block, math.pi / 2.0, gripper[:3, :3], arm,
                                       np.asarray(flip, float)) @ gripper[:3, :3]
        moved = turned @ held
        turned[:2, 3] += sim.object_transform(block)[:2, 3] - moved[:2, 3]
        points = sim.object_model(block).points() @ moved[:3, :3].T + moved[:3, 3]
        turned[2, 3] += sim.table.top_z + drop - float(points[:, 2].min())
        first = turned.copy() if first is None else first
        for _ in range(round((MAX_DROP - drop) / DROP_STEP) + 1):
            if _reachable(world, arm, turned):
                return turned, True
            turned[2, 3] += DROP_STEP
    return first, False


def _reachable(world: Any, arm: str, pose: np.ndarray) -> bool:
    ik = getattr(world, "ik", None)
    if ik is None:
        return True
    import pinocchio as pin

    return bool(ik.solve(arm, pin.SE3(pose[:3, :3], pose[:3, 3]), world.current_q(), seed=0).success)


class Place(PhasedSkill):
    """Pick ``block`` and put it down at a point of the grounding frame."""

    name = "place"
    def __init__(self, world: Any, arm: str | None = None, *, approach_height: float = 0.08, clearance: float = 0.002,
                 tolerance: float = 0.01) -> None:
        super().__init__(world, arm)
        self.approach_height = approach_height
        self.clearance = clearance
        self.tolerance = tolerance
        self.block = ""
        self.goal: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.turn = False
        self.drop = 0.03
        self._turned_pose = np.eye(4)
        self._high = np.eye(4)
        self._support: tuple[float, str | None] | None = None
        """(anchor height, support) of the target frame (``SimWorld.frame_support``); ``None``: the table."""

    def ground(self, args: tuple[str, ...]) -> None:
        if self.spec.get("mode", "place") == "turn":
            if len(args) != 1:
                raise SkillAbort(FailureKind.INTERNAL, f"place in mode turn takes (block), got {list(args)}")
            block = self.world.object_name(args[0])
            self.turn = True
            self.drop = float(self.spec.get("drop", self.drop))
            self.approach_height = float(self.spec.get("approach_height", self.approach_height))
            self.begin(block, (0.0, 0.0, 0.0))
            return
        if self.spec.get("mode", "place") != "place":
            raise SkillAbort(FailureKind.INTERNAL, f"place mode {self.spec.get('mode')!r}: expected place or turn")
        if len(args) != 3:
            raise SkillAbort(FailureKind.INTERNAL, f"place takes (block, x, y), got {list(args)}")
        block, x, y = args
        frame = str(self.spec.get("frame", "table"))
        goal = self.world.ground_cell(frame, x, y)
        self.approach_height = float(self.spec.get("approach_height", self.approach_height))
        self.begin(self.world.object_name(block), goal, frame=frame)

    def begin(self, block: str, goal: tuple[float, float, float], *, frame: str | None = None) -> Place:
        """Place ``block`` with its centroid at ``goal`` = (X, Y, yaw of the target frame) in the base frame, on
        what is under the target: the support ``frame`` names, else its anchor's height, else the table."""
        self.begin_ground()
        known = getattr(getattr(self.world, "grounding", None), "frames", None) or {}
        self._support: tuple[float, str | None] | None = (
            self.world.frame_support(frame) if frame is not None and frame in known else None)
        if block not in self.world.sim.object_names():
            raise SkillAbort(FailureKind.UNKNOWN_ENTITY, f"place: there is no block {block!r} in the world",
                             {"object": block, "present": list(self.world.sim.object_names())})
        if self._support is not None and self._support[1] == block:
            raise SkillAbort(FailureKind.UNEXPECTED_CONFIGURATION,
                             f"place {block}: it is the support of frame {frame}, what parts are put on",
                             {"object": block, "support": block, "objects": [block]})
        self.block = block
        self.goal = goal
        self._yaw: float | None = None
        self._goal_ref: float | None = None
        """The yaw the block is set down nearest (up to its symmetry), when the pick chose one."""
        self._beside = False
        self._down: np.ndarray | None = None
        self.info.update(block=block, goal=rounded(goal))
        self._tilt_before = tilt(self.world.sim.object_transform(block))
        self.begin_phases()
        return self

    # -- the phases ---------------------------------------------------------------------------------------------

    def reached_object(self) -> str | None:
        return self.block or None

    def phases(self) -> list[tuple[str, Any]]:
        if self.turn:
            held = self.world.sim.held(self.arm) == self.block
            picked = (getattr(self.world, "grasp_poses", None) or {}).get(self.block) if held else None
            if not held:
                pick = self._pick_phases()
            elif picked is not None:
                # A block a failed place left in the gripper was carried with the wrist tilted to stand it up
                # (picked on its side): turned from there, the wrist sweeps it into the table. It is taken back
                # over where it was picked, held as it was picked, and turned from there (TURN_RISE).
                pick = [("back", lambda: self._move(self._over(picked, 2.0), f"back over where {self.block} lay"))]
            else:  # held, not picked by this world's place: turned from where it is held
                pick = self._pick_phases(held=True)
            return [
                *pick,
                ("half turn", lambda: self._move(self._half_turned(), "half turn " + self.block)),
                ("turn", lambda: self._move(self._high, "turn " + self.block)),  # high: the block clear
                ("lower", lambda: self._move(self._turned_pose, "lower " + self.block)),  # of the table
                ("release", lambda: Grasp(self.world, self.arm).begin(self.block, release=True)),
                ("retreat", lambda: self._move(self._lifted(), "retreat")),
                # the wrist back to top-down where it is: the next pick's move from the turned wrist swept the
                # hand through the blocks beside the one to pick (letters_H s0 0024, a kept turn replayed first)
                ("square", lambda: self._move(self._squared(), "wrist top-down")),
            ]
        # a block still held from a placement that failed on the way (a repair runs it again) is carried from there
        return [
            *self._pick_phases(held=self.world.sim.held(self.arm) == self.block),
            ("carry", lambda: self._move(self._at_goal(self.approach_height), "above the target", CARRY_CLEARANCE)),
            ("room", self._check_room),
            ("lower", lambda: self._move(self._lowered(), "down at the target", -SNUG)),
            ("set down", self._set_down),
            ("release", lambda: Grasp(self.world, self.arm).begin(self.block, release=True)),
            ("retreat", lambda: self._move(self._lifted(), "retreat")),
        ]

    def _pick_phases(self, held: bool = False) -> list[tuple[str, Any]]:
        """Approach, descend, grasp, withdraw, lift -- or only the lift for a block already held."""
        lift = ("lift", lambda: self._move(self._lifted(), "lift " + self.block))
        if held:
            return [lift]
        return [
            ("approach", lambda: self._move(self._over_block(self.approach_height), "above " + self.block)),
            ("descend", self._descend),
            ("grasp", self._grasp),
            ("withdraw", self._withdraw),
            lift,
        ]

    def _grasp(self) -> Grasp:
        """Close on the block, noting where (``SimWorld.grasp_poses``) for a turn that takes it back there."""
        poses = getattr(self.world, "grasp_poses", None)
        if poses is not None:
            poses[self.block] = self.world.sim.link_transform(self.world.end_effector(self.arm)).copy()
        return Grasp(self.world, self.arm).begin(self.block, release=False)

    def _withdraw(self) -> MoveTo | None:
        """Draw the block slowly (:data:`WITHDRAW_SPEED`) straight up out from between the objects it touches, by
        its own height and 5 mm; nothing when it touches only the table."""
        sim = self.world.sim
        if not sim.contacts(self.block) - {"table", "robot"}:
            return None
        low, high = sim.object_model(self.block).extent()
        raised = sim.link_transform(self.world.end_effector(self.arm)).copy()
        raised[2, 3] += float(np.max(high - low)) + 0.005
        return MoveTo(self.world, self.arm, speed=WITHDRAW_SPEED).begin(raised, "withdraw " + self.block)

    def _clearances_at_goal(self, within: float) -> tuple[dict[str, float], np.ndarray]:
        """(object -> distance closer than ``within``, negative: overlap) of the block's box put down at the target
        to every other object not held, and the box's centre pose; the simulator's closest points."""
        sim = self.world.sim
        low, high = sim.object_model(self.block).extent()
        centre = self._goal_block().copy()
        centre[:3, 3] += centre[:3, :3] @ ((low + high) / 2.0)
        held = sim.held(self.arm)
        others = [n for n in sim.object_names() if n != self.block and n != held]
        return sim.box_clearances(high - low, centre, others, within), centre

    def _beside_others(self) -> bool:
        """Whether the block, put down at the target, would come within :data:`BESIDE` of another object."""
        return bool(self._clearances_at_goal(BESIDE)[0])

    def _check_room(self) -> None:
        """Fail (``collision``, naming the pair) when another object reaches deeper than :func:`place_overlap` into
        the block's footprint at the target. The lowering's own check ends :data:`SET_DOWN` over the target beside
        others, above a neighbour lower than that, and the set-down allows twice :data:`SNUG` for brushing on the
        way: a green 1x2 reaching 6.5 mm into a cell of H was shoved aside (generated letters_H s1 0058)."""
        clearances, centre = self._clearances_at_goal(0.0)
        deep = {n: d for n, d in clearances.items() if d < -place_overlap()}
        if deep:
            name, depth = min(deep.items(), key=lambda item: item[1])
            raise SkillAbort(FailureKind.COLLISION, f"place {self.block}: {name} reaches {-depth * 1000:.1f} mm into "
                             f"where it goes (more than the {place_overlap() * 1000:.0f} mm a block set down takes)",
                             {"pair": [self.block, name], "objects": [self.block, name], "collision_kind": "object",
                              "penetration": round(-depth, 5), "failed_phase": "room",
                              "target": rounded(centre[:3, 3])})

    def _lowered(self) -> np.ndarray:
        """Where the lowering at full speed ends: :data:`SET_DOWN` over the target beside other objects (the rest
        is :meth:`_set_down`), else on it. The gripper pose on the target is fixed here, through the grasp as it is
        before anything is touched: a block brushing its neighbours on the way down sits a little differently in
        the gripper, and the pose read from that put it 6.6 mm into the table (letters_A s0 0020, the apex)."""
        self._down = self._at_goal(0.0)
        self._beside = self._beside_others()
        lowered = self._down.copy()
        if self._beside:
            lowered[2, 3] += SET_DOWN
        return lowered

    def _set_down(self) -> MoveTo | None:
        """The last :data:`SET_DOWN` onto the target, slowly (:data:`WITHDRAW_SPEED`), beside other objects. The
        place was checked from above (:data:`SNUG`); a block that brushed a neighbour on the way down may press
        twice as far into it now (held by friction, it turns a little in the fingers: the Panda's letter H, b6
        beside b1, 3.5 mm)."""
        if not self._beside or self._down is None:
            return None
        return MoveTo(self.world, self.arm, speed=WITHDRAW_SPEED, carried_clearance=-2.0 * SNUG).begin(
            self._down, "set down at the target")

    def _over(self, pose: np.ndarray, heights: float = 1.0) -> np.ndarray:
        raised = np.asarray(pose, float).copy()
        raised[2, 3] += heights * self.approach_height
        return raised

    def _move(self, pose: np.ndarray, label: str, carried_clearance: float = 0.0) -> MoveTo:
        return MoveTo(self.world, self.arm, carried_clearance=carried_clearance).begin(pose, label)

    def _grasp_yaw(self) -> float:
        """The gripper's yaw for the pick: nearest the arm's comfortable top-down yaw among the block's
        symmetric turns, but turned a quarter when that keeps the fingers out of the blocks around the block
        here or around its target (a parallel gripper wider than the block closes across a free side)."""
        if self._yaw is None:
            sim = self.world.sim
            transform = sim.object_transform(self.block)
            period = _lying_period(sim.object_model(self.block), transform)
            preferred = nearest_yaw(object_yaw(transform), period, sim.robot.arm(self.arm).top_down_yaw)
            if sim.grasps_by_friction(self.block, self.arm):
                # the fingers close on the part's faces: from the heading of its faces as it lies
                preferred = nearest_yaw(lying_yaw(transform), period, sim.robot.arm(self.arm).top_down_yaw)
                # the fingers close on two of the part's own faces: each quarter turn from the preferred, the
                # narrowest across the fingers first (a pin lying down is held across, not along it); for a turn
                # by a hand that turns parts about its fingers, those closing along the turn's axis first
                turns = [preferred + k * math.pi / 2.0 for k in (0, 1, -1, 2)]
                ranked = sorted(turns, key=lambda yaw: (self._finger_obstruction(yaw), self._off_turn_axis(yaw),
                                                        self._width_across(yaw)))
                self._yaw = ranked[0]
                if self._descent_collides(ranked[0]):
                    self._clear_descent(ranked)
            else:
                turns = [preferred + k * period for k in range(max(1, round(math.pi / period)))]
                self._yaw = min(turns, key=self._finger_obstruction)  # ties: the first, the preferred yaw
        return self._yaw

    def _closing_axis_at(self, yaw: float) -> np.ndarray:
        """The fingers' closing axis (base frame) of a top-down gripper at ``yaw``."""
        sim = self.world.sim
        ee = sim.link_transform(self.world.end_effector(self.arm))
        return top_down(0.0, 0.0, 0.0, yaw)[:3, :3] @ (ee[:3, :3].T @ sim.closing_axis(self.arm))

    def _off_turn_axis(self, yaw: float) -> int:
        """For a turn by a gripper that turns parts about its fingers (``turn_about_fingers``): 1 when the fingers
        of a top-down grasp at ``yaw`` would not close along the horizontal axis the turn turns the block about,
        else 0. Grasped across that axis, the turn stood the fingers one over the other: the lower one was under
        the block when it let go, and the retreat tipped it back over (the Panda's letters_A s11 0009: b4 on its
        side ended on its opposite side, or upside down)."""
        gripper = self.world.sim.robot.arm(self.arm).gripper
        if not self.turn or gripper is None or not gripper.turn_about_fingers:
            return 0
        up = self.world.sim.object_transform(self.block)[:3, 2]
        axis = np.cross(up, (0.0, 0.0, 1.0))
        if tilt(self.world.sim.object_transform(self.block)) > math.radians(135.0) \
                or float(np.linalg.norm(axis)) < 1e-6:
            return 0  # upside down: any horizontal axis turns it; the turn takes the fingers' (turned_pose)
        closing = self._closing_axis_at(yaw)
        return int(abs(float(closing @ axis)) / float(np.linalg.norm(axis)) < math.cos(math.radians(45.0)))

    def _clear_descent(self, ranked: list[float]) -> None:
        """Where every way down at the chosen yaw collides -- the pad samples miss the fingers' bodies, and a
        friction hand stands open wider than the part (a Panda's 8 cm over a 6.1 cm block; letters_A 11_0001: a 1x2
        turned 33 degrees beside the block, 1.2 mm into a finger) -- pick at the first of ``ranked`` whose way down
        is clear (the labeller's check), and set the block down turned by a multiple of its symmetry that keeps
        the fingers out of its neighbours there (a quarter turn of the pick alone put a finger into the block
        beside the cell). Nothing clear: the chosen yaw stays, and the descent reports its collision."""
        sim = self.world.sim
        period = symmetry(sim.object_model(self.block))
        count = max(1, round(2.0 * math.pi / period))
        goal_turns = sorted((math.remainder(k * period, 2.0 * math.pi) for k in range(count)), key=abs)
        options = [((self._finger_obstruction(yaw, goal_turn=turn), abs(turn)), index, yaw, turn)
                   for index, yaw in enumerate(ranked) if not self._descent_collides(yaw) for turn in goal_turns]
        if not options:
            return
        _, _, self._yaw, turn = min(options, key=lambda option: option[:2])
        self._goal_ref = object_yaw(sim.object_transform(self.block)) + turn

    def _descent_collides(self, yaw: float) -> bool:
        """Whether every IK solution of the top-down grasp at ``yaw`` collides with the scene (the hand may touch
        the block), as the descent's own move would find; the fingers as they are now, open."""
        import pinocchio as pin

        world = self.world
        x, y = world.grasp_xy(self.block)
        pose = top_down(x, y, world.object_top(self.block) + world.grasp_height(self.block, self.arm, 0.004), yaw)
        world.allow_hand(self.block, self.arm, preshape=False)
        try:
            result = world.ik.solve(self.arm, pin.SE3(pose[:3, :3], pose[:3, 3]), world.current_q(), seed=0)
        finally:
            world.allow_hand(self.block, self.arm, False)
        return not result.success and result.kind == "collision"

    def _width_across(self, yaw: float) -> int:
        """The part's width (in 5 mm steps) between the fingers of a top-down gripper at ``yaw``."""
        sim = self.world.sim
        axis = self._closing_axis_at(yaw)
        t = sim.object_transform(self.block)
        along = (sim.object_model(self.block).points() @ t[:3, :3].T) @ axis
        return round(float(along.max() - along.min()) / 0.005)

    def _finger_obstruction(self, yaw: float, goal_turn: float | None = None) -> int:
        """How many sample points of the two finger pads, gripping with the gripper at ``yaw``, fall inside other
        objects, at the pick and at the goal; with ``goal_turn``, at the goal only, the block set down turned so
        from where it lies."""
        world, sim = self.world, self.world.sim
        block = sim.object_transform(self.block)
        model = sim.object_model(self.block)
        gripper = sim.robot.arm(self.arm).gripper
        if gripper is None:
            return 0
        ee = sim.link_transform(world.end_effector(self.arm))
        local_axis = ee[:3, :3].T @ sim.closing_axis(self.arm)  # in the gripper frame
        relative = yaw - object_yaw(block)
        top = world.object_top(self.block) - block[2, 3] + world.grasp_height(self.block, self.arm, 0.004)
        others = self._others()  # 108 points per pose against every object: read each object's pose once
        count = 0
        for pose in ((block, self._goal_block()) if goal_turn is None else (self._goal_block(goal_turn),)):
            gripper_yaw = object_yaw(pose) + relative
            axis = top_down(0.0, 0.0, 0.0, gripper_yaw)[:3, :3] @ local_axis
            across = np.array([-axis[1], axis[0], 0.0])
            along = model.points() @ (pose[:3, :3].T @ axis)
            inner = 0.5 * float(along.max() - along.min()) if sim.grasps_by_friction(self.block, self.arm) \
                else 0.5 * gripper.opening
            tcp_z = pose[2, 3] + top
            for side in (1.0, -1.0):
                for a in np.linspace(inner, inner + _PAD_THICKNESS, 3):
                    for b in np.linspace(-_PAD_HALF_WIDTH, _PAD_HALF_WIDTH, 3):
                        for z in np.linspace(tcp_z - gripper.fingertip, tcp_z + _PAD_HALF_WIDTH, 3):
                            point = pose[:3, 3] + side * a * axis + b * across
                            point[2] = z
                            count += self._inside_others(point, others=others)
        return count

    def _others(self) -> list[tuple[np.ndarray, np.ndarray, Any, Any]]:
        """(transform, its position, extent low, extent high) of every object but the block, as they are now."""
        sim = self.world.sim
        out = []
        for other in sim.object_names():
            if other == self.block:
                continue
            t = sim.object_transform(other)
            low, high = sim.object_model(other).extent()
            out.append((t, t[:3, 3], low, high))
        return out

    def _inside_others(self, point: np.ndarray, margin: float = 0.002,
                       others: list[tuple[np.ndarray, np.ndarray, Any, Any]] | None = None) -> int:
        """1 when ``point`` lies within ``margin`` of another object's box (``others``: :meth:`_others`, read once
        for many points), else 0."""
        for t, origin, low, high in (self._others() if others is None else others):
            local = t[:3, :3].T @ (point - origin)
            if np.all(local >= low - margin) and np.all(local <= high + margin):
                return 1
        return 0

    def _over_block(self, height: float) -> np.ndarray:
        x, y = self.world.grasp_xy(self.block)  # its catalogue grasp frame, else its centroid
        top = self.world.object_top(self.block)
        return top_down(x, y, top + height, self._grasp_yaw())

    def _descend(self) -> MoveTo:
        self.world.allow_hand(self.block, self.arm)
        return self._move(self._over_block(self.world.grasp_height(self.block, self.arm, 0.004)),
                          "grasp " + self.block)

    def _lifted(self) -> np.ndarray:
        return self._over(self.world.sim.link_transform(self.world.end_effector(self.arm)))

    def _half_turned(self) -> np.ndarray:
        """Half the turn's rotation, on the way up to where it ends: a quarter turn of the wrist in one joint-space
        move swings the block down into the table (letters_A 0040)."""
        import pinocchio as pin

        start = self.world.sim.link_transform(self.world.end_effector(self.arm)).copy()
        self._high = self._turned()
        half = self._high.copy()
        half[:3, :3] = start[:3, :3] @ pin.exp3(pin.log3(start[:3, :3].T @ self._high[:3, :3]) / 2.0)
        half[:3, 3] = (start[:3, 3] + self._high[:3, 3]) / 2.0
        return half

    def _turned(self) -> np.ndarray:
        """The turn, made where the block was lifted to (turning low swept it into the table); the lower phase
        then goes down to :func:`turned_pose`."""
        world = self.world
        gripper = world.sim.link_transform(world.end_effector(self.arm)).copy()
        self._turned_pose = turned_pose(world, self.block, self.arm, gripper, world.held_relative(self.arm),
                                        self.drop)[0]
        high = self._turned_pose.copy()
        high[2, 3] = max(high[2, 3], gripper[2, 3] + TURN_RISE)
        return high

    def _goal_block(self, turn: float | None = None) -> np.ndarray:
        """Where the block should end up: centroid at the goal, resting on the table, axes along the frame, at
        the symmetric yaw nearest its own -- turned by ``turn`` from where it is, else nearest the yaw the pick
        chose for it (:meth:`_clear_descent`), else nearest its yaw now."""
        sim = self.world.sim
        model = sim.object_model(self.block)
        current = sim.object_transform(self.block)
        x, y, frame_yaw = self.goal
        reference = (object_yaw(current) + turn if turn is not None
                     else self._goal_ref if self._goal_ref is not None else object_yaw(current))
        yaw = nearest_yaw(frame_yaw, symmetry(model), reference)
        z = self._floor(model, x, y, yaw) + model.lowest_z(0.0, 0.0) + self.clearance
        return pose_to_matrix((x, y, z, 0.0, 0.0, yaw))

    def _floor(self, model: Any, x: float, y: float, yaw: float) -> float:
        """The height the block's lowest point rests on at the target: the top of the frame's support under the
        middle of its footprint (a tray's floor, the part it is stacked on), else the frame anchor's height, else
        the table top. A support not under the target is ``unexpected_configuration`` (it was moved)."""
        table = float(self.world.sim.table.top_z)
        if self._support is None:
            return table
        floor, support = self._support
        if support is None:
            return floor
        low, high = model.extent()
        half = 0.25 * (high - low)  # the middle of the footprint: not a neighbour's edge it may touch
        centre = (low + high) / 2.0
        c, s = math.cos(yaw), math.sin(yaw)
        points = []
        for u, v in ((0.0, 0.0), (half[0], half[1]), (-half[0], half[1]), (half[0], -half[1]), (-half[0], -half[1])):
            px, py = centre[0] + u, centre[1] + v
            points.append((x + c * px - s * py, y + s * px + c * py))
        top = self.world.surface_under(support, np.asarray(points))
        if top is None:
            raise SkillAbort(FailureKind.UNEXPECTED_CONFIGURATION,
                             f"place {self.block}: its support {support} is not under the target",
                             {"object": self.block, "support": support, "objects": [self.block, support],
                              "target": rounded((x, y))})
        return max(top, floor)

    def _at_goal(self, height: float) -> np.ndarray:
        gripper = self._goal_block() @ np.linalg.inv(self.world.held_relative(self.arm))
        gripper[2, 3] += height
        return gripper

    def _squared(self) -> np.ndarray:
        here = self.world.sim.link_transform(self.world.end_effector(self.arm))
        return top_down(float(here[0, 3]), float(here[1, 3]), float(here[2, 3]), GRIPPER_YAW)

    def finish(self) -> None:
        sim = self.world.sim
        self.world.allow_hand(self.block, self.arm, allowed=False)
        final = sim.object_transform(self.block)
        self.info["final_pose"] = rounded(matrix_to_pose(final))
        if self.turn:
            self._check_turned(final)
            return
        error = float(np.linalg.norm(final[:2, 3] - np.asarray(self.goal[:2])))
        self.info["placement_error"] = rounded(error, 5)
        evidence = {"object": self.block, "target": rounded(self.goal[:2]), "final_pose": self.info["final_pose"],
                    "error": error}
        if error > self.tolerance:
            raise SkillAbort(FailureKind.PHYSICAL,
                             f"place: {self.block} came to rest {error * 100:.1f} cm from its target", evidence)
        goal = self._goal_block()
        off_face = tilt(final)
        self.info["face_error_deg"] = rounded(math.degrees(off_face), 2)
        if off_face > FACE_TOLERANCE:
            raise SkillAbort(FailureKind.PHYSICAL, f"place: {self.block} came to rest at its target tipped "
                             f"{math.degrees(off_face):.0f} degrees off the face it was set down on",
                             {**evidence, "face_error_deg": self.info["face_error_deg"]})
        model = self.world.sim.object_model(self.block)
        period = symmetry(model)
        if heading_matters(model, HEADING_TOLERANCE):  # a part that looks the same at any heading has none
            heading = abs(nearest_yaw(object_yaw(final), period, object_yaw(goal)) - object_yaw(goal))
            self.info["heading_error_deg"] = rounded(math.degrees(heading), 2)
            if heading > HEADING_TOLERANCE:
                raise SkillAbort(FailureKind.PHYSICAL, f"place: {self.block} came to rest at its target turned "
                                 f"{math.degrees(heading):.0f} degrees from the heading it was set down at",
                                 {**evidence, "heading_error_deg": self.info["heading_error_deg"],
                                  "target_yaw": rounded(object_yaw(goal))})

    def _check_turned(self, final: np.ndarray) -> None:
        """A turn must leave the part on another face, nearer standing on its base than before: by at least half
        the quarter turn (:data:`TURN_GAIN`), or still standing when it stood. A part that fell back onto the face
        it showed (a pin stood on its end topples) fails the turn here, ``physical``, not a later step."""
        before, after = self._tilt_before, tilt(final)
        self.info["tilt_deg"] = {"before": rounded(math.degrees(before), 1), "after": rounded(math.degrees(after), 1)}
        turned = after <= FACE_TOLERANCE if before <= FACE_TOLERANCE else after <= before - TURN_GAIN
        if not turned:
            raise SkillAbort(FailureKind.PHYSICAL, f"turn: {self.block} did not come to rest on its next face: its "
                             f"base is {math.degrees(after):.0f} degrees off standing after the turn, "
                             f"{math.degrees(before):.0f} before",
                             {"object": self.block, "tilt_before_deg": self.info["tilt_deg"]["before"],
                              "tilt_after_deg": self.info["tilt_deg"]["after"],
                              "final_pose": self.info["final_pose"]})
